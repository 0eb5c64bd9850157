"""Braking set-up: the constants (:class:`BrakingConfig`), the observation layout, the scenario (road, friction
change, initial speed) and the physical-limit distance of the ``fricenv/Braking-v0`` family.

The episode itself (actuator, physics substeps, ECU measurement, wheel lock, reward, episode figures) is
:class:`fricenv.envs.braking_sim.BrakingSim` over :mod:`fricenv.envs.episode`; :class:`BrakingSim` is re-exported
here for existing imports.

Measurement model (what an ABS ECU has), per control step of ``dt`` (10 ms):

=================  ==========================================================================================
channel            model
=================  ==========================================================================================
wheel speed        ``omega + e``, ``e ~ N(0, 0.2 (rad/s)^2)`` (Sui & Johansen, Section V)
wheel decel        ``-r (omega_k - omega_{k-1}) / dt + e``, ``e ~ N(0, decel_noise_std^2)``: the ECU's wheel
                   deceleration (from sensor tooth timing), positive when the wheel slows down [m/s^2]
longitudinal acc.  ``(v_k - v_{k-1}) / dt + e``, ``e ~ N(0, ax_noise_std^2)`` [m/s^2], negative when braking
=================  ==========================================================================================
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from fricenv.plants import quarter_car as qc
from fricenv.plants import sui_johansen as sj
from fricenv.plants.tire import ROADS, MagicFormula, get_road

__all__ = [
    "ACTION_MODES",
    "NOISE_BLOCK",
    "OBSERVATION_MODES",
    "RESET_OPTION_KEYS",
    "BrakingConfig",
    "BrakingSim",
    "ObsField",
    "Scenario",
    "decode_observation",
    "limit_distance",
    "observation_layout",
    "resolve_scenario",
    "valid_road_names",
]

# Control step of the ECU [s] and default physics substep [s] (5 substeps per control step).
CONTROL_DT = sj.SAMPLE_TIME
PHYSICS_DT = 0.002
# Brake torque at action +1 [N m]: locks the wheel on dry asphalt (r F_z mu_max = 1100 N m) with a wide margin.
T_MAX = 2500.0
# Torque-rate mode: brake modulator rate at action +-1 [N m/s] (full range in 0.1 s).
TORQUE_RATE_MAX = 25000.0
V_STOP = 2.0  # episode ends when the vehicle is this slow [m/s]
TIME_LIMIT = 60.0  # truncation [s]; a locked wheel on ice stops from 40 m/s in ~42 s
V0_DEFAULT = 20.0  # [m/s]
CHANGE_DISTANCE_DEFAULT = 15.0  # where a friction-change scenario switches road [m]
RANDOM_CHANGE_RANGE = (5.0, 30.0)  # change distance drawn for road="random-change" [m]
OMEGA_NOISE_VAR = sj.OMEGA_NOISE_VAR  # wheel-speed noise variance [(rad/s)^2], Sui & Johansen Section V
DECEL_NOISE_STD = 1.0  # wheel-deceleration noise [m/s^2]
AX_NOISE_STD = 0.1  # longitudinal accelerometer noise [m/s^2]
LOCK_SPEED_RATIO = 0.05  # wheel counts as locked while omega r < 0.05 v ...
LOCK_TIME = 0.1  # ... for longer than this [s], above v_stop
LOCK_PENALTY = 0.01  # reward subtracted per control step while locked [-]
NOISE_BLOCK = 512  # control steps of noise drawn at once per car
# Speed margin [m/s] of the per-step road-switch reach test: more than any tire force adds in one control step
# (F_z theta / m * dt is about 0.1 m/s), so a car that cannot reach its change point is never tested for it.
REACH_SPEED_SLACK = 1.0
N_NOISE = 3  # noisy channels: wheel speed, wheel deceleration, a_x

ACTION_MODES = ("torque", "torque_rate")
OBSERVATION_MODES = ("default", "oracle")
RESET_OPTION_KEYS = ("road", "v0", "change_distance")
SCENARIO_SEPARATOR = "->"
RANDOM_ROADS = ("random", "random-change")


@dataclass(frozen=True)
class BrakingConfig:
    """Constants of one braking set-up (shared by all cars of a :class:`BrakingSim`)."""

    dt: float = CONTROL_DT  # control step [s]
    physics_dt: float = PHYSICS_DT  # physics substep [s]; must divide dt
    t_max: float = T_MAX  # brake torque at action +1 [N m]
    torque_rate_max: float = TORQUE_RATE_MAX  # torque rate at action +-1 in torque_rate mode [N m/s]
    v_stop: float = V_STOP  # stop speed [m/s]
    time_limit: float = TIME_LIMIT  # episode truncation [s]
    omega_noise_var: float = OMEGA_NOISE_VAR  # [(rad/s)^2]
    decel_noise_std: float = DECEL_NOISE_STD  # [m/s^2]
    ax_noise_std: float = AX_NOISE_STD  # [m/s^2]
    lock_speed_ratio: float = LOCK_SPEED_RATIO  # [-]
    lock_time: float = LOCK_TIME  # [s]
    lock_penalty: float = LOCK_PENALTY  # per control step [-]
    action_mode: str = "torque"  # "torque" | "torque_rate"
    observation: str = "default"  # "default" | "oracle"
    params: qc.QuarterCarParams = field(default=qc.PAPER_PARAMS)  # quarter-car parameters

    def __post_init__(self):
        for name in ("dt", "physics_dt", "t_max", "torque_rate_max", "v_stop", "time_limit", "lock_time"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
        for name in ("omega_noise_var", "decel_noise_std", "ax_noise_std", "lock_speed_ratio", "lock_penalty"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        ratio = self.dt / self.physics_dt
        if abs(ratio - round(ratio)) > 1e-9 * ratio or round(ratio) < 1:
            raise ValueError(f"physics_dt={self.physics_dt} must divide the control step dt={self.dt} "
                             f"a whole number of times")
        if self.action_mode not in ACTION_MODES:
            raise ValueError(f"unknown action_mode {self.action_mode!r}; valid: {', '.join(ACTION_MODES)}")
        if self.observation not in OBSERVATION_MODES:
            raise ValueError(f"unknown observation {self.observation!r}; valid: {', '.join(OBSERVATION_MODES)}")
        if not isinstance(self.params, qc.QuarterCarParams):
            raise TypeError(f"params must be a QuarterCarParams, got {type(self.params).__name__}")

    @property
    def substeps(self) -> int:
        """Physics substeps per control step."""
        return round(self.dt / self.physics_dt)

    @property
    def max_steps(self) -> int:
        """Control steps before truncation."""
        return math.ceil(self.time_limit / self.dt - 1e-9)

    @property
    def lock_steps(self) -> int:
        """A wheel is locked after more than this many consecutive lock-condition steps."""
        return round(self.lock_time / self.dt)


@dataclass(frozen=True)
class ObsField:
    """One entry of the observation vector: ``obs = clip(value / scale, low, high)``."""

    name: str
    unit: str  # unit of the physical value
    scale: float  # physical value per observation unit
    low: float  # bound of the scaled entry
    high: float  # bound of the scaled entry
    description: str

    def decode(self, x):
        """Physical value [unit] of a scaled observation entry."""
        return np.asarray(x, dtype=float) * self.scale


def decode_observation(fields: Sequence[ObsField], obs) -> dict[str, float]:
    """Physical values (units of ``fields``) of an observation vector, by name."""
    obs = np.asarray(obs, dtype=float)
    return {f.name: float(obs[j] * f.scale) for j, f in enumerate(fields)}


G_STD = 9.81  # scaling of accelerations [m/s^2 per observation unit]
_DEFAULT_FIELDS = (
    ObsField("wheel_speed", "rad/s", 100.0, -1.0, 2.0, "measured wheel speed omega_m"),
    ObsField("wheel_decel", "m/s^2", G_STD, -50.0, 50.0,
             "measured wheel deceleration -r omega', positive when the wheel slows"),
    ObsField("torque", "-", 1.0, 0.0, 1.0, "last brake-torque command T_b / T_max"),
    ObsField("a_x", "m/s^2", G_STD, -5.0, 5.0, "measured longitudinal acceleration, negative when braking"),
)
_ORACLE_FIELDS = (
    ObsField("v", "m/s", 50.0, 0.0, 2.0, "true vehicle speed"),
    ObsField("slip", "-", 1.0, -1.0, 1.0, "true wheel slip"),
    ObsField("mu", "-", 1.0, -2.0, 2.0, "true friction coefficient in use"),
)


def observation_layout(observation: str = "default") -> tuple[ObsField, ...]:
    """The observation entries, in order, for an observation mode."""
    if observation not in OBSERVATION_MODES:
        raise ValueError(f"unknown observation {observation!r}; valid: {', '.join(OBSERVATION_MODES)}")
    return _DEFAULT_FIELDS + (_ORACLE_FIELDS if observation == "oracle" else ())


@dataclass(frozen=True)
class Scenario:
    """One car's episode set-up: road before/after the friction change, where it changes, initial speed."""

    name: str  # e.g. "dry", "dry->ice"
    road_a: MagicFormula  # road from the start
    road_b: MagicFormula  # road after change_distance (= road_a if no change)
    change_distance: float  # [m]; inf if the road does not change
    v0: float  # initial speed [m/s]


