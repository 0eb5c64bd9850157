"""The built-in quarter-car effects (docs/contracts.md): each one's spec and registry entry.

| name                | parameters                  | where it acts                                             |
| ------------------- | --------------------------- | --------------------------------------------------------- |
| ``brake_lag``        | ``tau`` [s]                 | applied torque: tau T_a' = T_cmd - T_a                     |
| ``brake_delay``      | ``delay`` [s]               | applied torque: T_a(t) = T_cmd(t - delay)                  |
| ``brake_gain``       | ``gain`` [-]                | applied torque: T_a = gain T_cmd                           |
| ``relaxation_length``| ``sigma`` [m]               | tire force from a transient slip, (sigma/v) l_t' = l - l_t |
| ``radius_error``     | ``r_eff`` [m]               | rolling radius of slip and torque arm                      |
| ``mu_change``        | ``t_change`` [s], ``theta_after`` [-] | road peak factor theta switches at t_change     |
| ``drag``             | ``c0`` [N], ``c2`` [N s^2/m^2] | extra force on the vehicle, c0 + c2 v^2                 |

Three physically real effects that are NOT in the library are registered for the gap tool's validation on withheld
effects (``in_library=False``): temperature brake fade, pitch-dynamics wheel-load transfer and friction that falls
with the sliding speed (Burckhardt's velocity factor). Their physics is built into
:class:`fricenv.effects.quarter_car.EffectSimulator`, like the library effects'.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from fricenv.effects.registry import (
    Excitation,
    FitContext,
    Param,
    QuarterCarEffect,
    always_testable,
    register,
)

__all__ = ["BrakeDelay", "BrakeFade", "BrakeGain", "BrakeLag", "Drag", "LoadTransfer", "MuChange", "RadiusError",
           "RelaxationLength", "SlidingSpeedFriction", "drag_force"]

# A road speed for the drag force used as drag's single error figure in the validation [m/s].
DRAG_REFERENCE_SPEED = 15.0


def _check_positive(obj, name: str, allow_zero: bool = False) -> None:
    value = getattr(obj, name)
    ok = np.isfinite(value) and (value >= 0 if allow_zero else value > 0)
    if not ok:
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{obj.name}.{name} must be finite and {bound}, got {value!r}")


@dataclass(frozen=True)
class BrakeLag:
    """Applied torque is a first-order lag of the logged torque: ``tau T_a' = T_cmd - T_a``."""

    tau: float  # lag time constant [s]
    name: ClassVar[str] = "brake_lag"

    def __post_init__(self):
        _check_positive(self, "tau")


@dataclass(frozen=True)
class BrakeDelay:
    """Applied torque is the logged torque delayed: ``T_a(t) = T_cmd(t - delay)``."""

    delay: float  # transport delay [s]
    name: ClassVar[str] = "brake_delay"

    def __post_init__(self):
        _check_positive(self, "delay", allow_zero=True)


@dataclass(frozen=True)
class BrakeGain:
    """Applied torque is a multiple of the logged torque: ``T_a = gain T_cmd``."""

    gain: float  # torque gain [-]
    name: ClassVar[str] = "brake_gain"

    def __post_init__(self):
        _check_positive(self, "gain")


@dataclass(frozen=True)
class RelaxationLength:
    """Tire force follows a transient slip: ``(sigma / v) lambda_t' = lambda - lambda_t``, ``F_x = F_z mu(lambda_t)``."""

    sigma: float  # relaxation length [m]
    name: ClassVar[str] = "relaxation_length"

    def __post_init__(self):
        _check_positive(self, "sigma")


@dataclass(frozen=True)
class RadiusError:
    """The effective rolling radius (slip and torque arm) is ``r_eff`` instead of the nominal one."""

    r_eff: float  # effective rolling radius [m]
    name: ClassVar[str] = "radius_error"

    def __post_init__(self):
        _check_positive(self, "r_eff")


@dataclass(frozen=True)
class MuChange:
    """The road's peak factor theta switches to ``theta_after`` at ``t_change`` (log time)."""

    t_change: float  # switching time [s]
    theta_after: float  # road condition coefficient after the change [-]
    name: ClassVar[str] = "mu_change"

    def __post_init__(self):
        if not np.isfinite(self.t_change):
            raise ValueError(f"mu_change.t_change must be finite, got {self.t_change!r}")
        _check_positive(self, "theta_after")


