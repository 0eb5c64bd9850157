"""Friction from wheel speed, torque and a_x: the EKF/RLS method of Li, Du & Li, for the quarter car and two axles.

Steps per sample (Section III of the paper), for n wheels (quarter car n = 1, two-axle model n = 2):

1. Vehicle speed, nonlinear filter eqs. (4)-(6): ``y' = -R Sat(y - x)`` with x the reference wheel surface speed
   (the quarter car's only wheel; on two axles the slowest wheel in traction, the fastest in braking), ``Sat``
   eq. (6) with width ``d``, and the rate R the torque feedforward of eq. (5), ``R_g = |sum T| / (m_eff R_w)``
   (``m_eff = m + n I_w / R_w^2``; the paper's 466.5 is this number for its Table I), optionally corrected by the
   a_x loop of Fig. 2: ``c' = K (|a_x| - R_g - c)``, ``R = max(R_g + dz(c), 0)`` (discretized exactly, trapezoid
   over each sample; ``dz`` an optional dead zone, 0 by default). Whenever the wheel slips by more than d the
   filter integrates R, and it follows the wheel when it rolls freely. With ``braking_reference`` and no torque
   driving the wheel the loop reads the deceleration ``max(-a_x, 0)`` in place of ``|a_x|``
   (:func:`~estimators.speed_reference.a_x_loop_step`).

   Reading of the a_x loop (Fig. 2 is a block diagram we only have the caption of; K = 100 1/s in Table I). Taken
   literally (``correction_gain=PAPER_CORRECTION_GAIN``), the loop makes R follow |a_x| within 10 ms, so the
   filter integrates the measured acceleration -- which the paper's own text says this filter is designed not to
   do ("does not need to integrate the measurement value of the acceleration ... the integration ... will induce
   even larger noise"). A lower gain (a complementary-filter reading: a_x corrects R_g's bias at low frequency)
   does not cure it: the correction has unit gain at zero frequency, so the speed error still performs the random
   walk ``sigma_ax sqrt(dt t)`` of integrated a_x noise (0.007 m/s after 6 s for uniform +-0.05), which in
   traction (slip 0.8 %, 0.08 m/s at 10 m/s) is a 9 % slip error and a mu error of about 0.08. Measured
   (``fricenv paper ekf-rls``, worst of seeds 0-7, a_x noise +-0.05): K = 100: 0.137, K = 1: 0.118, K = 0.3:
   0.087, K = 0.1: 0.057, K = 0: 0.028. On this quarter car the torque feedforward eq. (5) is the exact
   acceleration at steady slip (m_eff includes the wheel inertia), so the loop has nothing to correct and only
   adds noise: the estimators default to ``correction_gain=0`` (``DEFAULT_CORRECTION_GAIN``), which meets the
   0.05 target; the paper's loop is the option ``correction_gain=100``. The loop is what makes the filter robust
   to an error in the torque-to-acceleration map: with the vehicle mass 2 % off, K = 0 loses the speed (mu error
   1.9) while K = 100 stays at 0.10. ``correction_deadband`` (a dead zone on the correction) is offered as a
   middle way: it ignores noise-level discrepancies and bounds the drift under large map errors to about the
   dead zone times the time (mass 10 % off: mu error 0.45 with K = 1 and a 0.05 m/s^2 dead zone, against 0.98
   for K = 0 and 0.08 for K = 100).
   The effects of a real plant are map errors of this kind: a brake gain (the torque feedforward is off by the
   gain), drag (a deceleration the torque does not explain), a brake lag or delay (the feedforward leads the
   deceleration). The registry's ``ekf-rls`` (what the braking env and the robustness study run) therefore closes
   the loop at ``ENV_CORRECTION_GAIN`` = 20 1/s: on the effect grid at its high sizes (dry, wet, snow, ABS and
   open-loop, seed 0, ``validation.estimator_mismatch``) K = 10 took the rms speed error from 2.06 to 0.20 m/s
   (brake gain 1.25), 3.55 to 0.28 (drag), 0.45 to 0.19 (80 ms lag), 0.38 to 0.19 (60 ms delay), for 0.10 ->
   0.14 on the nominal plant. With rule (B5) of :mod:`estimators.speed_reference` (a free-rolling wheel is the
   car's speed) a faster loop pays: ``fricenv paper robustness --estimators ekf-rls`` (seeds 0-2, rms after the
   first 0.5 s of braking, m/s), K = 10 / 20 / 30 / 40: nominal 0.085 / 0.083 / 0.081 / 0.083, 80 ms lag 0.215 /
   0.146 / 0.113 / 0.094, 60 ms delay 0.190 / 0.141 / 0.123 / 0.116; stops missing the target (of 18; lag, delay,
   relaxation 0.3 / 0.6 m) 3, 3, 3 / 8 at K = 10; 2, 0, 2 / 8 at 20; 0, 0, 3 / 9 at 30 and 40 (the worst sample
   under the 0.6 m relaxation length 1.40 m/s at 20, 1.56 at 40). The paper's figures (``fricenv paper
   ekf-rls``) keep K = 0.
   While braking, the registry's ``ekf-rls`` does not let a wheel faster than the car pull the estimate up, and its
   wheel-speed gate predicts a braked wheel at most at the car's speed; with no torque it follows the free-rolling
   wheel (``braking_reference``, rules (B1)-(B3) and (B5) of :mod:`estimators.speed_reference`).
2. Slip per wheel, eq. (3): ``S = (omega R_w - y) / max(y, omega R_w)`` (positive in traction).
3. Tire force, EKF of eqs. (7)-(8) on ``(a_x, a_omega_i, F_i)`` with the tire stiffness prediction
   ``F_i(k+1) = C_s S_i(k)`` and the measurement ``z = a_x = sum F_i / m`` (generic steps from
   :mod:`estimators.ekf`, Joseph form).
4. Slip slope, RLS with forgetting, eqs. (10)-(14): ``y = sum F_i``, ``phi = sum F_zi S_i``; skipped (health
   ``NOT_EXCITED``, k_s held) while ``|phi|`` is below ``PHI_MIN_SLIP`` times the total load.
5. Friction. The paper's map ``mu = 0.1 k_s + 0.02`` was fitted to its tire. For this project's Magic Formula
   roads we use the family relation instead: with the tire's shape (B, C, E) fixed and the road scaling theta
   (the curve family mu = theta g(S), g the Magic Formula with theta = 1), the regression
   ``F / F_z = k_s S`` at the data's load-weighted slip S_bar gives ``theta = k_s S_bar / g(S_bar)`` and the
   peak friction ``mu = theta max g``. As S_bar -> 0, ``g(S)/S -> B C`` and the map is linear,
   ``mu = k_s max(g) / (B C)`` (dry shape: mu = 0.0584 k_s, the project's counterpart of 0.1 k_s + 0.02). It is
   exact for any slip on the family, so it does not drift down when braking moves the slip into the curved part
   (the paper's Fig. 11 shows that drift with a linear map). :class:`estimators.slope_maps.MagicFormulaFamilyMap` implements it;
   :class:`estimators.slope_maps.LinearMap` is the paper's form, used on the paper's own two-axle set-up (:class:`TwoAxleEkfRls`):
   there the Dugoff tire's force is ``C_s S / (1 - S)`` whatever mu is until the slip reaches about
   ``mu F_z / (2 C_s)`` (6.8 % on the front axle at mu = 0.9), so below that the slip slope carries no
   information on mu and no map can recover it; the paper's empirical map is reported as is.
   Also reported: ``mu_peak``, the largest ``|sum F| / sum F_z`` seen so far, which equals the peak friction once
   the data reach the peak of the curve (and is a lower bound before).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimators.base import Estimate, Estimator, EstimatorConfigError, Health, check_dt
from estimators.curve_shape import DEFAULT_BANK, ShapeBank, ShapeFit, ShapeFitParams
from estimators.ekf import ekf_predict, ekf_update
from estimators.outliers import DEFAULT_GATE, GateParams, Verdict, check_gate
from estimators.slope_maps import PAPER_MAP, MagicFormulaFamilyMap
from estimators.speed_reference import FREE_ROLLING_RATE, WheelSpeedGate, a_x_loop_step, speed_step
from estimators.tuning import REF_MARGIN_STD
from fricenv.plants.quarter_car import PAPER_PARAMS, QuarterCarParams
from fricenv.plants.sui_johansen import OMEGA_NOISE_STD
from fricenv.plants.tire import DRY, MagicFormula

__all__ = [
    "DEFAULT_CORRECTION_GAIN",
    "ENV_CORRECTION_GAIN",
    "PAPER_CORRECTION_GAIN",
    "EkfRlsConfig",
    "EkfRlsCore",
    "QuarterCarEkfRls",
    "TwoAxleEkfRls",
]

SAT_WIDTH = 0.01  # d of eq. (6) [m/s]
PAPER_CORRECTION_GAIN = 100.0  # K of Fig. 2 / Table I [1/s]: the paper-literal a_x loop
CORRECTION_GAIN = PAPER_CORRECTION_GAIN  # EkfRlsConfig's default (the paper's); the estimators default to 0
DEFAULT_CORRECTION_GAIN = 0.0  # the estimators' default: eq. (5) torque feedforward alone (module docstring)
ENV_CORRECTION_GAIN = 20.0  # K of the registry's ``ekf-rls`` (the env's): robust to brake and drag effects [1/s]
FORGETTING = 0.99  # RLS forgetting factor, in (0.9, 1) as the paper asks
C_S = 50000.0  # tire stiffness of eq. (7) [N/unit slip], Table I
PHI_MIN_SLIP = 1e-3  # RLS update only when the load-weighted |slip| exceeds this [-]
RLS_P0 = 10.0  # initial RLS covariance [(1/unit slip)^2]
KS0 = 10.0  # initial slip slope [1/unit slip]
Q_STD = {"a_x": 0.5, "a_w": 50.0, "F": 300.0}  # EKF process noise per sample [m/s^2, rad/s^2, N]
AX_STD_MIN = 0.01  # floor of the a_x noise standard deviation in the EKF [m/s^2]


@dataclass(frozen=True)
class EkfRlsConfig:
    """Vehicle and tuning constants of the EKF/RLS estimator."""

    m: float  # mass whose acceleration a_x measures [kg]
    I_w: float  # wheel inertia [kg m^2]
    R_w: float  # wheel radius [m]
    Fz: tuple  # vertical load per wheel [N]
    C_s: float = C_S  # tire stiffness of eq. (7) [N/unit slip]
    d: float = SAT_WIDTH  # Sat width of eq. (6) [m/s]
    K: float = CORRECTION_GAIN  # a_x correction gain of Fig. 2 [1/s]; 0 disables the loop
    deadband: float = 0.0  # dead zone on the a_x correction [m/s^2]; 0: the paper's loop
    forgetting: float = FORGETTING  # RLS forgetting factor [-]
    ax_std: float = AX_STD_MIN  # a_x noise standard deviation assumed by the EKF [m/s^2]
    omega_std: float = OMEGA_NOISE_STD  # wheel-speed noise standard deviation assumed by the gate [rad/s]
    outlier_gate: GateParams | None = DEFAULT_GATE  # the wheel-speed gate (WheelSpeedGate); None: off
    braking_reference: bool = False  # rules (B1)-(B3) while braking, (B5) without torque; False: the paper's eq. (4)

    def __post_init__(self):
        for name in ("m", "I_w", "R_w", "C_s", "d", "ax_std", "omega_std"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise EstimatorConfigError(f"EkfRlsConfig.{name} must be finite and > 0, got {value!r}")
        if not (np.isfinite(self.deadband) and self.deadband >= 0):
            raise EstimatorConfigError(f"EkfRlsConfig.deadband must be finite and >= 0, got {self.deadband!r}")
        if not (np.isfinite(self.K) and self.K >= 0):
            raise EstimatorConfigError(f"EkfRlsConfig.K must be finite and >= 0 (0: no a_x loop), got {self.K!r}")
        if not 0.9 <= self.forgetting <= 1.0:
            raise EstimatorConfigError(f"forgetting must be in [0.9, 1] (paper: (0.9, 1)), got {self.forgetting}")
        if len(self.Fz) < 1 or not all(np.isfinite(f) and f > 0 for f in self.Fz):
            raise EstimatorConfigError(f"Fz must be one positive load per wheel, got {self.Fz!r}")
        check_gate(self.outlier_gate)

    @property
    def overshoot_margin(self) -> float:
        """(B2): how far a wheel may run above the speed estimate and still be read as the car's speed [m/s]."""
        return REF_MARGIN_STD * self.omega_std * self.R_w

    @property
    def rest_band(self) -> float:
        """(J3) of :mod:`estimators.jump`, with the braking rules: a braked wheel within the wheel-speed noise
        margin of 0 is at rest [rad/s]; 0 (the rule off) without them."""
        return REF_MARGIN_STD * self.omega_std if self.braking_reference else 0.0

    @property
    def m_eff(self) -> float:
        """Mass of eq. (5)'s 466.5 = m_eff R_w: the car plus the wheels' rotary inertia [kg]."""
        return self.m + len(self.Fz) * self.I_w / self.R_w**2


