"""Measurement gating shared by every estimator: a chi-square innovation test and a consecutive-rejection counter.

Rule (one place, used by the EKF, the MHE, the EKF/RLS, the FMS observer and the FMS RLS calibrator). For each
sample the estimator forms its innovation ``e`` (measurement minus its prediction) and the innovation covariance
``S`` (the prediction's covariance plus the measurement noise), and the normalised innovation squared

    NIS = e^T S^-1 e,

which, for a filter consistent with its noise model, is chi-square distributed with ``dof`` = dim(e) degrees of
freedom. :func:`gate` compares it with the bound ``chi2.isf(p_false, dof)`` of :class:`GateParams` (default
``p_false`` = 1e-5: 19.5 for one degree of freedom, 25.9 for three): a sample above the bound cannot be true
(under the model) and is rejected -- the update skips it and the estimate says ``Health.OUTLIER``.

Several rejections in a row must not lock the filter out (a real jump of the signal, a filter that lost track): the
counter of consecutive rejections is carried from sample to sample, and the ``max_rejections + 1``-th sample in a
row that fails the test is not rejected but taken as the new truth: the estimator re-initialises its measured
states from that measurement (widening their covariance back to the initial one) and says
``Health.REINITIALISED`` for that sample. So at most ``max_rejections`` (default 10, 100 ms at 10 ms) samples in a
row are ever discarded.

:func:`gate` is a pure function over the frozen :class:`GateParams`: the estimators keep the counter.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from estimators.base import EstimatorConfigError
from estimators.tuning import MAX_REJECTIONS, P_FALSE

__all__ = ["DEFAULT_GATE", "FMS_GATE", "GateParams", "SignalGate", "Verdict", "block_health", "check_gate", "gate", "nis",
           "wrench_gate"]

WRENCH_ACCEL_MARGIN = 3.0  # the reading mixes eq. (13)'s channels through S^-1: measured |w_hat''| up to 2x [-]
WRENCH_STD_FLOOR_REL = 0.05  # smallest reading noise std assumed: the paper's stated 5 % of eq. (13)'s amplitude [-]
SCALE_TIME = 1.0  # averaging time of the signal's mean square in SignalGate [s]


@dataclass(frozen=True)
class GateParams:
    """The innovation gate: chi-square bound and re-initialisation rule (module docstring).

    :param p_false: probability that a sample consistent with the model is rejected; sets the bound.
    :param dof: degrees of freedom, the innovation's dimension.
    :param max_rejections: samples in a row that may be rejected; the next failing one re-initialises.
    """

    p_false: float = P_FALSE
    dof: int = 1
    max_rejections: int = MAX_REJECTIONS
    bound: float = field(init=False)  # chi-square bound on the NIS [-]

    def __post_init__(self):
        if not (np.isfinite(self.p_false) and 0.0 < self.p_false < 1.0):
            raise EstimatorConfigError(f"gate p_false must be in (0, 1), got {self.p_false!r}")
        if int(self.dof) != self.dof or self.dof < 1:
            raise EstimatorConfigError(f"gate dof must be an integer >= 1, got {self.dof!r}")
        if int(self.max_rejections) != self.max_rejections or self.max_rejections < 0:
            raise EstimatorConfigError(f"gate max_rejections must be an integer >= 0, got {self.max_rejections!r}")
        object.__setattr__(self, "bound", float(chi2.isf(self.p_false, int(self.dof))))

    def with_dof(self, dof: int) -> GateParams:
        """The same gate for an innovation of another dimension."""
        return GateParams(self.p_false, dof, self.max_rejections)


DEFAULT_GATE = GateParams()


def check_gate(value) -> GateParams | None:
    """An estimator's ``outlier_gate`` option: a :class:`GateParams` or None (off); anything else is refused."""
    if value is not None and not isinstance(value, GateParams):
        raise EstimatorConfigError(f"outlier_gate must be a GateParams (estimators.outliers) or None, got {value!r}")
    return value


class Verdict(enum.IntEnum):
    """What :func:`gate` decides for one sample."""

    ACCEPT = 0  # update with the sample
    REJECT = 1  # skip the update (Health.OUTLIER)
    REINIT = 2  # too many rejections in a row: re-initialise from the sample (Health.REINITIALISED)
    MISMATCH = 3  # a persistent innovation: the model is off, update with raised process noise (estimators.mismatch)
    START = 4  # the first sample after a reset fails against the a priori guess: start from it (estimators.mismatch)


def nis(innovation, S) -> float:
    """Normalised innovation squared ``e^T S^-1 e`` (inf when S is singular or the values are not finite).

    :param innovation: e, scalar or (m,).
    :param S: innovation covariance, scalar or (m, m).
    """
    e = np.atleast_1d(np.asarray(innovation, dtype=float))
    S = np.atleast_2d(np.asarray(S, dtype=float))
    if S.shape == (1, 1):
        value = float(e[0] * e[0] / S[0, 0]) if S[0, 0] > 0 else np.inf
    else:
        try:
            value = float(e @ np.linalg.solve(S, e))
        except np.linalg.LinAlgError:
            value = np.inf
    return value if np.isfinite(value) else np.inf