@dataclass(frozen=True)
class Drag:
    """Extra force on the vehicle, rolling resistance plus air drag: ``F_d = c0 + c2 v^2`` (while moving)."""

    c0: float  # constant resistance [N]
    c2: float  # quadratic (air drag) coefficient [N s^2/m^2]
    name: ClassVar[str] = "drag"

    def __post_init__(self):
        _check_positive(self, "c0", allow_zero=True)
        _check_positive(self, "c2", allow_zero=True)


def drag_force(v, c0, c2):
    """The drag effect's force on the vehicle [N]: ``F_d = c0 + c2 v^2`` while moving, 0 at standstill.

    :param v: vehicle speed [m/s] (array).
    :param c0: constant resistance [N]; :param c2: quadratic (air drag) coefficient [N s^2/m^2].
    """
    return np.where(v > 0.0, c0 + c2 * v * v, 0.0)


@dataclass(frozen=True)
class BrakeFade:
    """NOT a library effect (validation only): brake fade with pad temperature.

    The applied torque is divided by ``1 + k E_b``, with ``E_b`` the brake energy dissipated so far (a proxy of the
    disc temperature rise).
    """

    k: float  # fade coefficient [1/J]
    name: ClassVar[str] = "brake_fade"

    def __post_init__(self):
        _check_positive(self, "k", allow_zero=True)


@dataclass(frozen=True)
class LoadTransfer:
    """NOT a library effect (validation only): wheel-load transfer through the body's pitch dynamics.

    ``F_z = F_z0 (1 + k x)`` with the pitch response ``x'' = w_n^2 (d/g - x) - 2 zeta w_n x'`` to the deceleration
    ``d``; ``k`` is the static load-transfer ratio per g (front axle).
    """

    k: float  # static load transfer per g of deceleration [-]
    name: ClassVar[str] = "load_transfer"

    def __post_init__(self):
        if not np.isfinite(self.k):
            raise ValueError(f"load_transfer.k must be finite, got {self.k!r}")


@dataclass(frozen=True)
class SlidingSpeedFriction:
    """NOT a library effect (validation only): friction that falls with the sliding speed.

    Burckhardt's tire model (Kiencke & Nielsen, Automotive Control Systems, Section 7.1) multiplies the friction
    curve by ``exp(-c4 lambda v)``, ``lambda v = v - omega r`` being the sliding speed; ``c4`` is about 0.02-0.04 s/m
    on asphalt. A locked wheel at 30 m/s then has about half the friction it has at walking pace.
    """

    c4: float  # friction decay per unit sliding speed [s/m]
    name: ClassVar[str] = "sliding_speed_friction"

    def __post_init__(self):
        _check_positive(self, "c4", allow_zero=True)


# --------------------------------------------------------------------------------------------- registry entries
def _make(spec: type, **params: float):
    return spec(**{k: float(v) for k, v in params.items()})


def _draw_brake_gain(road, rng: np.random.Generator, p):
    u = rng.uniform
    return _make(BrakeGain, gain=u(0.75, 0.88) if rng.random() < 0.5 else u(1.12, 1.3))


def _draw_radius_error(road, rng: np.random.Generator, p):
    return _make(RadiusError, r_eff=p.r * (1 + rng.choice([-1, 1]) * rng.uniform(0.02, 0.05)))


def _draw_mu_change(road, rng: np.random.Generator, p):
    rise = road.theta < 0.85 and rng.random() < 0.5
    factor = rng.uniform(1.2, 1.4) if rise else rng.uniform(0.55, 0.8)
    return _make(MuChange, t_change=rng.uniform(1.0, 2.2), theta_after=road.theta * factor)


def _mu_change_error(truth: dict, fitted: dict, errors: dict) -> float:
    """The theta after the change; the switching time's absolute error [s] is reported beside it."""
    errors["t_change_abs_s"] = abs(fitted.get("t_change", np.nan) - truth["t_change"])
    return errors.get("theta_after", np.nan)