class EkfRlsCore:
    """The four steps on traction-positive quantities (torques, forces, slips); see the module docstring."""

    def __init__(self, cfg: EkfRlsConfig, dt: float, mu_map, shape_fit: ShapeFit | None = None):
        self.cfg = cfg
        self.shape_fit = shape_fit  # step 6 (estimators.curve_shape), one estimator; None: off
        self.dt = check_dt(dt)
        self.mu_map = mu_map
        n = len(cfg.Fz)
        self.n = n
        self.Fz = np.asarray(cfg.Fz, dtype=float)
        self.Fz_total = float(self.Fz.sum())
        self.corr_factor = 1.0 - np.exp(-cfg.K * self.dt)  # exact discretization of c' = K (target - c)
        nx = 1 + 2 * n
        self.Q = np.diag([Q_STD["a_x"] ** 2] + [Q_STD["a_w"] ** 2] * n + [Q_STD["F"] ** 2] * n)
        self.R = np.array([[cfg.ax_std**2]])
        self.H = np.zeros((1, nx))
        self.H[0, 1 + n:] = 1.0 / cfg.m  # z = a_x = sum F / m (paper's H)
        self.A = np.zeros((nx, nx))  # eq. (7) Jacobian
        self.A[0, 1 + n:] = 1.0 / cfg.m
        for i in range(n):
            self.A[1 + i, 1 + n + i] = -cfg.R_w / cfg.I_w
        self.wheel_gate = None if cfg.outlier_gate is None else WheelSpeedGate(
            n, cfg.I_w, cfg.R_w, self.Fz, self.dt, cfg.omega_std, cfg.outlier_gate, cfg.rest_band)
        self.reset()

    def reset(self, v0: float | None = None) -> None:
        self.y = v0  # speed estimate [m/s]; None: initialized from the first wheel speed
        self.c = 0.0  # a_x correction of the rate [m/s^2]
        self.R_g = 0.0  # eq. (5) for the torque held over the coming sample [m/s^2]
        n = self.n
        self.x = np.zeros(1 + 2 * n)
        self.P = np.diag([1.0] + [100.0] * n + [1e6] * n)
        self.k_s = KS0
        self.P_rls = RLS_P0
        self.s_num = 0.0
        self.s_den = 0.0
        self.mu_peak = 0.0
        self.torque_prev = np.zeros(self.n)  # torque held since the last sample (for the wheel-speed gate)
        if self.wheel_gate is not None:
            self.wheel_gate.reset()
        if self.shape_fit is not None:
            self.shape_fit.reset()

    def _dead(self, c: float) -> float:
        """The correction applied to the rate: c outside the dead zone (+-deadband), shrunk towards 0."""
        db = self.cfg.deadband
        return float(np.sign(c)) * max(abs(c) - db, 0.0)

    def step(self, omega: np.ndarray, a_x: float, torque: np.ndarray) -> dict:
        cfg, n = self.cfg, self.n
        verdicts = [Verdict.ACCEPT] * n
        if self.wheel_gate is not None:  # outliers: the gate's prediction replaces a rejected wheel speed
            ceiling = np.inf  # (B3): a braked wheel is predicted at most at the car's speed estimate plus the margin
            if cfg.braking_reference and self.y is not None:
                ceiling = (self.y + cfg.overshoot_margin) / cfg.R_w
            omega, verdicts = self.wheel_gate(omega, self.torque_prev, ceiling)
        restarted = Verdict.REINIT in verdicts  # a friction jump (estimators.jump) or a lost track: the RLS forgets
        self.P_rls = RLS_P0 if restarted else self.P_rls  # the old road at once, the shape fit withholds it (step 6)
        self.torque_prev = np.array(torque, dtype=float)
        wr = omega * cfg.R_w
        T_total = float(torque.sum())
        x_ref = float(wr.min() if T_total > 0 else wr.max()) if n > 1 else float(wr[0])
        # 1. velocity filter, eqs. (4)-(6) with the a_x loop of Fig. 2, advanced from the previous sample to this
        # one: the rate is the previous torque's feedforward R_g (eq. (5), the torque held over the interval) plus
        # the a_x correction averaged over the interval (trapezoid), and Sat uses the newest wheel speed. (A
        # forward Euler step lags one sample behind a wheel that starts to slip, and the filter, moving at the
        # car's own acceleration, never recovers such a lag.)
        if self.y is None:
            y = x_ref
        else:
            c_new = a_x_loop_step(self.c, a_x, self.R_g, self.corr_factor, cfg.braking_reference and T_total <= 0)
            rate = max(self.R_g + 0.5 * (self._dead(self.c) + self._dead(c_new)), 0.0)
            free = cfg.braking_reference and self.R_g <= FREE_ROLLING_RATE  # (B5): the torque held leaves the wheel free
            y = speed_step(self.y, x_ref, rate, self.dt, cfg.d, cfg.braking_reference and T_total < 0,
                           cfg.overshoot_margin, free)  # eq. (4), (B1)-(B2), (B5)
            self.c = c_new
        self.y = y
        self.R_g = abs(T_total) / (cfg.m_eff * cfg.R_w)  # eq. (5)
        # 2. slip, eq. (3), at the current speed estimate
        S = (wr - y) / np.maximum(np.maximum(y, wr), 0.1)
        # 3. force EKF, eqs. (7)-(8): measurement update with a_x, then the prediction F(k+1) = C_s S(k)
        xk, Pk, _ = ekf_update(self.x, self.P, np.array([a_x]), self.H @ self.x, self.H, self.R)
        F = xk[1 + n:].copy()
        x_next = np.empty_like(xk)
        x_next[0] = F.sum() / cfg.m
        x_next[1:1 + n] = (-F * cfg.R_w + torque) / cfg.I_w
        x_next[1 + n:] = cfg.C_s * S
        self.x, self.P = ekf_predict(x_next, self.A, Pk, self.Q)
        # 4. RLS on the slip slope, eqs. (10)-(14)
        F_total = float(F.sum())
        phi = float(self.Fz @ S)
        lam = cfg.forgetting
        excited = abs(phi) > PHI_MIN_SLIP * self.Fz_total
        if excited:
            e = F_total - phi * self.k_s  # (11)
            denom = lam + phi * self.P_rls * phi
            K = self.P_rls * phi / denom  # (12)
            self.P_rls = (self.P_rls - K * phi * self.P_rls) / lam  # (13)
            self.k_s += K * e  # (14)
            s_eff = abs(phi) / self.Fz_total
            self.s_num = lam * self.s_num + phi * phi * s_eff
            self.s_den = lam * self.s_den + phi * phi
        # 5. friction
        s_bar = self.s_num / self.s_den if self.s_den > 0 else 0.0
        mu = self.mu_map(self.k_s, s_bar)
        mu_util = abs(F_total) / self.Fz_total
        self.mu_peak = max(self.mu_peak, mu_util)
        # 6. the curve's shape (estimators.curve_shape): peak slip, and the peak friction once the fit is used
        peak_slip = np.nan
        if self.shape_fit is not None:
            self.shape_fit.restart(np.array([restarted]))  # nothing unless the gate restarted
            self.shape_fit.update(np.array([abs(phi) / self.Fz_total]), np.array([mu_util]), np.array([y]),
                                  np.array([True]))
            slip_fit, mu_fit = self.shape_fit.outputs()
            peak_slip = float(slip_fit[0])
            mu = float(mu_fit[0]) if np.isfinite(mu_fit[0]) else mu
        return {"v": y, "S": S, "F": F, "k_s": self.k_s, "mu": mu, "mu_peak": self.mu_peak,
                "mu_utilized": mu_util, "s_bar": s_bar, "excited": excited, "verdict": max(verdicts),
                "peak_slip": peak_slip}


