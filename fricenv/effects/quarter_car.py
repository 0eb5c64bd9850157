"""Unmodelled effects of the quarter-car braking plant (DESIGN.md, "Effect names (quarter car)").

Each effect is a typed, frozen spec whose name and parameter names are the DESIGN.md contract:

| name                | parameters                  | where it acts                                             |
| ------------------- | --------------------------- | --------------------------------------------------------- |
| ``brake_lag``        | ``tau`` [s]                 | applied torque: tau T_a' = T_cmd - T_a                     |
| ``brake_delay``      | ``delay`` [s]               | applied torque: T_a(t) = T_cmd(t - delay)                  |
| ``brake_gain``       | ``gain`` [-]                | applied torque: T_a = gain T_cmd                           |
| ``relaxation_length``| ``sigma`` [m]               | tire force from a transient slip, (sigma/v) l_t' = l - l_t |
| ``radius_error``     | ``r_eff`` [m]               | rolling radius of slip and torque arm                      |
| ``mu_change``        | ``t_change`` [s], ``theta_after`` [-] | road peak factor theta switches at t_change     |
| ``drag``             | ``c0`` [N], ``c2`` [N s^2/m^2] | extra force on the vehicle, c0 + c2 v^2                 |

:class:`EffectSimulator` is the one simulator with effects, batched over a leading dimension whose elements may each
carry their own effect parameters (a :class:`ModelBatch`). It layers the effects around the plant of
:mod:`fricenv.plants.quarter_car`:

- actuator effects (delay -> lag -> gain) form the torque seen by the wheel; the delay averages the zero-order-held
  command exactly over each physics substep and the lag uses its exact ZOH solution, so both are continuous in their
  parameters (which the gap tool's fits need);
- the wheel/vehicle dynamics are :func:`fricenv.plants.quarter_car.step` (ROS2), one call per substep, with the road's
  theta switched (and blended within the switching substep) for ``mu_change``, the wheel radius replaced for
  ``radius_error`` (elements grouped by radius, since the plant takes one parameter set per call), and the drag force
  added by Strang splitting (it varies on the vehicle's slow time scale);
- ``relaxation_length`` changes the tire force law (the force depends on a third state, the transient slip), which
  cannot be expressed through ``quarter_car.step``: those elements are integrated by :func:`relaxation_step`, the
  same L-stable ROS2 scheme on the extended 3-state right-hand side :func:`relaxation_derivatives`, with the Magic
  Formula of :mod:`fricenv.plants.tire`. It is checked against ``scipy.integrate.solve_ivp`` (Radau) in the tests.

Three physically real effects that are NOT in the library are provided for the gap tool's validation on withheld
effects (:data:`OUT_OF_LIBRARY`): temperature brake fade, pitch-dynamics wheel-load transfer and friction that falls
with the sliding speed (Burckhardt's velocity factor).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields, replace
from typing import ClassVar

import numpy as np

from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import (
    MagicFormula,
    longitudinal_slip,
    magic_formula,
    magic_formula_dslip,
    slip_and_partials,
)

__all__ = [
    "DEFAULT_SUBSTEPS",
    "EFFECTS",
    "EFFECT_PARAMS",
    "OUT_OF_LIBRARY",
    "BrakeDelay",
    "BrakeFade",
    "BrakeGain",
    "BrakeLag",
    "Drag",
    "EffectSimulator",
    "LoadTransfer",
    "ModelBatch",
    "MuChange",
    "RadiusError",
    "RelaxationLength",
    "SlidingSpeedFriction",
    "make_effect",
    "relaxation_derivatives",
    "relaxation_step",
    "simulate_with_effects",
]

# ROS2 constant (Verwer et al. 1999), the same L-stable choice as the plant's integrator.
_ROS2_GAMMA = 1.0 + 1.0 / np.sqrt(2.0)
# Physics substeps per 10 ms sample: the plant's verified setting (< 0.01 % vs Radau).
DEFAULT_SUBSTEPS = 5
# Rosenbrock gamma of the relaxation plant's steps: 1/2 (linearly implicit trapezoidal rule, A-stable, second
# order) leaves the oscillatory mode of the transient slip and the wheel (about 25 Hz on dry asphalt at
# sigma = 0.3 m) undamped, as it is; the plant's L-stable 1 + 1/sqrt(2) damps that mode numerically at 2 ms steps,
# which a fit then reads as a relaxation length about 10 % too long.
RELAX_GAMMA = 0.5
# Index rounding guard when locating a delayed sample [samples].
_INDEX_EPS = 1e-9
# Load-transfer pitch mode: natural frequency [rad/s] and damping ratio [-] of a passenger car's pitch.
_PITCH_OMEGA = 2.0 * np.pi * 1.5
_PITCH_ZETA = 0.4


# --------------------------------------------------------------------------------------------- effect specs
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


EFFECTS: dict[str, type] = {cls.name: cls for cls in (BrakeLag, BrakeDelay, BrakeGain, RelaxationLength,
                                                       RadiusError, MuChange, Drag)}
EFFECT_PARAMS: dict[str, tuple[str, ...]] = {
    name: tuple(f.name for f in fields(cls)) for name, cls in EFFECTS.items()
}
OUT_OF_LIBRARY: dict[str, type] = {cls.name: cls for cls in (BrakeFade, LoadTransfer,
                                                              SlidingSpeedFriction)}


def make_effect(name: str, allow_out_of_library: bool = False, **params: float):
    """An effect spec from its DESIGN.md name and parameters.

    :param name: effect name, one of :data:`EFFECTS` (or :data:`OUT_OF_LIBRARY` if allowed).
    :param allow_out_of_library: accept the validation-only effects too.
    :param params: the effect's parameters, by their DESIGN.md names.
    :raises ValueError: unknown name (lists the valid ones), unknown or missing parameter (lists the valid ones).
    """
    table = dict(EFFECTS)
    if allow_out_of_library:
        table.update(OUT_OF_LIBRARY)
    if name not in table:
        raise ValueError(f"unknown effect {name!r}; valid effects: {', '.join(table)}")
    cls = table[name]
    valid = [f.name for f in fields(cls)]
    unknown = sorted(set(params) - set(valid))
    missing = [v for v in valid if v not in params]
    if unknown or missing:
        what = f"unknown parameter(s) {', '.join(unknown)}" if unknown else f"missing parameter(s) {', '.join(missing)}"
        raise ValueError(f"effect {name!r}: {what}; its parameters are: {', '.join(valid)}")
    return cls(**{k: float(v) for k, v in params.items()})


def effect_params(effect) -> dict[str, float]:
    """The parameters of an effect spec as a plain dict (DESIGN.md names, SI units)."""
    return {f.name: float(getattr(effect, f.name)) for f in fields(effect)}


# --------------------------------------------------------------------------------------------- batched models
@dataclass(frozen=True)
class ModelBatch:
    """Per-element model parameters of a batch: the road and every effect's parameters, switched off by default.

    All arrays have shape ``(n,)`` except ``road`` ``(n, 4)``. "Off" values: ``tau = 0``, ``delay = 0``,
    ``gain = 1``, ``sigma = 0``, ``r_eff = p.r``, ``t_change = inf``, ``c0 = c2 = 0``, ``fade = 0``, ``load = 0``,
    ``slide = 0``.
    """

    road: np.ndarray  # (B, C, E, theta) per element
    tau: np.ndarray  # brake lag [s]
    delay: np.ndarray  # brake delay [s]
    gain: np.ndarray  # brake gain [-]
    sigma: np.ndarray  # relaxation length [m]
    r_eff: np.ndarray  # rolling radius [m]
    t_change: np.ndarray  # friction change time [s]
    theta_after: np.ndarray  # theta after the change [-]
    c0: np.ndarray  # drag constant [N]
    c2: np.ndarray  # drag quadratic coefficient [N s^2/m^2]
    fade: np.ndarray = None  # brake fade coefficient [1/J] (out of library)
    load: np.ndarray = None  # load transfer per g [-] (out of library)
    slide: np.ndarray = None  # friction decay per unit sliding speed [s/m] (out of library)

    def __post_init__(self):
        n = len(self.tau)
        for f in fields(self):
            if getattr(self, f.name) is None:
                object.__setattr__(self, f.name, np.zeros(n))

    def __len__(self) -> int:
        return len(self.tau)

    @classmethod
    def nominal(cls, road, n: int, p: qc.QuarterCarParams = qc.PAPER_PARAMS) -> ModelBatch:
        """``n`` elements with no effect on ``road`` ((4,), (n, 4) or a :class:`MagicFormula`)."""
        road = np.array(qc.road_array(road, n), dtype=float)
        return cls(road=road, tau=np.zeros(n), delay=np.zeros(n), gain=np.ones(n), sigma=np.zeros(n),
                   r_eff=np.full(n, p.r), t_change=np.full(n, np.inf), theta_after=road[:, 3].copy(),
                   c0=np.zeros(n), c2=np.zeros(n))

    @classmethod
    def from_effects(cls, road, effects: Sequence, p: qc.QuarterCarParams = qc.PAPER_PARAMS) -> ModelBatch:
        """One element on ``road`` with the effect specs ``effects`` switched on (each name at most once)."""
        batch = cls.nominal(road, 1, p)
        names = [e.name for e in effects]
        if len(set(names)) != len(names):
            raise ValueError(f"each effect may appear once, got {names}")
        updates: dict[str, np.ndarray] = {}
        mapping = {"brake_lag": {"tau": "tau"}, "brake_delay": {"delay": "delay"}, "brake_gain": {"gain": "gain"},
                   "relaxation_length": {"sigma": "sigma"}, "radius_error": {"r_eff": "r_eff"},
                   "mu_change": {"t_change": "t_change", "theta_after": "theta_after"},
                   "drag": {"c0": "c0", "c2": "c2"}, "brake_fade": {"k": "fade"}, "load_transfer": {"k": "load"},
                   "sliding_speed_friction": {"c4": "slide"}}
        for effect in effects:
            if effect.name not in mapping:
                raise ValueError(f"unknown effect {effect.name!r}; valid effects: {', '.join(mapping)}")
            for pname, field_name in mapping[effect.name].items():
                updates[field_name] = np.array([float(getattr(effect, pname))])
        return replace(batch, **updates)

    @classmethod
    def stack(cls, batches: Sequence[ModelBatch]) -> ModelBatch:
        """Concatenate batches along the leading dimension."""
        return cls(**{f.name: np.concatenate([getattr(b, f.name) for b in batches]) for f in fields(cls)})

    def repeat(self, k: int) -> ModelBatch:
        """Each element repeated ``k`` times consecutively (element i -> rows i*k .. i*k+k-1)."""
        return ModelBatch(**{f.name: np.repeat(getattr(self, f.name), k, axis=0) for f in fields(self)})


# --------------------------------------------------------------------------------------------- relaxation plant
def relaxation_derivatives(v, omega, lam_t, Tb, road, r, sigma, c0, c2, p: qc.QuarterCarParams = qc.PAPER_PARAMS):
    """Extended quarter car with tire relaxation (eq. (1) with a transient slip): returns (v', omega', lambda_t').

        m v'               = -F_z mu(lambda_t) - F_d(v)
        J omega'           =  r F_z mu(lambda_t) - T_b
        (sigma/v) lambda_t' = lambda(v, omega) - lambda_t

    :param v: vehicle speed [m/s]; :param omega: wheel speed [rad/s]; :param lam_t: transient slip [-].
    :param Tb: applied brake torque [N m]; :param road: (n, 4) Magic Formula parameters.
    :param r: rolling radius [m]; :param sigma: relaxation length [m] (> 0); :param c0: drag [N];
    :param c2: air drag coefficient [N s^2/m^2]; :param p: quarter-car parameters (m, J, F_z).
    """
    road = np.asarray(road, dtype=float)
    F = p.Fz * magic_formula(lam_t, road[..., 0], road[..., 1], road[..., 2], road[..., 3])
    drag = np.where(v > 0.0, c0 + c2 * v * v, 0.0)
    lam = longitudinal_slip(v, omega, r)
    return -(F + drag) / p.m, (r * F - Tb) / p.J, v * (lam - lam_t) / sigma


def _solve_relax(m, b: np.ndarray) -> np.ndarray:
    """Solve ``M k = b`` (b: (n, 3)) for the sparse ``M = [[m00, 0, m02], [0, 1, m12], [m20, m21, m22]]`` of
    :func:`relaxation_step` by elimination onto the transient slip (no inverse formed; ``m00 >= 1``)."""
    m00, m02, m12, m20, m21, m22 = m
    b0, b1, b2 = b[:, 0], b[:, 1], b[:, 2]
    k2 = (b2 - m20 * b0 / m00 - m21 * b1) / (m22 - m20 * m02 / m00 - m21 * m12)
    return np.stack([(b0 - m02 * k2) / m00, b1 - m12 * k2, k2], axis=1)


def relaxation_step(v, omega, lam_t, Tb, road, h: float, r, sigma, c0, c2,
                    p: qc.QuarterCarParams = qc.PAPER_PARAMS, gamma: float = RELAX_GAMMA):
    """One two-stage Rosenbrock step of :func:`relaxation_derivatives` (exact 3x3 Jacobian; the plant's ROS2
    scheme with ``gamma``, see :data:`RELAX_GAMMA`), then ``omega >= 0``, ``v >= 0``.

    :param h: step [s]; other parameters as in :func:`relaxation_derivatives` (arrays of shape (n,)).
    :param gamma: Rosenbrock gamma (second order for any value; 1 + 1/sqrt(2) is the L-stable ROS2).
    :return: (v, omega, lambda_t) after ``h``.
    """
    road = np.asarray(road, dtype=float)
    B, C, E, th = road[..., 0], road[..., 1], road[..., 2], road[..., 3]
    fz_dmu = p.Fz * magic_formula_dslip(lam_t, B, C, E, th)
    lam, dlam_dv, dlam_dw = slip_and_partials(v, omega, r)
    hg = h * gamma
    # I - h gamma A; the Jacobian A has zeros at (0, 1), (1, 0), (1, 1), so M is sparse the same way
    m00 = 1.0 - hg * np.where(v > 0.0, -2.0 * c2 * v / p.m, 0.0)
    m02 = hg * fz_dmu / p.m
    m12 = -hg * r * fz_dmu / p.J
    m20 = -hg * ((lam - lam_t) / sigma + v / sigma * dlam_dv)
    m21 = -hg * v / sigma * dlam_dw
    m22 = 1.0 + hg * v / sigma
    m = (m00, m02, m12, m20, m21, m22)

    def f(x):
        return np.stack(relaxation_derivatives(x[:, 0], np.maximum(x[:, 1], 0.0), x[:, 2], Tb, road, r, sigma,
                                               c0, c2, p), axis=1)

    x = np.stack([v, omega, lam_t], axis=1)
    k1 = _solve_relax(m, f(x))
    k2 = _solve_relax(m, f(x + h * k1) - 2.0 * k1)
    x = x + h * (1.5 * k1 + 0.5 * k2)
    return np.maximum(x[:, 0], 0.0), np.maximum(x[:, 1], 0.0), np.clip(x[:, 2], -1.0, 1.0)


# --------------------------------------------------------------------------------------------- simulator
class EffectSimulator:
    """Batched quarter car with effects, advanced one 10 ms sample (zero-order-held command) at a time.

    Elements may start at different sample indices of one shared command log (the gap tool's prediction windows),
    or receive their commands step by step from a controller (the real stand-in's closed loop).

    :param batch: per-element model (road and effect parameters).
    :param dt: sample time [s].
    :param n_samples: length of the command history [samples].
    :param p: quarter-car parameters.
    :param substeps: physics substeps per sample.
    :param t0: log time of sample 0 [s] (``mu_change`` switches on log time).
    :param commands: a preset command log, (n_samples,) shared or (n, n_samples); if None, :meth:`step` records the
        commands it is given.
    """

    def __init__(self, batch: ModelBatch, dt: float, n_samples: int, p: qc.QuarterCarParams = qc.PAPER_PARAMS,
                 substeps: int = DEFAULT_SUBSTEPS, t0: float = 0.0, commands: np.ndarray | None = None):
        if substeps < 1:
            raise ValueError(f"substeps must be >= 1, got {substeps}")
        if dt <= 0:
            raise ValueError(f"dt must be > 0, got {dt}")
        self.batch, self.dt, self.p, self.substeps, self.t0 = batch, float(dt), p, int(substeps), float(t0)
        n = len(batch)
        self.n = n
        if commands is None:
            self._cmd = np.zeros((n, n_samples))
            self._record = True
        else:
            commands = np.asarray(commands, dtype=float)
            self._cmd = commands[None, :] if commands.ndim == 1 else commands
            self._record = False
        self._rows = np.arange(n) if self._cmd.shape[0] == n else np.zeros(n, dtype=int)
        self._relax = batch.sigma > 0.0
        self._any_relax = bool(np.any(self._relax))
        self._std = ~self._relax
        # elements of one rolling radius share one plant call; their parameters are made once, not per substep
        self._groups = [(float(r), np.flatnonzero((batch.r_eff == r) & self._std)) for r in np.unique(batch.r_eff)]
        self._groups = [(idx, p if r == p.r else replace(p, r=r)) for r, idx in self._groups if idx.size]
        self._single = len(self._groups) == 1 and self._groups[0][0].size == n
        self._any_drag = bool(np.any(batch.c0 != 0.0) or np.any(batch.c2 != 0.0))
        self._any_lag = bool(np.any(batch.tau > 0.0))
        self._any_delay = bool(np.any(batch.delay > 0.0))
        self._any_change = bool(np.any(np.isfinite(batch.t_change)))
        self._any_fade = bool(np.any(batch.fade != 0.0))
        self._any_load = bool(np.any(batch.load != 0.0))
        self._any_slide = bool(np.any(batch.slide != 0.0))
        self._init_actuator()
        self.reset(np.zeros(n), np.zeros(n))

    def _init_actuator(self) -> None:
        """Per-element constants of the actuator chain over one substep (delay and lag are fixed per element)."""
        h = self.dt / self.substeps
        tau = self.batch.tau
        lagged = tau > 0.0
        safe_tau = np.where(lagged, tau, 1.0)
        e = np.exp(-h / safe_tau)
        # exact lag over a substep of constant input u: T_a+ = u + (T_a - u) keep, mean = u + (T_a - u) spread
        self._lag_keep = np.where(lagged, e, 0.0)
        self._lag_spread = np.where(lagged, safe_tau / h * (1.0 - e), 0.0)
        # delayed sample of substep j of sample k: k + offset[j] (weight frac[j]) and the next one (1 - frac[j])
        width = 1.0 / self.substeps
        self._delay_offset, self._delay_frac = [], []
        for j in range(self.substeps):
            s_a = j * width - self.batch.delay / self.dt
            i0 = np.floor(s_a + _INDEX_EPS).astype(int)
            self._delay_offset.append(i0)
            self._delay_frac.append(np.clip((i0 + 1 - s_a) / width, 0.0, 1.0))

    # -- state
    def reset(self, v, omega, k0=0, Ta=None, lam_t=None) -> None:
        """Set the state: speeds, start sample index per element, lag-filter output and transient slip.

        :param v: vehicle speed [m/s], (n,).
        :param omega: wheel speed [rad/s], (n,).
        :param k0: sample index of the first step, int or (n,).
        :param Ta: lag filter state [N m] (default: the delayed command at k0 times 1, i.e. settled).
        :param lam_t: transient slip [-] (default: the slip of (v, omega)).
        """
        n = self.n
        self.v = np.array(np.broadcast_to(np.asarray(v, dtype=float), (n,)))
        self.omega = np.array(np.broadcast_to(np.asarray(omega, dtype=float), (n,)))
        self.k = np.array(np.broadcast_to(np.asarray(k0, dtype=int), (n,)))
        if Ta is None:
            Ta = self._command_at(self.k) if not self._record else 0.0
        self.Ta = np.array(np.broadcast_to(np.asarray(Ta, dtype=float), (n,)))
        if lam_t is None:
            lam_t = longitudinal_slip(self.v, self.omega, self.batch.r_eff)
        self.lam_t = np.array(np.broadcast_to(np.asarray(lam_t, dtype=float), (n,)))
        self.energy = np.zeros(n)
        self.pitch = np.zeros(n)
        self.pitch_rate = np.zeros(n)
        self.applied = np.zeros(n)

    # -- actuator chain
    def _command_at(self, idx: np.ndarray) -> np.ndarray:
        """Logged command at sample ``idx`` of each element, held at the ends of the log."""
        return self._cmd[self._rows, np.minimum(np.maximum(idx, 0), self._cmd.shape[1] - 1)]

    def _delayed(self, j: int) -> np.ndarray:
        """Command delayed by ``delay``, averaged exactly over substep ``j`` of the current sample (ZOH input)."""
        idx = self.k + self._delay_offset[j]
        f = self._delay_frac[j]
        return f * self._command_at(idx) + (1.0 - f) * self._command_at(idx + 1)

    def _actuator_substep(self, j: int, held: np.ndarray | None = None) -> np.ndarray:
        """Mean applied torque over substep ``j`` (delay -> lag -> gain [-> fade]); advances the lag state.

        :param held: this sample's command without delay (read here if None; callers pass it once per sample).
        """
        if self._any_delay:
            u = self._delayed(j)
        else:
            u = self._command_at(self.k) if held is None else held
        if self._any_lag:
            offset = self.Ta - u
            mean = u + offset * self._lag_spread
            self.Ta = u + offset * self._lag_keep
        else:
            mean = u
            self.Ta = u
        torque = self.batch.gain * mean
        if self._any_fade:
            torque = torque / (1.0 + self.batch.fade * self.energy)
        return torque

    def actuator_run(self, n_steps: int) -> np.ndarray:
        """Lag-filter state at the start of each of ``n_steps`` samples, actuator only (no plant): (n, n_steps).

        Without delay or fade the lag is driven by the zero-order-held command, and its exact solution over a whole
        sample is the same recursion as over the substeps composed: ``T_a+ = u + (T_a - u) exp(-dt/tau)``; that
        case runs as a linear filter (scipy ``lfilter``) per element instead of a Python loop over substeps.
        """
        if not (self._any_delay or self._any_fade) and self._cmd.shape[0] == 1:
            from scipy.signal import lfilter

            u = self._cmd[0, self.k[0]:self.k[0] + n_steps]
            out = np.empty((self.n, n_steps))
            for i in range(self.n):
                if self.batch.tau[i] > 0:
                    a = np.exp(-self.dt / self.batch.tau[i])
                    # y[k+1] = a y[k] + (1 - a) u[k], y[0] = Ta: filter then shift by one sample
                    y, _ = lfilter([0.0, 1.0 - a], [1.0, -a], u, zi=[self.Ta[i]])
                    out[i] = y
                else:
                    out[i, 0] = self.Ta[i]
                    out[i, 1:] = u[:-1]
            self.k = self.k + n_steps
            self.Ta = out[:, -1].copy()
            return out
        out = np.empty((self.n, n_steps))
        for i in range(n_steps):
            out[:, i] = self.Ta
            for j in range(self.substeps):
                self._actuator_substep(j)
            self.k = self.k + 1
        return out

    # -- road and forces
    def _road_at(self, t_end: np.ndarray, h: float) -> np.ndarray:
        """Road of each element over the substep ending at ``t_end`` (theta blended in the switching substep)."""
        road = self.batch.road
        if not (self._any_change or self._any_load or self._any_slide):
            return road
        road = road.copy()
        if self._any_change:
            frac = np.clip((t_end - self.batch.t_change) / h, 0.0, 1.0)
            frac = np.where(np.isfinite(self.batch.t_change), frac, 0.0)
            road[:, 3] = road[:, 3] + frac * (self.batch.theta_after - road[:, 3])
        if self._any_load:
            road[:, 3] = road[:, 3] * np.maximum(1.0 + self.batch.load * self.pitch, 0.0)
        if self._any_slide:  # at the substep's start state: the factor varies slowly next to the slip dynamics
            sliding = np.maximum(self.v - self.omega * self.batch.r_eff, 0.0)
            road[:, 3] = road[:, 3] * np.exp(-self.batch.slide * sliding)
        return road

    def tire_force(self) -> np.ndarray:
        """Current longitudinal tire force [N] of each element."""
        t = self.t0 + self.k * self.dt
        road = self._road_at(t, self.dt / self.substeps)
        F = np.empty(self.n)
        if np.any(self._std):
            s = self._std
            lam = longitudinal_slip(self.v[s], self.omega[s], self.batch.r_eff[s])
            F[s] = self.p.Fz * magic_formula(lam, *road[s].T)
        if self._any_relax:
            s = self._relax
            F[s] = np.where(self.v[s] > 0.0, self.p.Fz * magic_formula(self.lam_t[s], *road[s].T), 0.0)
        return F

    def accel(self) -> np.ndarray:
        """Current longitudinal acceleration [m/s^2] (negative when braking), as an accelerometer reads it."""
        drag = np.where(self.v > 0.0, self.batch.c0 + self.batch.c2 * self.v**2, 0.0)
        return -(self.tire_force() + drag) / self.p.m

    def _drag_half(self, h: float) -> None:
        b = self.batch
        s = self._std
        dv = 0.5 * h * (b.c0[s] + b.c2[s] * self.v[s] ** 2) / self.p.m
        self.v[s] = np.maximum(self.v[s] - np.where(self.v[s] > 0.0, dv, 0.0), 0.0)

    # -- one sample
    def step(self, Tb: np.ndarray | float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Advance every element by one sample under its (commanded) brake torque.

        :param Tb: commanded torque [N m] for this sample, (n,) or scalar; None reads it from the preset log.
        :return: (v, omega) after the sample (views of the state; copy to keep).
        """
        if Tb is not None:
            if not self._record:
                raise ValueError("this simulator replays a preset command log; call step() without Tb")
            col = np.clip(self.k, 0, self._cmd.shape[1] - 1)
            self._cmd[self._rows, col] = np.broadcast_to(np.asarray(Tb, dtype=float), (self.n,))
        h = self.dt / self.substeps
        p = self.p
        held = None if self._any_delay else self._command_at(self.k)
        for j in range(self.substeps):
            torque = self._actuator_substep(j, held)
            t_end = self.t0 + (self.k + (j + 1) / self.substeps) * self.dt
            road = self._road_at(t_end, h)
            if self._any_fade or self._any_load:
                decel = self.tire_force() / p.m
            if self._any_drag:
                self._drag_half(h)
            if self._single:
                self.v, self.omega = qc.step(self.v, self.omega, torque, road, h, self._groups[0][1], 1)
            else:
                for idx, pr in self._groups:
                    self.v[idx], self.omega[idx] = qc.step(self.v[idx], self.omega[idx], torque[idx], road[idx], h,
                                                           pr, 1)
                if self._any_relax:
                    s = self._relax
                    b = self.batch
                    self.v[s], self.omega[s], self.lam_t[s] = relaxation_step(
                        self.v[s], self.omega[s], self.lam_t[s], torque[s], road[s], h, b.r_eff[s], b.sigma[s],
                        b.c0[s], b.c2[s], p)
            if self._any_drag:
                self._drag_half(h)
            if self._any_fade:
                self.energy = self.energy + torque * self.omega * h
            if self._any_load:
                # semi-implicit Euler of the pitch mode driven by the deceleration in g
                acc = _PITCH_OMEGA**2 * (decel / p.g - self.pitch) - 2 * _PITCH_ZETA * _PITCH_OMEGA * self.pitch_rate
                self.pitch_rate = self.pitch_rate + h * acc
                self.pitch = self.pitch + h * self.pitch_rate
            self.applied = torque
        self.k = self.k + 1
        return self.v, self.omega


def simulate_with_effects(effects: Sequence, road: MagicFormula | np.ndarray, torque, v0: float, n_samples: int,
                          dt: float = 0.01, p: qc.QuarterCarParams = qc.PAPER_PARAMS,
                          substeps: int = DEFAULT_SUBSTEPS, t0: float = 0.0,
                          measure: Callable[[np.ndarray], np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """Simulate one quarter car with effects, open loop or under a controller: the policy-level API of the gap tool.

    :param effects: effect specs (:func:`make_effect`); empty for the nominal simulator.
    :param road: Magic Formula road.
    :param torque: commanded torque [N m], an array of ``n_samples`` values, or a controller
        ``torque(k, t, omega_measured) -> float`` called every sample with the measured wheel speed.
    :param v0: initial speed [m/s]; the wheel starts free rolling (``omega r_eff = v0``).
    :param n_samples: number of samples.
    :param dt: sample time [s]; :param p: quarter-car parameters; :param substeps: physics substeps per sample.
    :param t0: log time of the first sample [s].
    :param measure: optional map from true omega to measured omega (e.g. adds noise); identity if None.
    :return: dict with arrays ``t``, ``T_cmd`` (commanded), ``T_applied`` (mean over the last substep), ``v``,
        ``omega`` (true), ``omega_meas``, ``a_x`` (true), each of length ``n_samples`` (values at the sample times,
        the command held over the following interval).
    """
    batch = ModelBatch.from_effects(road, effects, p)
    sim = EffectSimulator(batch, dt, n_samples, p, substeps, t0)
    r0 = float(batch.r_eff[0])
    sim.reset(np.array([v0]), np.array([v0 / r0]))
    out = {name: np.empty(n_samples) for name in ("t", "T_cmd", "T_applied", "v", "omega", "omega_meas", "a_x")}
    controller = torque if callable(torque) else None
    if controller is None:
        torque = np.asarray(torque, dtype=float)
        if torque.shape != (n_samples,):
            raise ValueError(f"torque must have shape ({n_samples},), got {torque.shape}")
    for k in range(n_samples):
        t = t0 + k * dt
        w_meas = measure(sim.omega.copy()) if measure is not None else sim.omega.copy()
        cmd = float(controller(k, t, float(w_meas[0]))) if controller is not None else float(torque[k])
        out["t"][k], out["v"][k], out["omega"][k] = t, sim.v[0], sim.omega[0]
        out["omega_meas"][k], out["a_x"][k], out["T_cmd"][k] = w_meas[0], sim.accel()[0], cmd
        sim.step(np.array([cmd]))
        out["T_applied"][k] = sim.applied[0]
    return out
