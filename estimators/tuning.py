"""Every tuning constant of the quarter-car estimators, in one place: the EKF's noise and prior, the MHE's horizon
and thresholds, the outlier gate's bound and run length.

The estimator modules read these (and re-export the names they always offered); a tuning change is a change here.
Values were chosen on the tuning seeds named beside each (the papers' cases and the estimators' own studies).
"""

from __future__ import annotations

from types import MappingProxyType

from fricenv.plants.sui_johansen import OMEGA_NOISE_VAR

__all__ = [
    "AB_P0_STD",
    "AB_Q_STD",
    "A_REF",
    "A_X_SLIP_BRAKING_Q_STD",
    "A_X_SPEED_Q_STD",
    "BRAKE_SETTLE_S",
    "DEFAULT_ARRIVAL",
    "DEFAULT_EKF_TUNING",
    "GATE_CHI2",
    "HORIZON",
    "JUMP_MU_MAX",
    "KT_P0_STD",
    "KT_Q_STD",
    "KT_TIMING_Q_STD",
    "MAX_REJECTIONS",
    "MISMATCH_NIS_MAX",
    "MISMATCH_STATES",
    "MISMATCH_TREND_NIS",
    "PAPER_TUNING",
    "P_FALSE",
    "REF_MARGIN_STD",
    "SLIP_PRIOR",
    "STATE_SCALES",
    "TIMING_STATES",
    "V_PRIOR",
    "brake_settle_samples",
]

# ---- the mismatch states (estimators.quarter_car_model.EXTRA_NAMES) of the env estimators
# brake gain k_T: prior spread, random walk per sample [-] (slow: a brake's timing is the torque error T_e's,
# estimators.ekf.torque_jump_std; a gain fast enough to follow it takes up a snow road's low friction)
KT_P0_STD, KT_Q_STD = 0.2, 0.01
# ... and for the models without the torque error (ekf-ax, mhe-ax: the speed from a_x; ekf-full, mhe-full: with
# B, C, E estimated, a torque noise let the curve's shape take the brake's timing): the gain takes that timing [-]
KT_TIMING_Q_STD = 0.1
AB_P0_STD, AB_Q_STD = 1.0, 0.05  # deceleration bias a_b: prior spread, random walk per sample [m/s^2]
# torque error T_e: prior spread (no command yet, so no error) [N m]; its noise comes from the commands' moves
# alone (estimators.ekf.torque_jump_std)
TE_P0_STD = 1.0
MISMATCH_STATES = ("k_T", "a_b")  # the brake gain and the drag of the env entries of the registry
TIMING_STATES = MISMATCH_STATES + ("T_e",)  # ... with a brake's torque error (ekf, mhe)

# ---- the augmented EKF (estimators.ekf), also the MHE's arrival-cost filter
DEFAULT_EKF_TUNING = {
    # initial prior spread, per state
    "P0_std": {"v": 1.0, "slip": 0.05, "theta": 0.4, "B": 3.0, "C": 0.5, "E": 3.0, "k_T": KT_P0_STD,
               "a_b": AB_P0_STD, "T_e": TE_P0_STD},
    # process noise per 10 ms sample: model error on v and slip, random walk on the parameters
    "Q_std": {"v": 0.01, "slip": 0.01, "theta": 0.002, "B": 0.02, "C": 0.005, "E": 0.02, "k_T": KT_Q_STD,
              "a_b": AB_Q_STD, "T_e": 0.0},
    "R": OMEGA_NOISE_VAR,  # wheel-speed noise variance [(rad/s)^2], Sui & Johansen Section IV
}
# a speed that follows the measured a_x (estimators.quarter_car_model, speed_from_a_x): its random walk per sample,
# three times the accelerometer's noise (0.1 m/s^2, the stand-in's and the env's) over a 10 ms sample [m/s]
A_X_SPEED_Q_STD = 0.003
# ... and its slip's random walk per sample once the brake has acted: the slip then follows the tire's force law,
# which the model holds only approximately (the road, a relaxation length, a brake that lags or is late), so the
# wheel speed moves the slip rather than the integrated speed. Free rolling keeps Q_std's 0.01: the slip is pinned
# at 0 and the wheel pins the speed. Chosen on the tuning seeds (validation.estimator_mismatch 0-2, the spike study
# 0-2): the largest that still flags every x0.5 wheel-speed spike. 0.01 / 0.03 / 0.05 / 0.07 / 0.1 missed 15 / 7 /
# 4 / 2 / 1 of 18 stops under a 0.6 m relaxation length; 0.1 let 2.8 % of the x0.5 spikes through.
A_X_SLIP_BRAKING_Q_STD = 0.07
V_PRIOR = 19.0  # a priori initial speed [m/s], Sui & Johansen Section IV
SLIP_PRIOR = 0.0  # a priori initial slip [-]

