"""The physics of the independent quarter-car simulator (:mod:`tests.independent_sim`): constants, the model
integrated by RK4, and the three drivers.

Written from the papers' equations and the contracts (docs/contracts.md) only, sharing no code with
:mod:`fricenv` (see :mod:`tests.independent_sim`, which re-exports every name here).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

# ----------------------------------------------------------------------------------------------------- constants
G = 9.81  # gravity [m/s^2]
H_STEP = 0.25e-3  # RK4 step [s]
DT = 0.01  # log sample time [s]
SUBSTEPS = round(DT / H_STEP)  # RK4 steps per sample
V_STOP = 3.0  # the log stops when the car is slower than this [m/s]
MAX_DURATION = 5.0  # longest log [s]
V0_RANGE = (18.0, 30.0)  # initial speed [m/s]
FREE_ROLL_RANGE = (0.2, 0.5)  # free-rolling start [s]
OMEGA_NOISE_VAR = 0.2  # wheel-speed noise variance [(rad/s)^2], Sui & Johansen Section IV
V_NOISE_RANGE = (0.03, 0.05)  # reference-speed noise std [m/s]
AX_NOISE_RANGE = (0.05, 0.15)  # accelerometer noise std [m/s^2]
# Column sets and their probabilities: all, no a_x, no v, required only.
COLUMN_SETS = (("v", "a_x"), ("v",), ("a_x",), ())
COLUMN_PROBS = (0.65, 0.1, 0.1, 0.15)
ROAD_JITTER_B = 0.15  # relative perturbation of B [-]
ROAD_JITTER_THETA = 0.10  # relative perturbation of theta [-]
SLIP_GRID = 20001  # grid points for the numerical peak of the Magic Formula
NEUTRAL_COMMENT = "quarter-car braking log"  # never names the effect
ZOH_EPS = 1e-9  # rounding guard when locating a time in the sample grid [samples]

LIBRARY_EFFECTS = ("brake_lag", "brake_delay", "brake_gain", "relaxation_length", "radius_error", "mu_change", "drag")
OUT_OF_LIBRARY_EFFECTS = ("load_oscillation", "brake_fade")
EFFECT_PARAMS = {
    "brake_lag": ("tau",),
    "brake_delay": ("delay",),
    "brake_gain": ("gain",),
    "relaxation_length": ("sigma",),
    "radius_error": ("r_eff",),
    "mu_change": ("t_change", "theta_after"),
    "drag": ("c0", "c2"),
    "load_oscillation": ("amplitude", "freq", "phase"),
    "brake_fade": ("fade_per_kelvin", "heat_capacity", "cooling"),
}
NONE, OUT = "none", "out_of_library"
CATEGORIES = LIBRARY_EFFECTS + (NONE, OUT)
DRIVERS = ("pedal", "bosch-abs", "sine")

# Brake fade thermal model: surface layer of disc and pad.
FADE_HEAT_CAPACITY = 600.0  # [J/K]
FADE_COOLING_TIME = 20.0  # cooling time constant [s]
FADE_FLOOR = 0.3  # the pad friction never falls below this share of its cold value [-]
FADE_DROP_RANGE = (0.10, 0.30)  # torque drop over a full dry stop [-]

# Pedal driver
PEDAL_RAMP = (0.1, 0.4)  # press time [s]
PEDAL_LEVEL = (0.3, 0.8)  # share of the peak tire torque r F_z mu_max [-]
PEDAL_DRIFT = (0.02, 0.08)  # relative amplitude of the slow drift [-]
PEDAL_DRIFT_FREQ = (0.2, 0.6)  # drift frequency [Hz]
PEDAL_REPRESS_DEPTH = (0.3, 0.8)  # partial release to this share of the level [-]
PEDAL_REPRESS_TIME = (0.15, 0.4)  # release + re-press duration [s]

# Bosch-style ABS (wheel circumferential acceleration thresholds act on r * filtered omega')
ABS_FILTER_TAU = 0.02  # wheel-speed low-pass [s]
ABS_DIFF_SAMPLES = 3  # backward difference over this many samples for the wheel acceleration
ABS_A_MINUS = 12.0  # -a threshold: wheel deceleration [m/s^2]
ABS_A_PLUS = 6.0  # +a threshold: wheel re-acceleration [m/s^2]
ABS_SLIP_RELEASE = 0.15  # release when the slip w.r.t. the reference exceeds this [-]
ABS_BUILD_TIME = (0.15, 0.3)  # first build-up to the peak tire torque takes this long [s]
ABS_RELEASE_RATE = 18.0  # exponential pressure release [1/s]
ABS_STEP_PERIOD = 0.04  # re-apply step period [s]
ABS_STEP_SHARE = (0.06, 0.12)  # re-apply step, share of the torque at the last -a signal [-]
ABS_HOLD2_MAX = 0.15  # longest hold after a release [s]
ABS_REF_DECEL0 = 4.0  # initial estimate of the car's deceleration [m/s^2]
ABS_REF_DECEL_RANGE = (0.5, 12.0)  # clip of the reference slope [m/s^2]
ABS_REF_TAU = 0.2  # low-pass of the wheel deceleration in stable phases, the car's deceleration estimate [s]
ABS_REF_MARGIN = (1.15, 0.3)  # reference slope = a * estimate + b [-, m/s^2]
ABS_STABLE_SLIP = 0.05  # the wheel counts as stable (its deceleration ~ the car's) below this slip [-]

# Sine driver
SINE_RAMP = (0.1, 0.3)  # ramp-in time [s]
SINE_MEAN = (0.35, 0.6)  # mean torque, share of the peak tire torque [-]
SINE_PEAK = (1.02, 1.2)  # mean + amplitude, share of the peak tire torque [-]
SINE_FREQ = (1.0, 6.0)  # modulation frequency [Hz]


# ----------------------------------------------------------------------------------------------------- model
@dataclass(frozen=True)
class Vehicle:
    """Quarter-car parameters (Sui & Johansen's plant)."""

    m: float = 325.0  # quarter-car mass [kg]
    J: float = 1.0  # wheel inertia [kg m^2]
    r: float = 0.345  # wheel radius [m]
    Fz: float = 3188.0  # vertical load [N]


VEHICLE = Vehicle()


@dataclass(frozen=True)
class Road:
    """Magic Formula road (eq. (2))."""

    B: float  # stiffness factor [-]
    C: float  # shape factor [-]
    E: float  # curvature factor [-]
    theta: float  # peak factor [-]
    name: str = "road"

    def mu(self, lam: float, theta: float | None = None) -> float:
        """Friction coefficient at slip ``lam`` (eq. (2)); ``theta`` overrides the peak factor."""
        bl = self.B * lam
        th = self.theta if theta is None else theta
        return th * math.sin(self.C * math.atan(bl - self.E * (bl - math.atan(bl))))

    @property
    def mu_max(self) -> float:
        """Largest friction coefficient over slip in [0, 1] (numerical)."""
        lam = np.linspace(0.0, 1.0, SLIP_GRID)
        bl = self.B * lam
        mu = self.theta * np.sin(self.C * np.arctan(bl - self.E * (bl - np.arctan(bl))))
        return float(mu.max())


ROADS = {  # the road presets: dry and snow from Sui & Johansen, wet and ice simplified Pacejka
    "dry": Road(10.38, 1.65, 0.65663, 1.0, "dry"),
    "wet": Road(12.0, 2.3, 1.0, 0.82, "wet"),
    "snow": Road(14.395, 0.9, -6.439, 0.3, "snow"),
    "ice": Road(4.0, 2.0, 1.0, 0.1, "ice"),
}


@dataclass(frozen=True)
class Effect:
    """One effect by its contract name (or an out-of-library name) with its parameters."""

    name: str
    params: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.name not in EFFECT_PARAMS:
            raise ValueError(f"unknown effect {self.name!r}; valid: {', '.join(EFFECT_PARAMS)}")
        want = set(EFFECT_PARAMS[self.name])
        if set(self.params) != want:
            raise ValueError(f"effect {self.name!r} takes parameters {sorted(want)}, got {sorted(self.params)}")


class _Model:
    """Right-hand side of the plant with effects; state x = (v, w, lam_t, T_lag, temp, s)."""

    def __init__(self, road: Road, effects: Sequence[Effect], veh: Vehicle, cmd: Callable[[float], float]):
        self.road, self.veh, self.cmd = road, veh, cmd
        e = {x.name: x.params for x in effects}
        if len(e) != len(effects):
            raise ValueError("each effect may be switched on once")
        self.tau = e.get("brake_lag", {}).get("tau")
        self.delay = e.get("brake_delay", {}).get("delay", 0.0)
        self.gain = e.get("brake_gain", {}).get("gain", 1.0)
        self.sigma = e.get("relaxation_length", {}).get("sigma")
        self.r = e.get("radius_error", {}).get("r_eff", veh.r)
        mc = e.get("mu_change")
        self.t_change, self.theta_after = (mc["t_change"], mc["theta_after"]) if mc else (math.inf, road.theta)
        dr = e.get("drag", {})
        self.c0, self.c2 = dr.get("c0", 0.0), dr.get("c2", 0.0)
        lo = e.get("load_oscillation")
        self.osc = (lo["amplitude"], 2 * math.pi * lo["freq"], lo["phase"]) if lo else None
        fd = e.get("brake_fade")
        self.fade = (fd["fade_per_kelvin"], fd["heat_capacity"], fd["cooling"]) if fd else None

    def torque_in(self, t: float, T_lag: float) -> float:
        """Torque after delay and lag, before gain and fade [N m]."""
        if self.tau is not None:
            return T_lag
        return self.cmd(t - self.delay)

    def applied(self, t: float, x) -> float:
        """Brake torque acting on the wheel [N m]."""
        T = self.gain * self.torque_in(t, x[3])
        if self.fade is not None:
            k = self.fade[0]
            T *= max(1.0 - k * x[4], FADE_FLOOR)
        return max(T, 0.0)

    def slip(self, v: float, w: float) -> float:
        """Braking slip eq. (3) with the wheel's effective radius."""
        return (v - max(w, 0.0) * self.r) / max(v, 1e-6)

    def force(self, t: float, x) -> float:
        """Tire force F_x [N]."""
        lam = x[2] if self.sigma is not None else self.slip(x[0], x[1])
        theta = self.theta_after if t >= self.t_change else self.road.theta
        Fz = self.veh.Fz
        if self.osc is not None:
            A, om, ph = self.osc
            Fz *= 1.0 + A * math.sin(om * t + ph)
        return Fz * self.road.mu(lam, theta)

    def drag(self, v: float) -> float:
        """Drag force [N], opposing motion while v > 0."""
        return self.c0 + self.c2 * v * v if v > 0 else 0.0

    def rhs(self, t: float, x) -> tuple:
        v, w = x[0], x[1]
        Fx = self.force(t, x)
        Tb = self.applied(t, x)
        dv = -(Fx + self.drag(v)) / self.veh.m
        net = self.r * Fx - Tb
        dw = 0.0 if (w <= 0.0 and net <= 0.0) else net / self.veh.J  # lock: held at 0 while Tb >= r Fx
        dl = (v / self.sigma) * (self.slip(v, w) - x[2]) if self.sigma is not None else 0.0
        dT = (self.cmd(t - self.delay) - x[3]) / self.tau if self.tau is not None else 0.0
        if self.fade is not None:
            _, cap, cool = self.fade
            dtemp = (Tb * max(w, 0.0) - cool * x[4]) / cap  # temperature above ambient [K]
        else:
            dtemp = 0.0
        return (dv, dw, dl, dT, dtemp, v)

    def accel(self, t: float, x) -> float:
        """Vehicle acceleration [m/s^2] (negative when braking)."""
        return -(self.force(t, x) + self.drag(x[0])) / self.veh.m


def _rk4_step(model: _Model, t: float, x: list, h: float) -> list:
    k1 = model.rhs(t, x)
    x2 = [a + 0.5 * h * b for a, b in zip(x, k1)]
    k2 = model.rhs(t + 0.5 * h, x2)
    x3 = [a + 0.5 * h * b for a, b in zip(x, k2)]
    k3 = model.rhs(t + 0.5 * h, x3)
    x4 = [a + h * b for a, b in zip(x, k3)]
    k4 = model.rhs(t + h, x4)
    out = [a + h / 6.0 * (b + 2 * c + 2 * d + e) for a, b, c, d, e in zip(x, k1, k2, k3, k4)]
    out[1] = max(out[1], 0.0)  # the wheel cannot turn backwards under a brake: clamp (lock)
    return out


def initial_state(model: _Model, v0: float) -> list:
    """Free rolling at v0: omega = v0 / r_eff, zero transient slip, filter, temperature and distance."""
    return [v0, v0 / model.r, 0.0, 0.0, 0.0, 0.0]


def integrate(model: _Model, x0: Sequence[float], t0: float, t1: float, h: float = H_STEP) -> list:
    """Fixed-step RK4 from t0 to t1 (the step is shrunk to fit the interval evenly).

    :param model: right-hand side.
    :param x0: state (v, w, lam_t, T_lag, temp, s).
    :param t0: start time [s]; :param t1: end time [s]; :param h: largest step [s].
    :return: the state at t1.
    """
    n = max(math.ceil((t1 - t0) / h - 1e-9), 1)
    hh = (t1 - t0) / n
    x = list(x0)
    for i in range(n):
        x = _rk4_step(model, t0 + i * hh, x, hh)
    return x


def make_model(road: Road, effects: Sequence[Effect] = (), cmd: Callable[[float], float] = lambda t: 0.0,
               veh: Vehicle = VEHICLE) -> _Model:
    """The plant with effects, driven by the command ``cmd(t)`` [N m]."""
    return _Model(road, effects, veh, cmd)


def stopping_distance(model: _Model, v0: float, v_stop: float = V_STOP, h: float = H_STEP,
                      t_max: float = 30.0) -> float:
    """Distance [m] until the speed falls to ``v_stop`` by RK4, the crossing interpolated linearly in the step."""
    x = initial_state(model, v0)
    t = 0.0
    while t < t_max:
        xn = _rk4_step(model, t, x, h)
        if xn[0] <= v_stop:
            a = (x[0] - v_stop) / (x[0] - xn[0])
            return x[5] + a * (xn[5] - x[5])
        x, t = xn, t + h
    raise ValueError(f"speed did not fall to {v_stop} m/s within {t_max} s")


# ----------------------------------------------------------------------------------------------------- drivers
def _pedal_torque(t_peak: float, n: int, free: int, rng: np.random.Generator) -> np.ndarray:
    """Human-like pedal press: smooth ramp, hold with slow drift, one or two partial releases and re-presses."""
    t = np.arange(n) * DT
    ts = free * DT
    ramp = rng.uniform(*PEDAL_RAMP)
    level = rng.uniform(*PEDAL_LEVEL) * t_peak
    drift_a, drift_f = rng.uniform(*PEDAL_DRIFT), rng.uniform(*PEDAL_DRIFT_FREQ)
    drift_ph = rng.uniform(0, 2 * np.pi)
    u = np.clip((t - ts) / ramp, 0.0, 1.0)
    shape = 0.5 - 0.5 * np.cos(np.pi * u)  # smooth press
    level_t = np.full(n, level)
    mult = np.ones(n)
    t_free = ts + ramp
    n_re = int(rng.integers(1, 3))
    t_end = n * DT
    starts = np.sort(rng.uniform(t_free + 0.3, max(t_free + 0.4, t_end - 0.6), n_re))
    for s in starts:
        dur = rng.uniform(*PEDAL_REPRESS_TIME)
        depth = rng.uniform(*PEDAL_REPRESS_DEPTH)
        new_level = rng.uniform(*PEDAL_LEVEL) * t_peak
        x = np.clip((t - s) / dur, 0.0, 1.0)
        dip = 1.0 - (1.0 - depth) * np.sin(np.pi * x)  # smooth dip and return
        mult *= np.where((t >= s) & (t <= s + dur), dip, 1.0)
        half = s + 0.5 * dur
        level_t = np.where(t >= half, new_level, level_t)  # the re-press goes to a new level
    drift = 1.0 + drift_a * np.sin(2 * np.pi * drift_f * (t - ts) + drift_ph)
    T = shape * level_t * mult * drift
    T[:free] = 0.0
    return np.maximum(T, 0.0)


def _sine_torque(t_peak: float, n: int, free: int, rng: np.random.Generator) -> np.ndarray:
    """A mean torque with a sinusoidal modulation whose crest briefly exceeds the road's peak torque."""
    t = np.arange(n) * DT
    ts = free * DT
    ramp = rng.uniform(*SINE_RAMP)
    mean = rng.uniform(*SINE_MEAN) * t_peak
    amp = rng.uniform(*SINE_PEAK) * t_peak - mean
    f = rng.uniform(*SINE_FREQ)
    u = np.clip((t - ts) / ramp, 0.0, 1.0)
    T = u * (mean + amp * np.sin(2 * np.pi * f * np.maximum(t - ts, 0.0)))
    T[:free] = 0.0
    return np.maximum(T, 0.0)


class BoschABS:
    """Classic ABS on the noisy measured wheel speed, with wheel-acceleration thresholds -a / +a and a slip threshold.

    Phases: 1 build-up; 2 hold (after the -a signal); 3 release (slip above threshold); 4 hold (wheel re-accelerates);
    5 slow re-apply in steps, back to 2 at the next -a signal. The reference speed is extrapolated from the filtered
    wheel speed with a slope from the wheel's deceleration while it runs stably (low slip, phases 1 and 5).
    """

    def __init__(self, t_peak: float, free: int, veh: Vehicle, rng: np.random.Generator):
        self.r = veh.r
        self.free = free
        self.build_rate = t_peak / rng.uniform(*ABS_BUILD_TIME)
        self.step_share = rng.uniform(*ABS_STEP_SHARE)
        self.alpha = DT / (ABS_FILTER_TAU + DT)
        self.wf: float | None = None
        self.hist: list[float] = []
        self.v_ref = 0.0
        self.decel = ABS_REF_DECEL0
        self.phase = 1
        self.T = 0.0
        self.T_lock = t_peak
        self.timer = 0.0

    def __call__(self, k: int, omega_meas: float) -> float:
        self.wf = omega_meas if self.wf is None else self.wf + self.alpha * (omega_meas - self.wf)
        vw = self.wf * self.r
        self.hist.append(vw)
        if len(self.hist) > ABS_DIFF_SAMPLES:
            acc = (self.hist[-1] - self.hist[-1 - ABS_DIFF_SAMPLES]) / (ABS_DIFF_SAMPLES * DT)
        else:
            acc = 0.0
        slip = 1.0 - vw / max(self.v_ref, 0.1)
        if self.phase in (1, 5) and slip < ABS_STABLE_SLIP:  # stable wheel: its deceleration is the car's
            self.decel += DT / ABS_REF_TAU * (-acc - self.decel)
        a, b = ABS_REF_MARGIN
        slope = float(np.clip(a * self.decel + b, *ABS_REF_DECEL_RANGE))
        self.v_ref = max(vw, self.v_ref - slope * DT) if k else vw
        if k < self.free:
            return 0.0
        self.timer += DT
        ph = self.phase
        if ph == 1:
            self.T += self.build_rate * DT
            if acc < -ABS_A_MINUS:
                self.phase, self.T_lock, self.timer = 2, self.T, 0.0
        elif ph == 2:
            if slip > ABS_SLIP_RELEASE:
                self.phase, self.timer = 3, 0.0
            elif acc > -0.5 * ABS_A_MINUS and self.timer > 2 * ABS_STEP_PERIOD:
                self.phase, self.timer = 5, 0.0
        elif ph == 3:
            self.T *= 1.0 - ABS_RELEASE_RATE * DT
            if acc > 0.0:
                self.phase, self.timer = 4, 0.0
        elif ph == 4:
            if (acc < ABS_A_PLUS and slip < 0.5 * ABS_SLIP_RELEASE) or self.timer > ABS_HOLD2_MAX:
                self.phase, self.timer = 5, 0.0
        else:  # 5: stepwise re-apply
            if self.timer >= ABS_STEP_PERIOD:
                self.T += self.step_share * self.T_lock
                self.timer = 0.0
            if acc < -ABS_A_MINUS:
                self.phase, self.T_lock, self.timer = 2, self.T, 0.0
            elif slip > ABS_SLIP_RELEASE:
                self.phase, self.T_lock, self.timer = 3, self.T, 0.0
        return max(self.T, 0.0)