def _health(out: dict) -> Health:
    """Health of one EKF/RLS step: the gate's verdict first, then the RLS excitation."""
    if out["verdict"] == Verdict.REJECT:
        return Health.OUTLIER
    if out["verdict"] == Verdict.REINIT:
        return Health.REINITIALISED
    return Health.OK if out["excited"] else Health.NOT_EXCITED


class QuarterCarEkfRls(Estimator):
    """EKF/RLS on the quarter car: ``update((omega, a_x), T_b)``.

    Quarter-car conventions: ``T_b > 0`` brakes, ``slip`` and ``F_x`` are positive when braking, ``a_x`` is
    negative when braking. Internally the paper's traction-positive signs are used.

    :param dt: sample time [s].
    :param p: quarter-car parameters (m, J, r, F_z).
    :param shape: tire shape (B, C, E) of the friction family map (default: dry asphalt).
    :param mu_map: a map ``(k_s, s_bar) -> mu`` overriding the family map (e.g. ``PAPER_MAP``).
    :param ax_std: a_x noise standard deviation assumed by the force EKF [m/s^2].
    :param forgetting: RLS forgetting factor.
    :param correction_gain: K of the a_x loop (Fig. 2) [1/s]; default 0, the torque feedforward of eq. (5) alone
        (module docstring); ``PAPER_CORRECTION_GAIN`` (100) is the paper-literal loop.
    :param correction_deadband: dead zone on the a_x correction [m/s^2] (0: none).
    :param omega_std: wheel-speed noise standard deviation assumed by the outlier gate [rad/s].
    :param outlier_gate: the wheel-speed gate (:class:`WheelSpeedGate`; ``Health.OUTLIER`` for a rejected sample,
        ``REINITIALISED`` when a wheel's gate restarts from it), or None to trust every sample.
    :param shape_bank: candidate curve shapes of the online shape fit (:mod:`estimators.curve_shape`), which gives
        ``peak_slip`` (the estimated curve's peak slip) and, once it has data, ``mu`` (the peak friction of the
        fitted shape); None: no fit (``peak_slip`` is that of ``shape``, ``mu`` the map's). With a custom
        ``mu_map`` there is no fit: the map is used as it is.
    :param shape_params: tuning of the shape fit.
    :param braking_reference: rules (B1)-(B3) while braking, (B5) without torque; False: the paper's eq. (4) and an
        unbounded gate prediction.
    """

    measurement_columns = ("omega", "a_x")
    input_columns = ("T_b",)
    names = ("v", "slip", "F_x", "k_s", "mu", "mu_peak", "mu_utilized", "peak_slip")

    def __init__(self, dt: float = 0.01, p: QuarterCarParams = PAPER_PARAMS, shape: MagicFormula = DRY,
                 mu_map=None, ax_std: float = AX_STD_MIN, forgetting: float = FORGETTING,
                 correction_gain: float = DEFAULT_CORRECTION_GAIN, correction_deadband: float = 0.0,
                 omega_std: float = OMEGA_NOISE_STD, outlier_gate: GateParams | None = DEFAULT_GATE,
                 shape_bank: ShapeBank | None = DEFAULT_BANK, shape_params: ShapeFitParams | None = None,
                 braking_reference: bool = False):
        cfg = EkfRlsConfig(m=p.m, I_w=p.J, R_w=p.r, Fz=(p.Fz,), ax_std=ax_std, forgetting=forgetting,
                           K=correction_gain, deadband=correction_deadband, omega_std=omega_std,
                           outlier_gate=outlier_gate, braking_reference=bool(braking_reference))
        coupling = p.J / (p.m * p.r**2)  # the speed filter's error per unit slip speed (estimators.curve_shape)
        fit = ShapeFit(1, shape_bank, shape_params, coupling) if shape_bank is not None and mu_map is None else None
        self.core = EkfRlsCore(cfg, dt, mu_map or MagicFormulaFamilyMap(shape), fit)
        self.prior_peak_slip = float(fit.outputs()[0][0]) if fit is not None else shape.peak_slip
        self._last = None
        self.reset()

    def reset(self, v0: float | None = None) -> Estimate:
        self.core.reset(v0)
        self._last = {"v": np.nan if v0 is None else float(v0), "slip": 0.0, "F_x": 0.0, "k_s": KS0,
                      "mu": self.core.mu_map(KS0, 0.0), "mu_peak": 0.0, "mu_utilized": 0.0,
                      "peak_slip": self.prior_peak_slip}
        return Estimate(dict(self._last), Health.NOT_EXCITED)

    def update(self, measurement, u) -> Estimate:
        sample = self._validated_sample(measurement, u)
        if sample is None:
            return Estimate(dict(self._last), Health.INVALID_INPUT, {"reason": "NaN or wrong shape; skipped"})
        y, uu = sample
        out = self.core.step(np.array([y[0]]), float(y[1]), np.array([-uu[0]]))
        peak_slip = self.prior_peak_slip if np.isnan(out["peak_slip"]) else out["peak_slip"]
        self._last = {"v": out["v"], "slip": float(-out["S"][0]), "F_x": float(-out["F"][0]), "k_s": out["k_s"],
                      "mu": out["mu"], "mu_peak": out["mu_peak"], "mu_utilized": out["mu_utilized"],
                      "peak_slip": peak_slip}
        return Estimate(dict(self._last), _health(out), {"s_bar": out["s_bar"]})