# ---- the regularized MHE (estimators.mhe)
HORIZON = 10  # N, Sui & Johansen Section IV
# Paper tuning, Section IV.A (theta only) and IV.B (theta, B, C, E).
PAPER_TUNING = MappingProxyType({
    "theta-only": MappingProxyType({"alpha": 0.01, "beta": 1.0, "delta": 0.1}),
    "all": MappingProxyType({"alpha": 0.01, "beta": 1.0, "delta": 0.8}),
})
# State scales D of the "scaled" reading (per group, as the paper tunes delta per group): the spread of the prior
# per window state; chosen on cases 1-4 (seeds 0-2) for the RMS of v and slip after 0.5 s. The torque error's,
# 100 N m, is a tenth of an ABS command's swing, set once and not tuned (the paper cases carry no T_e).
STATE_SCALES = MappingProxyType({
    "theta-only": MappingProxyType({"v": 0.3, "slip": 0.01, "theta": 0.04, "B": 2.0, "C": 0.4, "E": 2.0,
                                    "k_T": 0.1, "a_b": 0.5, "T_e": 100.0}),
    "all": MappingProxyType({"v": 0.3, "slip": 0.03, "theta": 0.03, "B": 1.0, "C": 0.2, "E": 1.0, "k_T": 0.1,
                             "a_b": 0.5, "T_e": 100.0}),
})
GATE_CHI2 = 25.0  # EKF-consistency gate of the arrival="ekf" MHE: squared Mahalanobis distance (estimators.mhe)
# Default arrival cost per group: the EKF arrival cost, with process noise in the window, for both; the paper's
# prior terms and hard dynamics are arrival="paper", model_error=None.
DEFAULT_ARRIVAL = MappingProxyType({"theta-only": "ekf", "all": "ekf"})

# ---- the outlier gate (estimators.outliers)
P_FALSE = 1e-5  # default per-sample false-rejection probability of a consistent filter [-]
MAX_REJECTIONS = 10  # default number of samples in a row that may be rejected before a re-initialisation [-]

# ---- the mismatch rule and reference speed of the EKF's wheel-speed gate (estimators.mismatch)
JUMP_MU_MAX = 1.5  # largest friction coefficient a road may show in a run of failing samples (the presets peak at 1) [-]
A_REF = 12.0  # deceleration bound of the reference speed, about 1.2 g (the presets peak at 1.0) [m/s^2]
REF_MARGIN_STD = 2.0  # the reference follows the wheel speed less this many noise std's [-]
MISMATCH_NIS_MAX = 10.0  # a persistent innovation above this many gate bounds is taken as outliers (M1) [-]
MISMATCH_TREND_NIS = 0.25  # an a_x-speed filter's run may start at a passing sample of this many gate bounds (M2') [-]

# ---- the EKF/RLS's wheel-speed gate (estimators.speed_reference)
# the torque a brake applies lies within its commands over this span: rule (B4); the time constant over which the
# torque error T_e of the EKF and the MHE fades [s]
BRAKE_SETTLE_S = 0.1


def brake_settle_samples(dt: float) -> int:
    """The commands of the ``BRAKE_SETTLE_S`` span at sample time ``dt``, the one held now included."""
    return round(BRAKE_SETTLE_S / dt) + 1
