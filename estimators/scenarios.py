"""Log generators for the paper cases, simulated with the quarter-car plant (:func:`fricenv.plants.quarter_car.step`).

MHE cases 1-4 (Sui & Johansen, Section IV): v(0) = 20 m/s, lambda(0) = 0.01, 10 ms samples, Gaussian noise of
variance 0.2 (rad/s)^2 on the wheel speed; dry (eq. (4)) in cases 1 and 3, snow (eq. (5)) in cases 2 and 4;
theta alone estimated in cases 1-2, (theta, B, C, E) in cases 3-4.

The paper does not state its brake torque. We use an ABS-like excitation (:func:`abs_like_torque`): the torque
ramps up at ``APPLY_RATE`` times the road's peak torque ``r F_z mu_max`` per second while the true slip is below the
band's upper edge, and falls at ``RELEASE_RATE`` times it once the slip has crossed the upper edge, until it is
below the lower edge: the hysteresis cycle of a rule-based ABS, which keeps slip in ``SLIP_BAND`` (dry: 0.03-0.2,
around the peak 0.19; snow: 0.03-0.15, where its curve flattens). Each cycle sweeps the slip across the rising
part of the friction curve, which is what makes theta (and on dry B, C, E) observable.

EKF/RLS scenario (Li, Du & Li, Section IV.B): traction, then braking, on a road of peak friction 0.9 (the dry
curve with theta = 0.9): drive torque for ``TRACTION_TIME`` seconds, then a brake torque ramp, with the
longitudinal acceleration a_x logged (clean, or with noise uniform in +-0.05 m/s^2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fricenv.logs import PayloadLog, QuarterCarLog
from fricenv.plants import li_du_li as ldl
from fricenv.plants import quarter_car as qc
from fricenv.plants import sui_johansen as sj
from fricenv.plants.payload import Trajectory
from fricenv.plants.tire import DRY, SNOW, MagicFormula
from fricenv.utils import as_generator

__all__ = [
    "MHE_CASES",
    "PEAK_09",
    "SETTLE_WINDOWS",
    "PaperCase",
    "TwoAxleRun",
    "abs_like_torque",
    "ekf_rls_scenario",
    "mhe_case",
    "payload_log",
    "two_axle_scenario",
]

DT = sj.SAMPLE_TIME  # sample time [s]
PLANT_SUBSTEPS = 10  # plant substeps per sample (1 ms; the plant is verified at 5)
V0 = 20.0  # initial speed [m/s]
SLIP0 = 0.01  # initial slip [-]
MHE_DURATION = 1.5  # [s]; dry ends near 7 m/s, still well above the stiff low-speed region
APPLY_RATE = 4.0  # torque rise rate as a multiple of r Fz mu_max per second [1/s]
RELEASE_RATE = 8.0  # torque fall rate, same unit [1/s]
TORQUE0 = 0.4  # initial torque as a fraction of r Fz mu_max [-]
SLIP_BAND = {"dry": (0.03, 0.2), "snow": (0.03, 0.15)}  # hysteresis band of the ABS-like excitation [-]
DEFAULT_BAND = (0.03, 0.15)

# Li, Du & Li scenario on the quarter car.
PEAK_09 = MagicFormula(B=DRY.B, C=DRY.C, E=DRY.E, theta=ldl.ROAD_MU, name="dry-0.9")
EKF_RLS_V0 = 10.0  # [m/s]
TRACTION_TIME = 8.0  # [s]
TRACTION_TORQUE = -150.0  # drive torque [N m] (about 1.3 m/s^2)
BRAKE_TORQUE = 600.0  # final brake torque [N m] (about 5 m/s^2)
BRAKE_RAMP = 1.0  # [s] to reach BRAKE_TORQUE
EKF_RLS_DURATION = 11.5  # [s]; the quarter car is then near 5 m/s (the slip estimate degrades near standstill)
AX_NOISE = ldl.AX_NOISE  # half-width of the uniform a_x noise [m/s^2]
# "after settling" in the EKF/RLS scenarios: 2 s after the start of traction until its end, and 1 s after the start
# of braking until the end [s]
SETTLE_WINDOWS = ((2.0, TRACTION_TIME), (TRACTION_TIME + 1.0, np.inf))
# Two-axle set-up (Li, Du & Li, Table I): front-wheel drive, then braking on both axles.
TWO_AXLE_V0 = 10.0  # [m/s]
TWO_AXLE_DRIVE = 300.0  # front drive torque [N m] (about 0.65 m/s^2)
TWO_AXLE_BRAKE = (-900.0, -600.0)  # final front, rear brake torques [N m] (about 3.3 m/s^2)
TWO_AXLE_SUBSTEPS = 10  # RK4 substeps per sample (1 ms)

# case -> (road, estimated parameters), Section IV.A-B
MHE_CASES: dict[int, tuple[MagicFormula, tuple[str, ...]]] = {
    1: (DRY, ("theta",)),
    2: (SNOW, ("theta",)),
    3: (DRY, ("theta", "B", "C", "E")),
    4: (SNOW, ("theta", "B", "C", "E")),
}


@dataclass(frozen=True)
class PaperCase:
    """A generated log with its truth."""

    case: str  # name, e.g. "1" or "ekf-rls-clean"
    road: MagicFormula  # true road
    estimated: tuple[str, ...]  # parameters the estimator should augment
    log: QuarterCarLog  # t, T_b, omega (noisy), v (truth), a_x (if any)
    v: np.ndarray  # true speed [m/s]
    slip: np.ndarray  # true slip [-]
    omega: np.ndarray  # true wheel speed [rad/s]
    mu: np.ndarray  # true friction coefficient in use [-]
    Fx: np.ndarray  # true tire force [N]


def abs_like_torque(slip: float, torque: float, applying: bool, road: MagicFormula,
                    band: tuple[float, float], dt: float = DT,
                    p: qc.QuarterCarParams = qc.PAPER_PARAMS) -> tuple[float, bool]:
    """One step of the hysteresis ABS excitation (module docstring).

    :param slip: current true slip [-].
    :param torque: current brake torque [N m].
    :param applying: True while the torque is rising.
    :param road: true road (sets the torque scale r Fz mu_max).
    :param band: (low, high) slip band [-].
    :param dt: sample time [s].
    :param p: vehicle parameters.
    :return: (next torque, next applying flag).
    """
    scale = p.r * p.Fz * road.mu_max
    if applying and slip > band[1]:
        applying = False
    elif not applying and slip < band[0]:
        applying = True
    rate = APPLY_RATE if applying else -RELEASE_RATE
    return max(torque + rate * scale * dt, 0.0), applying


def _simulate(road, v0, omega0, torque_fn, n, substeps, p):
    """Run the plant for n samples; torque_fn(k, v, omega) -> T_b held over sample k."""
    R = road.as_array()
    v = np.empty(n)
    w = np.empty(n)
    tb = np.empty(n)
    vk, wk = np.array([v0]), np.array([omega0])
    for k in range(n):
        v[k], w[k] = vk[0], wk[0]
        tb[k] = torque_fn(k, v[k], w[k])
        vk, wk = qc.step(vk, wk, np.array([tb[k]]), R, DT, p, substeps)
    s = qc.slip(v, w, p)
    mu = road.mu(s)
    return v, w, tb, s, mu, p.Fz * mu


def mhe_case(case: int, seed=None, duration: float = MHE_DURATION, p: qc.QuarterCarParams = qc.PAPER_PARAMS,
             band: tuple[float, float] | None = None) -> PaperCase:
    """Generate the log of MHE paper case 1-4.

    :param case: 1, 2, 3 or 4.
    :param seed: int, Generator or None, for the measurement noise.
    :param duration: simulated time [s].
    :param p: vehicle parameters.
    :param band: slip band of the excitation (default per road, ``SLIP_BAND``).
    :return: the case's log and truth; ``log.T_b[k]`` is the torque held from ``t[k]`` to ``t[k+1]``.
    """
    if case not in MHE_CASES:
        raise ValueError(f"case must be one of {sorted(MHE_CASES)}, got {case!r}")
    road, estimated = MHE_CASES[case]
    band = band or SLIP_BAND.get(road.name, DEFAULT_BAND)
    rng = as_generator(seed)
    n = round(duration / DT) + 1
    state = {"T": TORQUE0 * p.r * p.Fz * road.mu_max, "applying": True}

    def torque(k, v, w):
        s = float(qc.slip(v, w, p))
        state["T"], state["applying"] = abs_like_torque(s, state["T"], state["applying"], road, band, DT, p)
        return state["T"]

    v, w, tb, s, mu, Fx = _simulate(road, V0, V0 * (1 - SLIP0) / p.r, torque, n, PLANT_SUBSTEPS, p)
    omega_meas = w + rng.normal(0.0, sj.OMEGA_NOISE_STD, n)
    t = np.arange(n) * DT
    log = QuarterCarLog(t=t, T_b=tb, omega=omega_meas, v=v, a_x=-Fx / p.m)
    return PaperCase(str(case), road, estimated, log, v, s, w, mu, Fx)


def ekf_rls_scenario(noisy: bool = False, seed=None, road: MagicFormula = PEAK_09,
                     p: qc.QuarterCarParams = qc.PAPER_PARAMS, duration: float = EKF_RLS_DURATION,
                     omega_noise_var: float = 0.0) -> PaperCase:
    """Traction then braking on the quarter car (Li, Du & Li, Section IV.B shape).

    :param noisy: add uniform noise in +-``AX_NOISE`` to a_x (the paper's Fig. 12).
    :param seed: int, Generator or None.
    :param road: true road (default peak friction 0.9).
    :param p: vehicle parameters.
    :param duration: simulated time [s].
    :param omega_noise_var: wheel-speed noise variance [(rad/s)^2] (the paper uses none).
    :return: the log (with a_x) and truth.
    """
    rng = as_generator(seed)
    n = round(duration / DT) + 1

    def torque(k, v, w):
        t = k * DT
        if t < TRACTION_TIME:
            return TRACTION_TORQUE
        return BRAKE_TORQUE * min((t - TRACTION_TIME) / BRAKE_RAMP, 1.0)

    v, w, tb, s, mu, Fx = _simulate(road, EKF_RLS_V0, EKF_RLS_V0 / p.r, torque, n, PLANT_SUBSTEPS, p)
    a_x = -Fx / p.m
    if noisy:
        a_x = a_x + rng.uniform(-AX_NOISE, AX_NOISE, n)
    omega_meas = w + (rng.normal(0.0, np.sqrt(omega_noise_var), n) if omega_noise_var > 0 else 0.0)
    t = np.arange(n) * DT
    log = QuarterCarLog(t=t, T_b=tb, omega=omega_meas, v=v, a_x=a_x)
    return PaperCase("ekf-rls-" + ("noisy" if noisy else "clean"), road, (), log, v, s, w, mu, Fx)


@dataclass(frozen=True)
class TwoAxleRun:
    """A two-axle run (Li, Du & Li's own set-up): measurements, inputs and truth, one array per signal."""

    t: np.ndarray  # [s]
    omega_f: np.ndarray  # front wheel speed [rad/s]
    omega_r: np.ndarray  # rear wheel speed [rad/s]
    a_x: np.ndarray  # measured longitudinal acceleration [m/s^2]
    T_f: np.ndarray  # front torque, drive positive [N m]
    T_r: np.ndarray  # rear torque [N m]
    v: np.ndarray  # true speed [m/s]
    slip_f: np.ndarray  # true front slip, eq. (3) [-]
    slip_r: np.ndarray  # true rear slip [-]
    F: np.ndarray  # true total longitudinal force [N]
    mu: float  # road friction [-]
    case: str = "two-axle"


def two_axle_scenario(noisy: bool = False, seed=None, duration: float = EKF_RLS_DURATION, params=None,
                      ) -> TwoAxleRun:
    """Traction (front drive) then braking on the two-axle Dugoff model (Li, Du & Li, Section IV.B shape).

    :param noisy: add uniform noise in +-``AX_NOISE`` to a_x.
    :param seed: int, Generator or None.
    :param duration: simulated time [s].
    :param params: :class:`fricenv.plants.two_axle.TwoAxleParams` (default Table I, mu = 0.9).
    """
    from fricenv.plants import two_axle as ta

    p = params or ta.TABLE_I
    rng = as_generator(seed)
    n = round(duration / DT) + 1
    t = np.arange(n) * DT
    ramp = np.clip((t - TRACTION_TIME) / BRAKE_RAMP, 0.0, 1.0)
    T_f = np.where(t < TRACTION_TIME, TWO_AXLE_DRIVE, TWO_AXLE_BRAKE[0] * ramp)
    T_r = np.where(t < TRACTION_TIME, 0.0, TWO_AXLE_BRAKE[1] * ramp)
    v = np.empty(n)
    wf = np.empty(n)
    wr = np.empty(n)
    x = (np.array([TWO_AXLE_V0]), np.array([TWO_AXLE_V0 / p.R_w]), np.array([TWO_AXLE_V0 / p.R_w]))
    for k in range(n):
        v[k], wf[k], wr[k] = x[0][0], x[1][0], x[2][0]
        x = ta.step(x[0], x[1], x[2], T_f[k], T_r[k], DT, p, TWO_AXLE_SUBSTEPS)
    Sf, Sr = ta.slip(v, wf, p), ta.slip(v, wr, p)
    Fzf, Fzr = ta.axle_loads(p)
    F = ta.dugoff_force(Sf, Fzf, v, p.mu, p) + ta.dugoff_force(Sr, Fzr, v, p.mu, p)
    a_x = F / p.m
    if noisy:
        a_x = a_x + rng.uniform(-AX_NOISE, AX_NOISE, n)
    return TwoAxleRun(t, wf, wr, a_x, T_f, T_r, v, Sf, Sr, F, p.mu,
                      "two-axle-" + ("noisy" if noisy else "clean"))


def payload_log(traj: Trajectory) -> PayloadLog:
    """The measurements of a simulated payload trajectory (:func:`fricenv.plants.payload.simulate`) as a
    :class:`fricenv.logs.PayloadLog`: the raw sensor readings and the vision pose."""
    return PayloadLog(t=traj.t, M=traj.w_hat[:, 0], f_x=traj.w_hat[:, 1], f_y=traj.w_hat[:, 2],
                      theta=traj.pose[:, 0], X=traj.pose[:, 1], Y=traj.pose[:, 2])