def valid_road_names() -> list[str]:
    """Every road name accepted by :func:`resolve_scenario` (presets, random draws, preset pairs ``a->b``)."""
    pairs = [f"{a}{SCENARIO_SEPARATOR}{b}" for a in ROADS for b in ROADS if a != b]
    return [*ROADS, *RANDOM_ROADS, *pairs]


def _parse_range(value, name: str, low_bound: float) -> tuple[float, float]:
    """A number or a (low, high) pair as a range; raises ValueError naming ``name``."""
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool):
        lo = hi = float(value)
    elif isinstance(value, (tuple, list, np.ndarray)) and len(value) == 2:
        lo, hi = (float(value[0]), float(value[1]))
    else:
        raise ValueError(f"{name} must be a number or a (low, high) pair, got {value!r}")
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi or lo <= low_bound:
        raise ValueError(f"{name} must be finite, with low <= high and > {low_bound}, got {value!r}")
    return lo, hi


def _draw(rng: np.random.Generator, lo: float, hi: float) -> float:
    """A uniform draw on [lo, hi]; no draw (and no generator use) if the range is a single value."""
    return lo if lo == hi else float(rng.uniform(lo, hi))


def resolve_scenario(road: str | MagicFormula, v0, change_distance, v_stop: float,
                     rng: np.random.Generator) -> Scenario:
    """Turn a road spec, an initial-speed spec and a change-distance spec into a :class:`Scenario`.

    Draws come from ``rng`` in a fixed order (road, then change distance, then v0), only for the parts that are
    random, so the same generator state gives the same scenario.

    :param road: a preset name (``dry``, ``wet``, ``snow``, ``ice``), ``"a->b"`` for a friction change from preset
        ``a`` to preset ``b`` at ``change_distance``, ``"random"`` (a preset drawn uniformly), ``"random-change"``
        (two different presets drawn uniformly, change distance drawn on :data:`RANDOM_CHANGE_RANGE` unless
        given as a range), or a :class:`~fricenv.plants.tire.MagicFormula`.
    :param v0: initial speed [m/s], a number or a (low, high) range drawn uniformly.
    :param change_distance: distance of the friction change [m], a number or a (low, high) range.
    :param v_stop: stop speed [m/s]; v0 must exceed it.
    :param rng: the car's generator.
    :return: the scenario.
    """
    names = list(ROADS)
    road_b = None
    if isinstance(road, MagicFormula):
        road_a, name = road, road.name
    elif not isinstance(road, str):
        raise TypeError(f"road must be a road name or a MagicFormula, got {type(road).__name__}; "
                         f"valid names: {', '.join(valid_road_names())}")
    elif road == "random":
        road_a = ROADS[names[int(rng.integers(len(names)))]]
        name = road_a.name
    elif road == "random-change":
        i = int(rng.integers(len(names)))
        j = int(rng.integers(len(names) - 1))
        j = j + 1 if j >= i else j
        road_a, road_b = ROADS[names[i]], ROADS[names[j]]
        name = f"{road_a.name}{SCENARIO_SEPARATOR}{road_b.name}"
    elif SCENARIO_SEPARATOR in road:
        parts = road.split(SCENARIO_SEPARATOR)
        if len(parts) != 2 or parts[0] not in ROADS or parts[1] not in ROADS:
            raise ValueError(f"unknown road {road!r}; valid: {', '.join(valid_road_names())}")
        road_a, road_b = ROADS[parts[0]], ROADS[parts[1]]
        name = road
    elif road in ROADS:
        road_a, name = get_road(road), road
    else:
        raise ValueError(f"unknown road {road!r}; valid: {', '.join(valid_road_names())}")

    if road_b is None:
        distance = math.inf
        road_b = road_a
    else:
        if change_distance is None:
            change_distance = RANDOM_CHANGE_RANGE if road == "random-change" else CHANGE_DISTANCE_DEFAULT
        lo, hi = _parse_range(change_distance, "change_distance", 0.0)
        distance = _draw(rng, lo, hi)
    lo, hi = _parse_range(V0_DEFAULT if v0 is None else v0, "v0", v_stop)
    return Scenario(name=name, road_a=road_a, road_b=road_b, change_distance=distance, v0=_draw(rng, lo, hi))