def _drag_error(truth: dict, fitted: dict, errors: dict) -> float:
    """The drag force at :data:`DRAG_REFERENCE_SPEED` (c0 and c2 trade off against each other)."""
    ref = DRAG_REFERENCE_SPEED**2
    f_true = truth["c0"] + truth["c2"] * ref
    f_fit = fitted.get("c0", np.nan) + fitted.get("c2", np.nan) * ref
    key = f"force_at_{DRAG_REFERENCE_SPEED:g}_m_s"
    errors[key] = abs(f_fit - f_true) / f_true
    return errors[key]


def _uniform(spec: type, name: str, low: float, high: float):
    """A validation draw of a one-parameter effect, uniform over ``[low, high]``."""
    def draw(road, rng: np.random.Generator, p):
        return _make(spec, **{name: rng.uniform(low, high)})
    return draw


def _starts(name: str, *values: float):
    return lambda ctx: [{name: v} for v in values]


def _radius_starts(ctx: FitContext) -> list[dict]:
    """Multiples of the nominal radius, and the free-rolling ratio v / omega when v is logged."""
    opts = [{"r_eff": f * ctx.p.r} for f in (0.96, 0.98, 1.02, 1.04)]
    if ctx.free_roll_ratio is not None:
        opts.append({"r_eff": float(ctx.free_roll_ratio)})
    return opts


_ACTUATOR = "brake torque that changes (apply and release) while the wheel responds"
MIN_TRANSIENTS = 2  # brake apply/release events an actuator effect needs [-]
MIN_SLIP_TRANSIENTS = 3  # windows with a fast slip change a relaxation length needs [-]
MIN_BRAKING_SIDE = 2  # braking windows on either side of a friction change [-]
MIN_NEAR_PEAK = 2  # windows near the friction peak on either side for a change of the peak alone to show [-]
MIN_CHANGE_TRAINING = 4  # training windows per fold a change-point search needs (one on either side and more) [-]
MIN_SPEED_RANGE = 8.0  # braking speed range drag needs [m/s]


def _testable_actuator(x: Excitation) -> str | None:
    if x.torque_transients < MIN_TRANSIENTS:
        return f"{x.torque_transients} brake apply/release event(s); needs {MIN_TRANSIENTS}"
    return always_testable(x)


def _testable_relaxation(x: Excitation) -> str | None:
    if x.slip_transient_windows < MIN_SLIP_TRANSIENTS:
        return f"{x.slip_transient_windows} window(s) with a slip transient; needs {MIN_SLIP_TRANSIENTS}"
    return None


def _testable_radius(x: Excitation) -> str | None:
    if not (x.has_v or x.has_a_x):
        return ("neither v nor a_x logged: from t, T_b and omega a rolling radius r_e gives the data of a brake gain "
                "(r/r_e)^2, up to the wheel-inertia term (fricenv.gap.quarter_car.alternatives)")
    return always_testable(x)


def _testable_mu_change(x: Excitation) -> str | None:
    """A change of theta scales the whole friction curve (the slip stiffness ``B C D`` with the peak ``D``), so braking
    on either side shows it in the slip the torque needs; the power analysis then decides whether its plausible size
    stands above the noise. Requiring slip near the peak as well left every log that brakes below it untested, where
    the true change passed the test (gap validate tuning seeds 9006/9007, 2 of 14 friction-change logs)."""
    if x.training_windows < MIN_CHANGE_TRAINING:
        return f"{x.training_windows} training windows per fold; a change-point search needs {MIN_CHANGE_TRAINING}"
    if x.braking_windows < 2 * MIN_BRAKING_SIDE:
        return f"{x.braking_windows} braking window(s); needs {MIN_BRAKING_SIDE} on either side of a change"
    return None


def _caveat_mu_change(x: Excitation) -> str | None:
    if min(x.near_peak_early, x.near_peak_late) >= MIN_NEAR_PEAK:
        return None
    return (f"tested below the friction peak only (slip near the peak in {x.near_peak_early} early and "
            f"{x.near_peak_late} late window(s)): the change shows through the slip stiffness, which the model "
            f"scales with the peak; a road whose peak changes and whose stiffness does not would not show here")


def _testable_drag(x: Excitation) -> str | None:
    """The constant part ``c0`` shows in the deceleration level when ``v`` or ``a_x`` is logged; from the wheel speed
    alone the force must change with speed to stand apart from the road's friction level."""
    if not (x.has_v or x.has_a_x) and x.speed_range < MIN_SPEED_RANGE:
        return (f"neither v nor a_x logged and a braking speed range of {x.speed_range:.1f} m/s; drag needs one of "
                f"them or {MIN_SPEED_RANGE:g} m/s")
    return always_testable(x)