class TwoAxleEkfRls(Estimator):
    """EKF/RLS on the paper's two-axle set-up: ``update((omega_f, omega_r, a_x), (T_f, T_r))``, paper signs.

    :param dt: sample time [s].
    :param params: :class:`fricenv.plants.two_axle.TwoAxleParams`.
    :param mu_map: ``(k_s, s_bar) -> mu``; default the paper's eq. (15), ``PAPER_MAP``.
    :param ax_std: a_x noise standard deviation assumed by the force EKF [m/s^2].
    :param forgetting: RLS forgetting factor.
    :param correction_gain: K of the a_x loop (Fig. 2) [1/s]; default 0 as for the quarter car;
        ``PAPER_CORRECTION_GAIN`` (100) is the paper-literal loop.
    :param correction_deadband: dead zone on the a_x correction [m/s^2] (0: none).
    :param omega_std: wheel-speed noise standard deviation assumed by the outlier gate [rad/s].
    :param outlier_gate: the wheel-speed gate (:class:`WheelSpeedGate`; ``Health.OUTLIER`` for a rejected sample,
        ``REINITIALISED`` when a wheel's gate restarts from it), or None to trust every sample.
    :param braking_reference: rules (B1)-(B3) while braking, (B5) without torque; False: the paper's eq. (4) and an
        unbounded gate prediction.
    """

    measurement_columns = ("omega_f", "omega_r", "a_x")
    input_columns = ("T_f", "T_r")
    names = ("v", "slip_f", "slip_r", "F_xf", "F_xr", "k_s", "mu", "mu_peak", "mu_utilized")

    def __init__(self, dt: float = 0.01, params=None, mu_map=None, ax_std: float = AX_STD_MIN,
                 forgetting: float = FORGETTING, correction_gain: float = DEFAULT_CORRECTION_GAIN,
                 correction_deadband: float = 0.0, omega_std: float = OMEGA_NOISE_STD,
                 outlier_gate: GateParams | None = DEFAULT_GATE, braking_reference: bool = False):
        from fricenv.plants.two_axle import TABLE_I, axle_loads

        p = params or TABLE_I
        Fzf, Fzr = axle_loads(p)
        cfg = EkfRlsConfig(m=p.m, I_w=p.I_w, R_w=p.R_w, Fz=(Fzf, Fzr), C_s=p.C_s, ax_std=ax_std,
                           forgetting=forgetting, K=correction_gain, deadband=correction_deadband,
                           omega_std=omega_std, outlier_gate=outlier_gate,
                           braking_reference=bool(braking_reference))
        self.core = EkfRlsCore(cfg, dt, mu_map or PAPER_MAP)
        self.reset()

    def reset(self, v0: float | None = None) -> Estimate:
        self.core.reset(v0)
        self._last = {k: 0.0 for k in self.names}
        self._last["v"] = np.nan if v0 is None else float(v0)
        return Estimate(dict(self._last), Health.NOT_EXCITED)

    def update(self, measurement, u) -> Estimate:
        sample = self._validated_sample(measurement, u)
        if sample is None:
            return Estimate(dict(self._last), Health.INVALID_INPUT, {"reason": "NaN or wrong shape; skipped"})
        y, uu = sample
        out = self.core.step(y[:2], float(y[2]), uu)
        self._last = {"v": out["v"], "slip_f": float(out["S"][0]), "slip_r": float(out["S"][1]),
                      "F_xf": float(out["F"][0]), "F_xr": float(out["F"][1]), "k_s": out["k_s"],
                      "mu": out["mu"], "mu_peak": out["mu_peak"], "mu_utilized": out["mu_utilized"]}
        return Estimate(dict(self._last), _health(out), {"s_bar": out["s_bar"]})
