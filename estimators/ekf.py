"""Extended Kalman filter: a generic predict/update pair and the quarter-car augmented EKF baseline.

The generic steps follow the numerically careful form used by dynamax and filterpy: the gain comes from a linear
solve with the innovation covariance (no explicit inverse), the covariance update is Joseph's form
``(I - K H) P (I - K H)^T + K R K^T``, and every covariance is symmetrized, so P stays symmetric positive
semi-definite over long runs. On a linear model they reduce exactly to the Kalman filter (tested).

:class:`QuarterCarEKF` runs them on the augmented quarter-car model of
:mod:`estimators.quarter_car_model` (state (v, lambda) plus any subset of theta, B, C, E), with the paper's
initial prior (v = 19, lambda = 0, eq. (18) parameters) and bounds (projection after each update). It is the
baseline the MHE must beat.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

import numpy as np

from estimators.base import Estimate, Estimator, EstimatorConfigError, Health, check_dt
from estimators.mismatch import WheelSpeedGuard
from estimators.outliers import DEFAULT_GATE, GateParams, Verdict, check_gate
from estimators.quarter_car_model import BOUNDS, EXTRA_NAMES, PARAM_NAMES, AugmentedModel
from estimators.tuning import (
    DEFAULT_EKF_TUNING,
    HORIZON,
    PAPER_TUNING,
    SLIP_PRIOR,
    V_PRIOR,
    brake_settle_samples,
)

__all__ = ["DEFAULT_EKF_TUNING", "SLIP_PRIOR", "V_PRIOR", "ExtendedKalmanFilter", "ParameterInformation", "QuarterCarEKF",
           "ekf_predict", "ekf_update", "innovation_covariance", "torque_jump_std", "torque_step_noise"]


def _sym(P: np.ndarray) -> np.ndarray:
    return 0.5 * (P + P.T)


def ekf_predict(x_next: np.ndarray, F: np.ndarray, P: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Time update: ``x+ = f(x, u)`` (given), ``P+ = F P F^T + Q``.

    :param x_next: the propagated mean f(x, u), shape (n,).
    :param F: Jacobian d f / d x at the previous mean, (n, n).
    :param P: previous covariance, (n, n).
    :param Q: process noise covariance, (n, n).
    :return: (x+, P+).
    """
    return x_next, _sym(F @ P @ F.T + Q)


def torque_jump_std(commands: np.ndarray, previous: np.ndarray, fade: float) -> np.ndarray:
    """The standard deviation of the jump of a brake's torque error ``T_e`` over one sample [N m].

    A brake reaches its command only over its settling time ``BRAKE_SETTLE_S``. A command changed by
    ``d = commands[-1] - previous`` reaches the wheel off by up to ``|d|`` (a step arrives late), and while the
    commands move the torque lies anywhere within those of the span (a ramp or a modulation arrives late all along,
    rule (B4) of :mod:`estimators.speed_reference`): the jump's variance is ``d^2 + (1 - fade^2) s^2``, ``s`` the
    distance from the command held to the farthest of the span, so that the fading error's spread settles at ``s``.
    A command held over the whole span gives none.

    :param commands: the span's commands, the one held over this sample last, shape (..., k) [N m].
    :param previous: the command held over the sample before, shape (...) [N m].
    :param fade: the factor by which ``T_e`` fades over a sample (``AugmentedModel.torque_fade``) [-].
    """
    commands = np.asarray(commands, dtype=float)
    held = commands[..., -1]
    span = np.max(np.abs(commands - held[..., None]), axis=-1)
    return np.sqrt((held - previous) ** 2 + (1.0 - fade**2) * span**2)


def torque_step_noise(F_e: np.ndarray, jump: np.ndarray) -> np.ndarray:
    """Process noise of a brake that lags or waits: ``j^2 F_e F_e^T``.

    The torque error ``T_e`` of the model (:mod:`estimators.quarter_car_model`) takes a jump of standard deviation
    ``j`` (:func:`torque_jump_std`) before the sample's step, so ``F_e = d x+ / d T_e`` maps it to the state; between
    jumps it fades over ``BRAKE_SETTLE_S``. A brake on time keeps ``T_e`` at 0; a lag or a delay moves it, and its
    fading keeps the torque's average at the commands' own, so that the friction and the brake gain keep theirs.

    :param F_e: d x+ / d T_e, shape (..., n).
    :param jump: the jump's standard deviation, shape (...) [N m].
    :return: (..., n, n).
    """
    Fj = F_e * np.asarray(jump, dtype=float)[..., None]
    return Fj[..., :, None] * Fj[..., None, :]