def limit_distance(v0, v_stop, mu_a, mu_b, change_distance, g: float = qc.PAPER_PARAMS.g):
    """Physical-limit stopping distance [m] with peak friction held the whole way, piecewise over a change.

    On one road this is ``(v0^2 - v_stop^2) / (2 g mu_max)`` (:func:`~fricenv.plants.quarter_car.
    physical_limit_distance`). With a change from ``mu_a`` to ``mu_b`` at distance ``d``: if the limit stop on road
    a ends before ``d`` that is the answer; otherwise the car reaches ``d`` at ``v_d^2 = v0^2 - 2 g mu_a d`` and
    stops on road b, ``d + (v_d^2 - v_stop^2) / (2 g mu_b)``. Broadcasts over arrays.
    """
    v0, mu_a, mu_b, d = (np.asarray(x, dtype=float) for x in (v0, mu_a, mu_b, change_distance))
    first = (v0**2 - v_stop**2) / (2.0 * g * mu_a)
    d_fin = np.where(np.isfinite(d), d, 0.0)
    vd2 = v0**2 - 2.0 * g * mu_a * d_fin
    second = d_fin + (vd2 - v_stop**2) / (2.0 * g * mu_b)
    return np.where(first <= d, first, second)


def _as_index_array(cars, n: int) -> np.ndarray:
    """Car indices from a boolean mask of length n, an index sequence, or None (all cars)."""
    if cars is None:
        return np.arange(n)
    arr = np.asarray(cars)
    if arr.dtype == bool:
        if arr.shape != (n,):
            raise ValueError(f"car mask must have shape ({n},), got {arr.shape}")
        return np.flatnonzero(arr)
    arr = np.atleast_1d(arr).astype(np.intp, copy=False)
    if arr.size and (arr.min() < 0 or arr.max() >= n):
        raise ValueError(f"car indices must be in [0, {n}), got {arr.tolist()}")
    return arr


# BrakingSim lives in its own module (the episode); re-exported here for existing imports.
from fricenv.envs.braking_sim import BrakingSim