for _entry in (
    QuarterCarEffect(BrakeLag, (Param("tau", "s", (1e-3, 0.4), 0.0, 1e-3, 0.01),), _ACTUATOR,
                     _starts("tau", 0.01, 0.03, 0.07, 0.15), draw=_uniform(BrakeLag, "tau", 0.02, 0.08),
                     testable=_testable_actuator),
    QuarterCarEffect(BrakeDelay, (Param("delay", "s", (0.0, 0.25), 0.0, 1e-3, 0.01),), _ACTUATOR,
                     _starts("delay", 0.01, 0.025, 0.045, 0.08), draw=_uniform(BrakeDelay, "delay", 0.015, 0.06),
                     testable=_testable_actuator),
    QuarterCarEffect(BrakeGain, (Param("gain", "-", (0.3, 3.0), 1.0, 2e-3, 0.05),),
                     "braking below the friction peak (the torque sets the deceleration there)",
                     _starts("gain", 0.8, 0.9, 1.1, 1.25), draw=_draw_brake_gain),
    # A car tire's longitudinal relaxation length is a few tens of centimetres: a fit beyond 1 m imitates a lag or a
    # filter (docs/design-notes.md); the fit's own range is wider, so that a joint fit can pass through.
    QuarterCarEffect(RelaxationLength, (Param("sigma", "m", (0.01, 3.0), 0.0, 5e-3, 0.1, physical=(0.01, 1.0)),),
                     "fast slip transients (brake steps, ABS cycles)", _starts("sigma", 0.1, 0.3, 0.6, 1.2),
                     window_states=1, draw=_uniform(RelaxationLength, "sigma", 0.2, 0.6), testable=_testable_relaxation),
    QuarterCarEffect(RadiusError, (Param("r_eff", "m", (0.25, 0.45), lambda road, p: p.r, 2e-4, 0.005),),
                     "v logged, or a free-rolling start and braking to read the speed from", _radius_starts,
                     draw=_draw_radius_error, testable=_testable_radius),
    QuarterCarEffect(MuChange, (Param("t_change", "s", (-np.inf, np.inf), np.inf, 0.01, 0.1, log_time=True),
                                Param("theta_after", "-", (0.03, 1.6), lambda road, p: np.array(road)[..., 3].copy(),
                                      0.002, 0.05)),
                     "braking before and after the change, best near the friction peak", fit="change_point",
                     searched=("t_change",), draw=_draw_mu_change, main_error=_mu_change_error,
                     testable=_testable_mu_change, caveat=_caveat_mu_change),
    QuarterCarEffect(Drag, (Param("c0", "N", (0.0, 3000.0), 0.0, 2.0, 50.0),
                            Param("c2", "N s^2/m^2", (0.0, 10.0), 0.0, 0.01, 0.1)),
                     "a wide speed range, best with v or a_x logged",
                     lambda ctx: [{"c0": a, "c2": b} for a, b in ((50.0, 0.0), (200.0, 0.0), (0.0, 0.3),
                                                                  (100.0, 0.2), (400.0, 0.5))],
                     draw=lambda road, rng, p: _make(Drag, c0=rng.uniform(100.0, 300.0), c2=rng.uniform(0.2, 0.6)),
                     main_error=_drag_error, testable=_testable_drag),
    QuarterCarEffect(BrakeFade, (Param("k", "1/J", (0.0, np.inf), field="fade"),), "long or hard braking",
                     draw=_uniform(BrakeFade, "k", 3e-6, 6e-6), in_library=False),
    QuarterCarEffect(LoadTransfer, (Param("k", "-", (-np.inf, np.inf), field="load"),), "deceleration changes",
                     in_library=False),
    QuarterCarEffect(SlidingSpeedFriction, (Param("c4", "s/m", (0.0, np.inf), field="slide"),),
                     "wheel lock-ups at different speeds", draw=_uniform(SlidingSpeedFriction, "c4", 0.02, 0.04),
                     in_library=False),
):
    register(_entry)
del _entry
