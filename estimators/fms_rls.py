"""Recursive least-squares calibration of the force-moment sensor (beside the paper's observer).

With ``w = S w_hat`` (3), eq. (1) is linear in the nine entries of S. Writing ``s1, s2, s3`` for the rows of S
and ``r = (1, -rho_y, rho_x)``:

    I_G theta'' = w_hat . (s1 - rho_y s2 + rho_x s3)                    (eq. (1), row 1)
    m X''       = (cos(theta) w_hat) . s2 - (sin(theta) w_hat) . s3      (eq. (1), row 2)
    m Y''       = (sin(theta) w_hat) . s2 + (cos(theta) w_hat) . s3      (eq. (1), row 3)

so the regressors are ``w_hat``, ``cos(theta) w_hat`` and ``sin(theta) w_hat``. The accelerations come from the
vision signals by a central second difference (at the middle sample, error ``dt^2/12 x''''``), and then the SAME
linear low-pass filter F (Butterworth, order ``filter_order``, cut-off ``cutoff_hz``) is applied to the targets and
to the regressors; because F is linear and time invariant, ``F[m X''] = F[cos(theta) w_hat] . s2 - ...`` holds
exactly, whatever F does to the signal, while F removes the amplified vision noise of the second difference (the
filter order must be >= 3 so that ``s^2 F(s)`` rolls off). The rows are weighted by the inverse vision noise
(``I_G sigma_theta`` against ``m sigma_position``).

The least-squares problem is kept in information form, ``A = sum lambda^(n-k) H_k^T W H_k``, ``b = ...``, which is
recursive least squares with exponential forgetting ``lambda = exp(-dt / forgetting_time)`` (no forgetting by
default; a finite ``forgetting_time`` tracks a slowly drifting S). For step changes of S (the paper's Table 1),
``change_detection=True`` compares the power of the residuals (against the current S_hat) over the last 0.5 s with
its 20 s baseline; a ratio above ``change_threshold`` discounts all old information by 1e-4 and mutes the filter's
memory of the old readings for one settle time, after which the estimate is rebuilt from new data in a few
seconds (measured: back below E = 1e-2 within 2.8-3.8 s of each Table 1 step at the stated noise). A small prior
``prior_weight (S - S0)`` keeps the solve defined before any excitation. A block of samples is absorbed at once
(:meth:`FmsRLS.update_block`), so the cost per 1 ms sample is a few microseconds.

Measured (``fricenv paper fms --seeds 5``, medians over 5 seeds, the paper's multi-sine and S): noise-free
E = 1.4e-5 at 20 s and 100 s (the O(dt^2) second difference); stated noise E = 2.3e-3 at 20 s and 8.6e-4 at
100 s; Table 1 steps (stated noise, change detection) back below 1e-2 within 2.3, 2.9 and 3.7 s.

Health: ``NOT_EXCITED`` while the filtered sensor reading has too little power in some direction compared with the
sensor noise (``excitation`` below ``min_excitation``), or while S_hat is near singular (``cond > max_cond``);
``SOLVER_FAILED`` if the normal equations cannot be solved (the last S_hat is kept); ``INVALID_INPUT`` for a sample
with NaN or a wrong shape (skipped, and the difference chain restarts). Nothing raises inside ``update``.

Wrench hold: with ``wrench_hold="point"`` the reading at a sample is the wrench at that instant (smooth wrench,
the paper's set-up); with ``"zoh"`` it is held until the next sample (the env's zero-order-hold actions), and the
regressor uses the mean of the two readings around the middle sample of the second difference, which is exact
for a piecewise-constant wrench.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from estimators.base import Estimate, Estimator, EstimatorConfigError, Health, check_dt
from estimators.outliers import FMS_GATE, GateParams, block_health, check_gate, wrench_gate
from fricenv.plants.payload import PAPER_NOISE, PAPER_PARAMS, PayloadParams

__all__ = ["WRENCH_HOLDS", "FmsRLS"]

WRENCH_HOLDS = ("point", "zoh")
DEFAULT_CUTOFF_HZ = 2.0  # low-pass cut-off of the common filter [Hz]
DEFAULT_FILTER_ORDER = 4  # Butterworth order; >= 3 so that s^2 F(s) is strictly proper
MIN_FILTER_ORDER = 3
DEFAULT_PRIOR_WEIGHT = 1e-6  # weight of the prior S0 in the normal equations [-]
DEFAULT_MIN_EXCITATION = 10.0  # filtered reading power / filtered sensor-noise power, smallest direction [-]
DEFAULT_MAX_COND = 1e3  # S_hat with a larger condition number is flagged near singular
SIGMA_FLOOR_THETA = 1e-7  # [rad] floor of the vision noise used for the row weights
SIGMA_FLOOR_POSITION = 1e-8  # [m]
WRENCH_STD_FLOOR = 1e-6  # [N m, N] floor of the sensor noise used in the excitation measure
DEFAULT_CHANGE_THRESHOLD = 10.0  # fast/slow residual power ratio that signals a jump of S [-]
CHANGE_FAST_TIME = 0.5  # time constant of the fast residual power [s]
CHANGE_SLOW_TIME = 20.0  # time constant of the slow (baseline) residual power [s]
CHANGE_WARMUP_TIME = 5.0  # effective data [s] needed before the detector is armed (again)
CHANGE_DISCOUNT = 1e-4  # the old information is multiplied by this when a jump is detected [-]
MAX_GAP_FILL = 20  # longest run of invalid samples bridged by extrapolation; longer gaps restart the chain
RESTART_SETTLE_FACTOR = 2  # a chain restarted while moving is muted this many settle times (velocity transient)
SETTLE_CYCLES = 2.0  # samples of the filter start-up not used: this many periods of the cut-off [-]
MAX_BLOCK_MAP = 200  # blocks up to this length are filtered by a cached exact block map, longer ones by sosfilt
N_CHANNELS = 12  # 3 pose channels + 9 regressor channels (w_hat, cos w_hat, sin w_hat)


class FmsRLS(Estimator):
    """RLS calibrator of S from raw sensor readings and vision poses (see the module docstring).

    :param dt: sample time [s].
    :param params: payload mass properties and sensor location (assumed known, as in the paper).
    :param cutoff_hz: cut-off of the common low-pass filter [Hz].
    :param filter_order: Butterworth order (>= 3).
    :param forgetting_time: time constant of the exponential forgetting [s]; ``None`` = no forgetting.
    :param vision_std: (theta [rad], position [m]) noise standard deviations used for the row weights.
    :param wrench_std: sensor noise std (M, f_x, f_y) used by the excitation measure.
    :param wrench_hold: ``"point"`` or ``"zoh"`` (see the module docstring).
    :param change_detection: discount the old information when the residual power jumps (a step change of S,
        e.g. the paper's Table 1), see the module docstring.
    :param change_threshold: fast/slow residual power ratio that counts as a jump.
    :param prior_weight: weight of the prior S0.
    :param min_excitation: excitation below which the estimate is flagged ``NOT_EXCITED``.
    :param max_cond: condition number above which S_hat is flagged near singular.
    :param outlier_gate: the gate on the readings (:func:`estimators.outliers.wrench_gate`, with ``wrench_std``):
        a rejected reading is replaced by the gate's prediction (``Health.OUTLIER`` for the block), the
        ``max_rejections + 1``-th in a row restarts the predictor at it (``Health.REINITIALISED``); None: off.
    """

    measurement_columns = ("theta", "X", "Y")
    input_columns = ("M", "f_x", "f_y")
    names = ("S", "excitation")

    def __init__(self, dt: float = 1e-3, params: PayloadParams = PAPER_PARAMS, *,
                 cutoff_hz: float = DEFAULT_CUTOFF_HZ, filter_order: int = DEFAULT_FILTER_ORDER,
                 forgetting_time: float | None = None,
                 vision_std: tuple[float, float] = (PAPER_NOISE.theta_std, PAPER_NOISE.position_std),
                 wrench_std=tuple(PAPER_NOISE.wrench_std), wrench_hold: str = "point",
                 change_detection: bool = False, change_threshold: float = DEFAULT_CHANGE_THRESHOLD,
                 prior_weight: float = DEFAULT_PRIOR_WEIGHT, min_excitation: float = DEFAULT_MIN_EXCITATION,
                 max_cond: float = DEFAULT_MAX_COND, outlier_gate: GateParams | None = FMS_GATE):
        self.dt = check_dt(dt)
        if not isinstance(params, PayloadParams):
            raise EstimatorConfigError(f"params must be a PayloadParams, got {type(params).__name__}")
        self.params = params
        nyquist = 0.5 / self.dt
        if not np.isfinite(cutoff_hz) or not 0 < cutoff_hz < nyquist:
            raise EstimatorConfigError(f"cutoff_hz must be in (0, {nyquist:g}) Hz for dt={self.dt}, got {cutoff_hz!r}")
        if int(filter_order) != filter_order or filter_order < MIN_FILTER_ORDER:
            raise EstimatorConfigError(f"filter_order must be an integer >= {MIN_FILTER_ORDER}, got {filter_order!r}")
        if forgetting_time is not None and (not np.isfinite(forgetting_time) or forgetting_time <= 0):
            raise EstimatorConfigError(f"forgetting_time must be > 0 s or None, got {forgetting_time!r}")
        if wrench_hold not in WRENCH_HOLDS:
            raise EstimatorConfigError(f"wrench_hold must be one of {', '.join(WRENCH_HOLDS)}, got {wrench_hold!r}")
        vs = np.asarray(vision_std, dtype=float)
        if vs.shape != (2,) or not np.all(np.isfinite(vs)) or np.any(vs < 0):
            raise EstimatorConfigError(f"vision_std must be (theta_std, position_std) >= 0, got {vision_std!r}")
        ws = np.asarray(wrench_std, dtype=float)
        if ws.shape != (3,) or not np.all(np.isfinite(ws)) or np.any(ws < 0):
            raise EstimatorConfigError(f"wrench_std must be 3 values >= 0, got {wrench_std!r}")
        if not isinstance(change_detection, (bool, np.bool_)):
            raise EstimatorConfigError(f"change_detection must be True or False, got {change_detection!r}")
        for name, value in (("change_threshold", change_threshold), ("prior_weight", prior_weight), ("min_excitation", min_excitation),
                            ("max_cond", max_cond)):
            if not np.isfinite(value) or value <= 0:
                raise EstimatorConfigError(f"{name} must be finite and > 0, got {value!r}")
        self.cutoff_hz = float(cutoff_hz)
        self.filter_order = int(filter_order)
        self.forgetting_time = forgetting_time
        self.wrench_hold = wrench_hold
        self.prior_weight = float(prior_weight)
        self.change_detection = bool(change_detection)
        self.change_threshold = float(change_threshold)
        self.min_excitation = float(min_excitation)
        self.max_cond = float(max_cond)
        self._lam = 1.0 if forgetting_time is None else float(np.exp(-self.dt / forgetting_time))
        self._sos = signal.butter(self.filter_order, self.cutoff_hz, fs=1.0 / self.dt, output="sos")
        # Row weights (inverse noise variance of each equation), normalised to 1 for the translational rows.
        sig_rot = params.I_G * max(vs[0], SIGMA_FLOOR_THETA)
        sig_tr = params.m * max(vs[1], SIGMA_FLOOR_POSITION)
        self._row_w = np.array([(sig_tr / sig_rot) ** 2, 1.0, 1.0])
        # Filtered sensor-noise variance: white noise through F has variance std^2 * sum(h_F^2).
        impulse = np.zeros(int(20.0 / (self.cutoff_hz * self.dt)) + 1)
        impulse[0] = 1.0
        h = signal.sosfilt(self._sos, impulse)
        self._noise_power = float(np.max(np.maximum(ws, WRENCH_STD_FLOOR)) ** 2 * np.sum(h * h))
        self._rho = np.array([params.rho_x, params.rho_y])
        self._zi_unit = signal.sosfilt_zi(self._sos)
        self._block_maps: dict[int, tuple] = {}
        self._settle = int(np.ceil(SETTLE_CYCLES / (self.cutoff_hz * self.dt)))
        self._wrench_gate = None if check_gate(outlier_gate) is None else wrench_gate(self.dt, ws, outlier_gate)
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self, S0=None) -> Estimate:
        """Start over from the prior ``S0`` (default the identity, i.e. an uncalibrated sensor)."""
        S0 = np.eye(3) if S0 is None else np.asarray(S0, dtype=float)
        if S0.shape != (3, 3) or not np.all(np.isfinite(S0)):
            raise EstimatorConfigError(f"S0 must be a finite 3x3 matrix, got shape {S0.shape}")
        self._p0 = S0.reshape(9).copy()
        self._A = np.zeros((9, 9))
        self._b = np.zeros(9)
        self._G = np.zeros((3, 3))
        self._n_eff = 0.0
        self._break_chain()
        self._S = S0.copy()
        self._exc = 0.0
        self._cond = float(np.linalg.cond(S0))
        self._t = 0
        self._res_fast = 0.0
        self._res_slow = 0.0
        self._armed_after = CHANGE_WARMUP_TIME / self.dt
        self.changes: list[int] = []  # sample counts at which a jump of S was detected
        if self._wrench_gate is not None:
            self._wrench_gate.reset()
        return self._estimate(Health.NOT_EXCITED, reason="no data yet")

    @property
    def S(self) -> np.ndarray:
        """The current estimate of S."""
        return self._S.copy()

    @property
    def excitation(self) -> float:
        """Smallest-direction power of the filtered reading over the filtered sensor-noise power [-]."""
        if self._n_eff <= 0:
            return 0.0
        return float(np.linalg.eigvalsh(self._G / self._n_eff)[0] / self._noise_power)

    # ------------------------------------------------------------------ updates
    def update(self, measurement, u) -> Estimate:
        """One sample: ``measurement = (theta, X, Y)`` (vision), ``u = (M, f_x, f_y)`` (raw sensor reading)."""
        sample = self._validated_sample(measurement, u)
        if sample is None:
            self._absorb_with_gaps(np.full((1, 3), np.nan), np.full((1, 3), np.nan), np.zeros(1, dtype=bool))
            return self._estimate(Health.INVALID_INPUT, reason="sample with NaN or wrong shape skipped")
        return self.update_block(sample[0][None, :], sample[1][None, :])

    def update_block(self, measurements, inputs) -> Estimate:
        """Absorb consecutive samples at once: ``measurements`` (n, 3) vision, ``inputs`` (n, 3) raw readings.

        Rows with NaN are skipped (the difference chain restarts after them). Returns the estimate after the block.
        """
        Y = np.asarray(measurements, dtype=float)
        U = np.asarray(inputs, dtype=float)
        if Y.ndim != 2 or U.ndim != 2 or Y.shape[1] != 3 or U.shape[1] != 3 or len(Y) != len(U):
            return self._estimate(Health.INVALID_INPUT,
                                  reason=f"block shapes {Y.shape} and {U.shape}; expected (n, 3) and (n, 3)")
        valid = np.all(np.isfinite(Y), axis=1) & np.all(np.isfinite(U), axis=1)
        flagged = verdicts = None
        if self._wrench_gate is not None and valid.any():
            U = U.copy()
            U[valid], verdicts = self._wrench_gate(U[valid])
            flagged = block_health(verdicts)
        if valid.all():
            self._absorb(Y, U)
        else:
            self._absorb_with_gaps(Y, U, valid)
        health, reason = self._solve()
        if not valid.all():
            return self._estimate(Health.INVALID_INPUT, reason=f"{int((~valid).sum())} sample(s) with NaN skipped")
        if flagged is not None and health != Health.SOLVER_FAILED:
            return self._estimate(flagged, reason=f"{int(np.count_nonzero(verdicts))} force reading(s) failed the gate")
        return self._estimate(health, reason=reason)

    def _absorb_with_gaps(self, Y: np.ndarray, U: np.ndarray, valid: np.ndarray) -> None:
        """Short gaps of invalid samples are bridged (pose extrapolated, reading held) and the filter output around
        them is muted for a settle time; longer gaps restart the difference chain."""
        n = len(Y)
        start = i = 0
        while i < n:
            if valid[i]:
                i += 1
                continue
            j = i
            while j < n and not valid[j]:
                j += 1
            if i > start:
                self._absorb(Y[start:i], U[start:i])
            gap = j - i
            if self._gap_run + gap <= MAX_GAP_FILL and len(self._raw_pose) == 2:
                p0, p1 = self._raw_pose
                steps = np.arange(1, gap + 1)[:, None]
                self._absorb(p1 + steps * (p1 - p0), np.repeat(self._last_u[None, :], gap, axis=0), filled=True)
                self._gap_run += gap
                self._mute_until = self._chain_samples + self._settle
            else:
                self._break_chain()
                self._mute_until = RESTART_SETTLE_FACTOR * self._settle
            start = i = j
        if start < n:
            self._absorb(Y[start:], U[start:])

    def _break_chain(self) -> None:
        """Restart the difference chain (at reset and after an invalid sample)."""
        self._hist_q = np.zeros((0, 3))
        self._hist_r = np.zeros((0, 9))
        self._raw_pose = np.zeros((0, 3))
        self._gap_run = 0
        self._last_u = None
        self._chain_samples = 0
        self._mute_until = 0
        self._zi = None

    def _absorb(self, Y: np.ndarray, U: np.ndarray, filled: bool = False) -> None:
        """Common filter, second differences and information update for a run of valid samples."""
        p = self.params
        if not filled:
            self._gap_run = 0
        n_new = len(Y)
        self._t += n_new
        if self._zi is None:
            # Start of a chain: the payload is taken at rest at the first pose, with zero wrench before it, so the
            # position channels start in the filter's steady state and the regressor channels at zero.
            self._zi = np.zeros((self._sos.shape[0], N_CHANNELS, 2))
            self._zi[:, :3, :] = self._zi_unit[:, None, :] * Y[0][None, :, None]
        if self.wrench_hold == "point":
            wbar = U
        else:
            prev = np.zeros((1, 3)) if self._last_u is None else self._last_u[None, :]
            wbar = 0.5 * (np.concatenate([prev, U[:-1]]) + U)
        self._last_u = U[-1].copy()
        self._raw_pose = np.concatenate([self._raw_pose, Y])[-2:]
        c, s = np.cos(Y[:, 0])[:, None], np.sin(Y[:, 0])[:, None]
        raw = np.concatenate([Y, wbar, c * wbar, s * wbar], axis=1)
        filt = self._filter(raw)
        Q = np.concatenate([self._hist_q, filt[:, :3]])
        R = np.concatenate([self._hist_r, filt[:, 3:]])
        first = self._chain_samples - len(self._hist_q)  # chain index of Q[0]
        self._hist_q, self._hist_r = Q[-2:], R[-2:]
        self._chain_samples += n_new
        n = len(Q) - 2
        if n <= 0:
            return
        # eq. (1) left sides at the middle samples j = 1..len(Q)-2: F[m X''] = D^2 F[m X] (F and D^2 commute).
        acc = (Q[2:] - 2.0 * Q[1:-1] + Q[:-2]) / (self.dt * self.dt)
        yf = acc * np.array([p.I_G, p.m, p.m])
        Rm = R[1:-1]
        rf, crf, srf = Rm[:, 0:3], Rm[:, 3:6], Rm[:, 6:9]
        # Regression rows H (n, 3, 9) on p = (s1, s2, s3).
        H = np.zeros((n, 3, 9))
        rho_x, rho_y = self._rho
        H[:, 0, 0:3] = rf
        H[:, 0, 3:6] = -rho_y * rf
        H[:, 0, 6:9] = rho_x * rf
        H[:, 1, 3:6] = crf
        H[:, 1, 6:9] = -srf
        H[:, 2, 3:6] = srf
        H[:, 2, 6:9] = crf
        if self._lam < 1.0:
            decay = self._lam ** np.arange(n - 1, -1, -1)
            total = self._lam ** n
        else:
            decay = np.ones(n)
            total = 1.0
        # The filter's start-up transient is not used: zero weight for the first settle samples of a chain.
        chain_index = first + 1 + np.arange(n)
        weight = decay * (chain_index >= max(self._settle, self._mute_until))
        if self.change_detection and self._detect_change(H, yf, weight):
            # The filters still hold readings from before the jump: mute them for another settle time.
            self._mute_until = int(chain_index[-1]) + self._settle
            weight = np.zeros(n)
        Hw = H * (self._row_w[None, :, None] * weight[:, None, None])
        self._A = total * self._A + np.einsum("nki,nkj->ij", Hw, H)
        self._b = total * self._b + np.einsum("nki,nk->i", Hw, yf)
        self._G = total * self._G + np.einsum("n,ni,nj->ij", weight, rf, rf)
        self._n_eff = total * self._n_eff + float(weight.sum())

    def _filter(self, raw: np.ndarray) -> np.ndarray:
        """The common filter F on (n, channels) samples, continuing from the stored state.

        Short blocks use the filter's exact block map (built once per block length from ``sosfilt`` itself), which
        costs three small matrix products instead of ``sosfilt``'s per-call overhead.
        """
        n = len(raw)
        if n > MAX_BLOCK_MAP:
            out, self._zi = signal.sosfilt(self._sos, raw.T, axis=-1, zi=self._zi)
            return out.T
        G, Phi, Psi, L = self._block_map(n)
        ns = self._sos.shape[0]
        z = self._zi.transpose(0, 2, 1).reshape(2 * ns, -1)  # state index 2 s + i
        out = G @ raw + Phi @ z
        self._zi = (Psi @ z + L @ raw).reshape(ns, 2, -1).transpose(0, 2, 1).copy()
        return out

    def _block_map(self, n: int):
        maps = self._block_maps.get(n)
        if maps is None:
            ns = self._sos.shape[0]
            nz = 2 * ns
            y_in, zf_in = signal.sosfilt(self._sos, np.eye(n), axis=-1, zi=np.zeros((ns, n, 2)))
            basis = np.zeros((ns, nz, 2))
            for sec in range(ns):
                for i in range(2):
                    basis[sec, 2 * sec + i, i] = 1.0
            y_z, zf_z = signal.sosfilt(self._sos, np.zeros((nz, n)), axis=-1, zi=basis)
            G = y_in.T  # (n, n): output k from input j
            Phi = y_z.T  # (n, nz): output k from initial state
            Psi = zf_z.transpose(0, 2, 1).reshape(nz, nz)  # final state from initial state
            L = zf_in.transpose(0, 2, 1).reshape(nz, n)  # final state from input j
            maps = self._block_maps[n] = (G, Phi, Psi, L)
        return maps

    def _detect_change(self, H: np.ndarray, yf: np.ndarray, weight: np.ndarray) -> bool:
        """Compare the fast and slow power of the residuals against the current S_hat; discount on a jump."""
        used = weight > 0
        if not used.any():
            return False
        res = yf[used] - H[used] @ self._S.reshape(9)
        q = float(np.mean(res * res @ self._row_w))
        n = int(used.sum())
        a_fast = np.exp(-n * self.dt / CHANGE_FAST_TIME)
        self._res_fast = a_fast * self._res_fast + (1.0 - a_fast) * q
        if self._n_eff < self._armed_after:
            self._res_slow = self._res_fast
            return False
        if self._res_fast > self.change_threshold * self._res_slow:
            self._A *= CHANGE_DISCOUNT
            self._b *= CHANGE_DISCOUNT
            self._G *= CHANGE_DISCOUNT
            self._n_eff *= CHANGE_DISCOUNT
            self._armed_after = self._n_eff + CHANGE_WARMUP_TIME / self.dt
            self.changes.append(self._t)
            return True
        a_slow = np.exp(-n * self.dt / CHANGE_SLOW_TIME)
        self._res_slow = a_slow * self._res_slow + (1.0 - a_slow) * q
        return False

    def _solve(self) -> tuple[Health, str]:
        scale = max(float(np.trace(self._A)) / 9.0, 1.0)
        eps = self.prior_weight * scale
        try:
            p = np.linalg.solve(self._A + eps * np.eye(9), self._b + eps * self._p0)
        except np.linalg.LinAlgError:
            return Health.SOLVER_FAILED, "singular normal equations; S_hat held"
        if not np.all(np.isfinite(p)):
            return Health.SOLVER_FAILED, "non-finite solution; S_hat held"
        self._S = p.reshape(3, 3)
        exc = self._exc = self.excitation
        self._cond = cond = float(np.linalg.cond(self._S))
        if exc < self.min_excitation:
            return Health.NOT_EXCITED, f"excitation {exc:.3g} < {self.min_excitation:g}"
        if not np.isfinite(cond) or cond > self.max_cond:
            return Health.NOT_EXCITED, f"S_hat near singular (cond {cond:.3g} > {self.max_cond:g})"
        return Health.OK, ""

    def _estimate(self, health: Health, reason: str = "") -> Estimate:
        return Estimate({"S": self._S.copy(), "excitation": self._exc}, health,
                        {"reason": reason, "samples": self._t, "cond_S": self._cond})