def gate(nis_value: float, rejected_in_row: int, params: GateParams = DEFAULT_GATE) -> tuple[Verdict, int]:
    """Decide on one sample from its NIS and the number of samples rejected just before it.

    :param nis_value: normalised innovation squared of the sample (:func:`nis`).
    :param rejected_in_row: consecutive rejections before this sample (the estimator's counter).
    :param params: bound and re-initialisation rule.
    :return: (verdict, the counter after this sample).
    """
    if nis_value <= params.bound:
        return Verdict.ACCEPT, 0
    if rejected_in_row >= params.max_rejections:
        return Verdict.REINIT, 0
    return Verdict.REJECT, rejected_in_row + 1


class SignalGate:
    """The gate on a smooth signal sampled fast, without a model of it: the FMS force-moment readings.

    Per channel, a steady-state constant-velocity Kalman filter (an alpha-beta tracker) predicts the next sample;
    its innovation is the second difference of the signal through an all-pole filter,
    ``E(z) / Z(z) = (1 - z^-1)^2 / (1 + (alpha + beta - 2) z^-1 + (1 - alpha) z^-2)``, so a block is gated with
    one ``lfilter`` call (and one more per rejected sample). The NIS sums the channels' squared innovations over
    their steady-state variances (``dof`` = channels). In units of the noise std and the sample time the filter
    has one parameter, the tracking index ``accel dt^2 / std`` (largest over the channels, so that every channel's
    model error is covered). A rejected sample is replaced by its prediction (innovation 0); a re-initialisation
    restarts the tracker at the sample, at rest. A failing sample that the next sample (or the rejected one before
    it) agrees with is a step of the signal -- a PRBS wrench, a change of the sensor's calibration -- and restarts
    the tracker without a mark: the gate removes isolated spikes, but a run of equal bad readings (a dropout to
    zero, a stuck sensor) cannot be told from a step and is accepted after at most one sample.

    The model error scales with the signal: the floor of the noise std is ``std_floor`` times
    ``sqrt(ms / ms_ref)``, with ms the signal's mean square (robust start: the median of the first block's
    squares, at least ``ms_ref``; then an average over ``SCALE_TIME`` of the samples used) and ``ms_ref`` the mean square ``accel`` and
    ``std_floor`` were stated for, so that a sensor whose readings are 100 times larger is not rejected wholesale.

    :param dt: sample time [s].
    :param std: noise standard deviation per channel (floored as above).
    :param accel: bound on the true signal's second derivative per channel [unit/s^2].
    :param params: the gate (its ``dof`` must equal the number of channels).
    :param std_floor: smallest noise std assumed per channel at mean square ``ms_ref``.
    :param ms_ref: mean square of the signal ``accel`` and ``std_floor`` describe, per channel.
    """

    def __init__(self, dt: float, std, accel, params: GateParams, std_floor=0.0, ms_ref=1.0):
        from scipy.linalg import solve_discrete_are

        self.std = np.asarray(std, dtype=float)
        self.std_floor = np.broadcast_to(np.asarray(std_floor, dtype=float), self.std.shape)
        self.ms_ref = np.broadcast_to(np.asarray(ms_ref, dtype=float), self.std.shape)
        self.decay_per_sample = float(np.exp(-dt / SCALE_TIME))
        std = np.maximum(self.std, self.std_floor)
        accel = np.asarray(accel, dtype=float)
        if std.ndim != 1 or std.shape != accel.shape or np.any(std <= 0) or params.dof != len(std):
            raise EstimatorConfigError(f"SignalGate needs one positive std and accel per channel and dof = channels,"
                                       f" got std {std!r}, accel {accel!r}, dof {params.dof}")
        lam = float(np.max(accel * dt * dt / std))  # tracking index
        F = np.array([[1.0, 1.0], [0.0, 1.0]])
        G = np.array([[0.5], [1.0]])
        P = solve_discrete_are(F.T, np.array([[1.0], [0.0]]), lam**2 * (G @ G.T) + 1e-15 * np.eye(2),
                               np.array([[1.0]]))
        s_norm = P[0, 0] + 1.0
        alpha, beta = P[0, 0] / s_norm, P[0, 1] / s_norm
        self.b = np.array([1.0, -2.0, 1.0])
        self.a = np.array([1.0, alpha + beta - 2.0, 1.0 - alpha])
        self.s_norm = s_norm  # steady-state innovation variance in units of the noise variance
        self.params = params
        self.reset()

    def reset(self) -> None:
        self._z = None  # the last two samples used (most recent first), (2, channels)
        self._e = None  # their innovations
        self._ms = None  # running mean square of the samples used, per channel
        self._pending = None  # the raw value of the previous sample if it was rejected
        self.rejected = 0

    def _start(self, z: np.ndarray) -> None:
        self._z = np.stack([z, z])
        self._e = np.zeros_like(self._z)

    def _push(self, z: np.ndarray, e: np.ndarray) -> None:
        """Record the samples used (rows, oldest first) and their innovations."""
        self._z = np.concatenate([z[::-1], self._z])[:2]
        self._e = np.concatenate([e[::-1], self._e])[:2]

    def __call__(self, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gate a block of samples (n, channels); returns the samples to use and a :class:`Verdict` per sample."""
        from scipy.signal import lfilter

        Z = np.array(Z, dtype=float)
        verdicts = np.zeros(len(Z), dtype=int)
        if not len(Z):
            return Z, verdicts
        start = 0
        if self._z is None:
            self._start(Z[0])
            start = 1
        if self._ms is None:
            self._ms = np.maximum(np.median(Z * Z, axis=0), self.ms_ref)  # a signal starting at 0 has no scale yet
        floor = self.std_floor * np.sqrt(self._ms / self.ms_ref)
        S = self.s_norm * np.maximum(self.std, floor) ** 2
        b, a = self.b, self.a
        while start < len(Z):
            zi = np.stack([b[1] * self._z[0] - a[1] * self._e[0] + b[2] * self._z[1] - a[2] * self._e[1],
                           b[2] * self._z[0] - a[2] * self._e[0]])
            E, _ = lfilter(b, a, Z[start:], axis=0, zi=zi)
            values = np.sum(E * E / S, axis=1)
            bad = np.flatnonzero(values > self.params.bound)
            first = int(bad[0]) if bad.size else len(values)
            if first:
                self._push(Z[start:start + first], E[:first])
                self.rejected, self._pending = 0, None
            if not bad.size:
                break
            j = start + first
            if self._is_step(Z, j, S):  # the signal stepped (e.g. a PRBS wrench): restart the tracker, keep it
                self._start(Z[j])
                self.rejected, self._pending = 0, None
                start = j + 1
                continue
            verdict, self.rejected = gate(float(values[first]), self.rejected, self.params)
            verdicts[j] = verdict
            self._pending = Z[j].copy() if verdict == Verdict.REJECT else None
            if verdict == Verdict.REJECT:
                Z[j] -= E[first]
                self._push(Z[j:j + 1], np.zeros((1, Z.shape[1])))
            else:
                self._start(Z[j])
            start = j + 1
        decay = self.decay_per_sample ** len(Z)
        self._ms = decay * self._ms + (1.0 - decay) * np.mean(Z * Z, axis=0)
        return Z, verdicts


    def _is_step(self, Z: np.ndarray, j: int, S: np.ndarray) -> bool:
        """A failing sample j is a step of the signal, not an outlier, when the sample after it (in this block) or
        the rejected sample before it agrees with it within the gate (pair variance 2 S / s_norm per channel)."""
        other = Z[j + 1] if j + 1 < len(Z) else self._pending
        if other is None:
            return False
        d = Z[j] - other
        return float(np.sum(d * d / (2.0 * S / self.s_norm))) <= self.params.bound


def block_health(verdicts: np.ndarray):
    """Health for a block of gated samples: REINITIALISED if any re-initialised, else OUTLIER if any was rejected,
    else None (the estimator's own health)."""
    from estimators.base import Health

    if np.any(verdicts == Verdict.REINIT):
        return Health.REINITIALISED
    if np.any(verdicts == Verdict.REJECT):
        return Health.OUTLIER
    return None


FMS_GATE = GateParams(p_false=1e-9, dof=3)  # the FMS force readings: 1e5 samples per 100 s run at 1 kHz [-]


def wrench_gate(dt: float, wrench_std, params: GateParams = FMS_GATE) -> SignalGate:
    """The gate on the FMS sensor's readings (M, f_x, f_y), used by the observer and the RLS calibrator.

    The second-derivative bound is ``WRENCH_ACCEL_MARGIN`` times that of the paper's multi-sine, eq. (13)
    (``sum a w^2`` per channel); the noise std is floored at ``WRENCH_STD_FLOOR_REL`` of eq. (13)'s amplitude. The
    bound is the chi-square(3) quantile at ``FMS_GATE.p_false`` = 1e-9 (44.8): at 1 kHz a 1e-5 gate would reject a
    clean sample in most 100 s runs. Measured on 100 s of the paper's trajectory, noise-free and at the stated
    noise: no rejection.

    :param dt: sample time [s].
    :param wrench_std: reading noise std (M, f_x, f_y) [N m, N, N].
    :param params: the gate (dof 3).
    """
    from fricenv.plants.payload import PAPER_WRENCH_AMPLITUDE, PAPER_WRENCH_TERMS

    accel = np.array([sum(a * w * w for a, w, _, _ in terms) for terms in PAPER_WRENCH_TERMS])
    ms = np.array([sum(a * a / 2.0 for a, _, _, _ in terms) for terms in PAPER_WRENCH_TERMS])  # distinct frequencies
    return SignalGate(dt, wrench_std, WRENCH_ACCEL_MARGIN * accel, params,
                      std_floor=WRENCH_STD_FLOOR_REL * PAPER_WRENCH_AMPLITUDE, ms_ref=ms)