def innovation_covariance(P: np.ndarray, H: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(P H^T, S = H P H^T + R)``: the cross covariance and the innovation covariance of a measurement update.

    :param P: prior covariance, (n, n).
    :param H: Jacobian d h / d x, (m, n).
    :param R: measurement noise covariance, (m, m).
    """
    PHt = P @ H.T
    return PHt, _sym(H @ PHt + R)


def ekf_update(x: np.ndarray, P: np.ndarray, y: np.ndarray, y_pred: np.ndarray, H: np.ndarray,
               R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Measurement update with Joseph's covariance form.

    :param x: prior mean, (n,).
    :param P: prior covariance, (n, n).
    :param y: measurement, (m,).
    :param y_pred: predicted measurement h(x), (m,).
    :param H: Jacobian d h / d x, (m, n).
    :param R: measurement noise covariance, (m, m).
    :return: (posterior mean, posterior covariance, innovation).
    """
    innov = np.atleast_1d(y - y_pred)
    PHt, S = innovation_covariance(P, H, R)
    if S.shape == (1, 1):  # scalar measurement: the solve is a division
        K = PHt / S[0, 0]
    else:
        # K = P H^T S^-1  <=>  S K^T = H P  (S and P symmetric)
        K = np.linalg.solve(S, PHt.T).T
    IKH = np.eye(P.shape[0]) - K @ H
    P_post = _sym(IKH @ P @ IKH.T + K @ R @ K.T)
    return x + K @ innov, P_post, innov


class ExtendedKalmanFilter:
    """A generic discrete EKF ``x+ = f(x, u) + w``, ``y = h(x) + v``, ``w ~ N(0, Q)``, ``v ~ N(0, R)``.

    :param f_and_jacobian: ``(x, u) -> (f(x, u), d f / d x)``.
    :param h_and_jacobian: ``x -> (h(x), d h / d x)``.
    :param Q: process noise covariance (n, n).
    :param R: measurement noise covariance (m, m).
    """

    def __init__(self, f_and_jacobian: Callable, h_and_jacobian: Callable, Q, R):
        self.f_and_jacobian = f_and_jacobian
        self.h_and_jacobian = h_and_jacobian
        self.Q = np.atleast_2d(np.asarray(Q, dtype=float))
        self.R = np.atleast_2d(np.asarray(R, dtype=float))
        for name, M in (("Q", self.Q), ("R", self.R)):
            if M.shape[0] != M.shape[1] or not np.all(np.isfinite(M)):
                raise EstimatorConfigError(f"{name} must be a finite square matrix, got shape {M.shape}")

    def predict(self, x, P, u, Q=None):
        """Time update from (x, P) under input u (process noise ``Q``, default the filter's)."""
        xn, F = self.f_and_jacobian(x, u)
        return ekf_predict(np.asarray(xn, dtype=float), np.asarray(F, dtype=float), P, self.Q if Q is None else Q)

    def update(self, x, P, y):
        """Measurement update with y; returns (x, P, innovation)."""
        yp, H = self.h_and_jacobian(x)
        return ekf_update(x, P, np.atleast_1d(y), np.atleast_1d(yp), np.atleast_2d(H), self.R)




class ParameterInformation:
    """The MHE's excitation rule for a recursive filter: is every estimated parameter direction informed?

    The MHE (estimators.mhe) calls its window excited when every singular value s_i of the window's sensitivity,
    in units of the prior, reaches delta, i.e. the window's information along every state direction is at least
    delta^2 times the prior's. The same test on a filter: over the last ``horizon + 1`` measurement updates, add up
    the information each update gave the parameter block (``inv(P_post) - inv(P_prior)`` of the marginal
    parameter covariances) and compare it, whitened by the current parameter covariance, with delta^2. Free
    rolling gives no information on the friction curve (mu(0) = 0 whatever theta), so it is NOT_EXCITED.

    :param index: indices of the parameters in the state.
    :param horizon: N, the MHE's window length minus one.
    :param delta: the MHE's SVD threshold for this parameter group.
    """

    def __init__(self, index: slice, horizon: int, delta: float):
        self.index = index
        self.horizon = int(horizon)
        self.delta2 = float(delta) ** 2
        self.reset()

    def reset(self) -> None:
        self._gains: list[np.ndarray] = []
        self._total = 0.0  # sum of self._gains

    def add(self, P_prior: np.ndarray, P_post: np.ndarray | None) -> None:
        """Record one sample's update (``P_post`` None: the sample gave no update)."""
        i = self.index
        if P_post is None:
            gain = 0.0 * P_prior[i, i]
        elif P_prior[i, i].shape == (1, 1):  # theta alone: no inverse needed
            gain = 1.0 / P_post[i, i] - 1.0 / P_prior[i, i]
        else:
            gain = np.linalg.inv(P_post[i, i]) - np.linalg.inv(P_prior[i, i])
        self._gains.append(gain)
        self._total = self._total + gain
        if len(self._gains) > self.horizon + 1:
            self._total = self._total - self._gains.pop(0)

    def excited(self, P: np.ndarray) -> bool:
        """True when the recorded window informs every parameter direction by at least delta^2 times ``P``'s."""
        block = P[self.index, self.index]
        if block.size == 0:
            return True
        G = self._total + 0.0 * block
        if block.shape == (1, 1):
            return bool(G[0, 0] * block[0, 0] >= self.delta2)
        L = np.linalg.cholesky(_sym(block))
        return bool(np.linalg.eigvalsh(_sym(L.T @ G @ L))[0] >= self.delta2)


class QuarterCarEKF(Estimator):
    """EKF on the augmented quarter-car model (the MHE's baseline).

    ``update(omega, T_b)``: measurement update with the wheel speed at time k, returns x(k|k), then predicts to
    k+1 with the torque held over the sample (``update(omega, (T_b, a_x))`` for a model whose speed follows the
    measured acceleration, ``AugmentedModel(speed_from_a_x=True)``: :attr:`input_columns` says which). Values:
    ``v``, ``slip``, the four curve parameters (estimated or fixed) and ``mu``, the friction in use, mu(slip) on
    the estimated curve.

    Every wheel speed is gated (:mod:`estimators.outliers`): a sample whose NIS exceeds the chi-square bound is
    skipped (``Health.OUTLIER``, the state is only predicted); after ``outlier_gate.max_rejections`` in a row the
    next failing one re-initialises v from it (:func:`reinit_from_wheel_speed`, ``Health.REINITIALISED``). The
    health is ``NOT_EXCITED`` when the last N + 1 updates did not inform every estimated parameter by the MHE's
    rule (:class:`ParameterInformation`), e.g. free rolling. A model that carries the torque error ``T_e`` takes
    :func:`torque_step_noise` of :func:`torque_jump_std` at each time update (``ekf`` and the arrival filter of
    ``mhe``).

    :param estimated: parameters augmented to the state (subset of theta, B, C, E).
    :param dt: sample time [s].
    :param P0_std: initial standard deviations per state name (overrides defaults).
    :param Q_std: process noise standard deviations per sample, per state name (overrides defaults).
    :param R: measurement noise variance [(rad/s)^2].
    :param model: a prebuilt :class:`AugmentedModel` (else one is built from ``estimated`` and ``dt``).
    :param outlier_gate: the innovation gate, or None to trust every sample (the paper's EKF).
    :param Q_braking_std: process noise per state name that replaces ``Q_std``'s from the first sample with a brake
        torque on, until the next reset (``ekf-ax``: the slip, whose force law the model holds only approximately
        once the tire is loaded); None: ``Q_std`` throughout.
    """

    measurement_columns = ("omega",)
    input_columns = ("T_b",)
    names = ("v", "slip", "theta", "B", "C", "E", "mu")

    def __init__(self, estimated: tuple[str, ...] = ("theta",), dt: float = 0.01, P0_std: dict | None = None,
                 Q_std: dict | None = None, R: float = DEFAULT_EKF_TUNING["R"],
                 model: AugmentedModel | None = None, outlier_gate: GateParams | None = DEFAULT_GATE,
                 Q_braking_std: dict | None = None):
        dt = check_dt(dt)
        try:
            self.model = model or AugmentedModel(estimated=tuple(estimated), dt=dt)
        except ValueError as exc:
            raise EstimatorConfigError(str(exc)) from None
        for label, given in (("P0_std", P0_std), ("Q_std", Q_std), ("Q_braking_std", Q_braking_std)):
            bad = [k for k in (given or {}) if k not in ("v", "slip") + PARAM_NAMES + EXTRA_NAMES]
            if bad:
                raise EstimatorConfigError(f"{label} keys {bad} unknown; valid: v, slip, "
                                           f"{', '.join(PARAM_NAMES + EXTRA_NAMES)}")
        p0 = {**DEFAULT_EKF_TUNING["P0_std"], **(P0_std or {})}
        q = {**DEFAULT_EKF_TUNING["Q_std"], **(Q_std or {})}
        names = self.model.names
        self.P0 = np.diag([p0[n] ** 2 for n in names])
        self.filter = ExtendedKalmanFilter(
            self.model.f_and_jacobian,
            lambda x: (np.array([self.model.h(x)]), self.model.h_jacobian(x)),
            np.diag([q[n] ** 2 for n in names]),
            np.array([[float(R)]]),
        )
        # while the brake acts, the states of Q_braking_std take that process noise instead (None: no change)
        self.Q_braking = None if Q_braking_std is None else \
            np.diag([{**q, **Q_braking_std}[n] ** 2 for n in names])
        self.input_columns = self.model.input_names  # ("T_b",), or ("T_b", "a_x") when the speed follows a_x
        # the torque error's index, or None for a model without one
        self.torque_error = self.model.names.index("T_e") if "T_e" in self.model.extras else None
        self.lower, self.upper = self.model.lower(), self.model.upper()
        # the model's speed can change by at most F_z theta_max / m per second (|mu| <= theta <= 1): a predicted
        # step beyond it is a numerical failure of the stiff step (slip near 1, speed near 0) and is clipped to it
        theta_max = BOUNDS["theta"][1] if "theta" in self.model.estimated else self.model.road(self.lower)[3]
        self.dv_max = self.model.p.Fz * theta_max / self.model.p.m * dt
        self.outlier_gate = check_gate(outlier_gate)
        self.guard = WheelSpeedGuard(self.model, self.outlier_gate, float(np.sqrt(R)))
        group = "theta-only" if len(self.model.estimated) <= 1 else "all"
        self.information = ParameterInformation(slice(2, 2 + len(self.model.estimated)), HORIZON, PAPER_TUNING[group]["delta"])
        self.reset()

    def reset(self, v: float = V_PRIOR, slip: float = SLIP_PRIOR, params: dict | None = None,
              v_std: float | None = None) -> Estimate:
        """Start from the a priori state (Section IV) with covariance P0.

        :param v: the speed to start from [m/s]; :param slip: the slip; :param params: parameter values.
        :param v_std: how well ``v`` is known [m/s] (e.g. a free-rolling wheel's speed: its noise times r); None:
            the prior spread of P0. A model whose speed follows ``a_x`` keeps this error for the whole run.
        """
        self.x = self.model.nominal_state(v, slip, params)
        self.P = self.P0.copy()
        if v_std is not None:  # P0 is diagonal: the speed's variance alone changes
            if not (np.isfinite(v_std) and v_std > 0):
                raise EstimatorConfigError(f"v_std must be a positive speed [m/s], got {v_std!r}")
            self.P[0, 0] = float(v_std) ** 2
        self.guard.reset()
        self._brake_torque = 0.0  # torque held since the last sample [N m]
        self._braked = False  # a brake torque has acted since the reset
        self._commands = deque(maxlen=brake_settle_samples(self.model.dt))  # the torques commanded, newest last
        self.torque_jump = 0.0  # the torque error's jump at the last time update, its standard deviation [N m]
        self.torque_variance = np.zeros(2)  # ... and the variance of (v, slip) it adds over that update
        self.information.reset()
        return self._estimate(self.x, Health.OK)

    def _estimate(self, x: np.ndarray, health: Health, info: dict | None = None) -> Estimate:
        return Estimate(self.model.values(x), health, info or {})

    def correct(self, y: np.ndarray) -> tuple[Verdict, np.ndarray, np.ndarray, np.ndarray | None, float]:
        """Gate wheel speed ``y`` on the prior (x, P) (:class:`estimators.mismatch.WheelSpeedGuard`) and update.

        :return: (verdict, posterior mean (not yet clipped to the bounds), posterior covariance, innovation or None
            for a rejected sample, the process-noise factor of a mismatch); the prior (x, P) is re-initialised on
            ``REINIT`` and raised on ``MISMATCH``.
        """
        verdict, self.x, self.P, inflation = self.guard.check(self.x, self.P, self.P0, self.filter.R, self.filter.Q,
                                                              y, self._brake_torque)
        if verdict == Verdict.REJECT:
            return verdict, self.x, self.P, None, inflation
        x_post, P_post, innov = self.filter.update(self.x, self.P, y)
        return verdict, self.guard.bound_posterior(x_post, float(self.x[0]), float(y[0])), P_post, innov, inflation

    def propagate(self, x_post: np.ndarray, P_post: np.ndarray, inputs) -> bool:
        """Time update from the posterior (clipped to the bounds) under the input held to the next sample.

        :param inputs: the torque [N m], or the model's inputs in :attr:`input_columns` order.
        :return: False when the step is not finite: the prior is kept and its covariance restarts at P0.
        """
        u = np.atleast_1d(np.asarray(inputs, dtype=float))
        previous, self._brake_torque = self._brake_torque, float(u[0])
        self._commands.append(self._brake_torque)
        x_post = np.clip(x_post, self.lower, self.upper)
        self._braked = self._braked or self._brake_torque > 0.0
        braked = self.Q_braking is not None and self._braked
        Q = self.Q_braking if braked else self.filter.Q
        x_next, F = self.model.f_and_jacobian(x_post, u)
        if self.torque_error is not None:  # the torque error's jump, through the step's Jacobian column
            self.torque_jump = float(torque_jump_std(np.array(self._commands), previous, self.model.torque_fade))
            noise = torque_step_noise(F[:, self.torque_error], self.torque_jump)
            self.torque_variance = np.diag(noise)[:2].copy()
            Q = Q + noise
        x_next, P_next = ekf_predict(x_next, F, P_post, Q)
        if not (np.all(np.isfinite(x_next)) and np.all(np.isfinite(P_next))):
            self.P = self.P0.copy()
            return False
        if not self.model.speed_from_a_x:  # a speed from a_x moves by a_x dt, no stiff step
            x_next[0] = np.clip(x_next[0], x_post[0] - self.dv_max, x_post[0] + self.dv_max)
        self.x, self.P = np.clip(x_next, self.lower, self.upper), P_next
        return True

    def update(self, measurement, u) -> Estimate:
        sample = self._validated_sample(measurement, u)
        if sample is None:
            return self._estimate(self.x, Health.INVALID_INPUT, {"reason": "NaN or wrong shape; sample skipped"})
        y, uu = sample
        verdict, x_post, P_post, innov, inflation = self.correct(y)
        P_prior = self.P
        x_post = np.clip(x_post, self.lower, self.upper)
        if not self.propagate(x_post, P_post, uu):  # keep the last good state
            return self._estimate(self.x, Health.SOLVER_FAILED, {"reason": "non-finite EKF step"})
        self.information.add(P_prior, None if innov is None else P_post)
        if verdict in (Verdict.ACCEPT, Verdict.MISMATCH, Verdict.START):
            health = Health.OK if self.information.excited(P_post) else Health.NOT_EXCITED
        else:
            health = Health.OUTLIER if verdict == Verdict.REJECT else Health.REINITIALISED
        info = {"rejected_in_row": self.guard.rejected} if innov is None else {"innovation": float(innov[0])}
        if verdict == Verdict.MISMATCH:
            info["mismatch"] = inflation
        return self._estimate(x_post, health, info)

    @property
    def braked(self) -> bool:
        """A brake torque has acted since the reset (from then on ``Q_braking_std`` applies)."""
        return self._braked

    @property
    def covariance(self) -> np.ndarray:
        """Current (predicted) covariance."""
        return self.P.copy()
