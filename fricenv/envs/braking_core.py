"""Batched braking simulation: ``n`` quarter cars stepped in one numpy call (no Gymnasium).

:class:`BrakingSim` is the whole of the ``fricenv/Braking-v0`` environment except the Gymnasium shell: scenario
(road, friction change, initial speed), the brake actuator (torque or torque-rate command), the physics substeps of
:func:`fricenv.plants.quarter_car.step`, the ECU measurement model, wheel-lock detection, reward, termination and
truncation, and the episode figures (stopping distance, physical-limit distance, ratio). Every per-step quantity is
an array over the ``n`` cars; :meth:`BrakingSim.step` has no Python loop over cars, so a vector env can step 1024
cars at once, and :meth:`BrakingSim.reset_cars` resets any subset of cars (for per-env autoreset).

Randomness. Each car owns a ``numpy.random.Generator``. At reset the car's scenario draws (random road, initial
speed, change distance) come from it first, then its measurement noise is drawn from it in blocks of
:data:`NOISE_BLOCK` control steps (standard normals, one column per noisy channel) and consumed by index. A car
therefore sees the same noise whether it is simulated alone or in a batch, and whatever the other cars do.

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
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fricenv.envs.braking_kernels import Ros2Batch, make_scalar_substep, scalar_road
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import ROADS, SLIP_SPEED_FLOOR, MagicFormula, get_road, magic_formula

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
CONTROL_DT = 0.01
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
OMEGA_NOISE_VAR = 0.2  # wheel-speed noise variance [(rad/s)^2], Sui & Johansen
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


class BrakingSim:
    """``n`` quarter cars braking, each with its own scenario, noise generator and episode clock.

    Typical use::

        sim = BrakingSim(n, BrakingConfig(), road="dry", v0=20.0)
        sim.reset_cars(None, [np.random.default_rng(s) for s in seeds])
        obs, reward, terminated, truncated = sim.step(actions)   # actions: (n,) in [-1, 1]

    Arrays returned by :meth:`observe` and :meth:`step` are internal buffers, valid until the next call: copy
    them to keep them.

    Speed. The physics substeps run in :class:`fricenv.envs.braking_kernels.Ros2Batch` (the ROS2 substep of
    :func:`fricenv.plants.quarter_car.step` with shared subexpressions and cached road constants, equal to it to
    1e-12). With ``scalar=True`` (one car only) every step runs in Python floats instead
    (:func:`~fricenv.envs.braking_kernels.make_scalar_substep`), which is several times faster for one car than
    numpy on 1-element arrays; it equals the batched path to about 1e-12 (not bit for bit: ``math`` and numpy
    round transcendentals differently). ``BrakingEnv`` uses it. Per-car state (``v``, ``omega``, ``slip``, ``mu``, ``x``, ``t``, ``torque``,
    ``locked``, ``lock_seen``, ``stop_distance``, ``limit``, ...) is public, read-only by convention.

    :param n: number of cars.
    :param config: constants shared by all cars.
    :param road: default road spec for every car (see :func:`resolve_scenario`), overridable per reset.
    :param v0: default initial speed [m/s] or (low, high) range.
    :param change_distance: default friction-change distance [m] or range; None: 15 m (random-change: 5..30 m).
    :param scalar: step the single car in Python floats (requires ``n == 1``).
    """

    def __init__(self, n: int, config: BrakingConfig | None = None, *, road: str | MagicFormula = "dry",
                 v0=V0_DEFAULT, change_distance=None, scalar: bool = False):
        if not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n must be an int >= 1, got {n!r}")
        if scalar and n != 1:
            raise ValueError(f"scalar=True steps one car in Python floats; it needs n == 1, got n={n}")
        self.n = int(n)
        self.scalar = bool(scalar)
        self.config = config if config is not None else BrakingConfig()
        c = self.config
        # Validate the defaults once (a throwaway generator: only the spec is checked here).
        resolve_scenario(road, v0, change_distance, c.v_stop, np.random.default_rng(0))
        self.defaults = {"road": road, "v0": v0, "change_distance": change_distance}
        self.layout = observation_layout(c.observation)
        self._scale = np.array([f.scale for f in self.layout])
        self._low = np.array([f.low for f in self.layout])
        self._high = np.array([f.high for f in self.layout])
        self._noise_std = np.array([math.sqrt(c.omega_noise_var), c.decel_noise_std, c.ax_noise_std])
        self._h = c.dt / c.substeps
        self._p = c.params
        self._kernel = Ros2Batch(self.n, self._h, self._p)
        self._road_rows: dict[MagicFormula, tuple[float, float, float, float]] = {}
        # Scalar path: the substep function, the constants of the road in use, and the config's derived integers.
        self._substep1 = make_scalar_substep(self._h, self._p) if self.scalar else None
        self._road1: tuple[float, ...] = ()
        self._mf1: tuple[float, ...] = ()
        self._substeps, self._max_steps, self._lock_steps = c.substeps, c.max_steps, c.lock_steps
        # Observation scales with the torque entry's times t_max (the value scaled is T_b itself); scalar path:
        # (scale, low, high) per entry; noise standard deviations.
        torque_scale = np.ones(len(self.layout))
        torque_scale[2] = c.t_max
        self._scale_t = self._scale * torque_scale
        self._obs64 = np.zeros((self.n, len(self.layout)))
        self._obs_consts = tuple(zip(self._scale_t.tolist(), self._low.tolist(), self._high.tolist()))
        self._noise_sd = tuple(self._noise_std.tolist())
        n = self.n
        z = lambda: np.zeros(n)
        # Physical state and scenario, per car.
        self.v, self.omega, self.x, self.torque = z(), z(), z(), z()
        self.t = np.zeros(n, dtype=np.int64)  # control steps since reset
        self.road_a, self.road_b = np.zeros((n, 4)), np.zeros((n, 4))
        self.road = np.zeros((n, 4))  # road in use
        self.mu_peak_a, self.mu_peak_b, self.mu_peak = z(), z(), z()
        self.change_distance = np.full(n, np.inf)
        self._next_change = np.full(n, np.inf)  # change distance until the switch, then inf [m]
        self.switched = np.zeros(n, dtype=bool)
        self.v0, self.limit = z(), z()
        self.names: list[str] = [""] * n
        self.scenarios: list[Scenario | None] = [None] * n
        # Derived per-step quantities.
        self.slip, self.mu = z(), z()
        self.lock_count = np.zeros(n, dtype=np.int64)
        self.locked = np.zeros(n, dtype=bool)  # lock condition held > lock_time now
        self.lock_seen = np.zeros(n, dtype=bool)  # locked at any time this episode
        self.stopped = np.zeros(n, dtype=bool)
        self.stop_distance = np.full(n, np.nan)
        self.stop_time = np.full(n, np.nan)
        self.meas = np.zeros((n, N_NOISE))  # measured wheel speed, wheel decel, a_x
        # Noise blocks, per car.
        self.rngs: list[np.random.Generator | None] = [None] * n
        self._noise = np.zeros((n, NOISE_BLOCK, N_NOISE))
        self._noise_idx = np.zeros(n, dtype=np.intp)
        self._noise_rows = self._noise.reshape(n * NOISE_BLOCK, N_NOISE)  # a view of the blocks
        self._row_base = np.arange(n) * NOISE_BLOCK
        self._arange = np.arange(n)
        # Output buffers.
        self._obs = np.zeros((n, len(self.layout)), dtype=np.float32)
        self.reward = z()
        self.terminated = np.zeros(n, dtype=bool)
        self.truncated = np.zeros(n, dtype=bool)

    # ------------------------------------------------------------------ reset
    def reset_cars(self, cars=None, rngs: Sequence[np.random.Generator] | None = None,
                   options: Mapping[str, Any] | Sequence[Mapping[str, Any] | None] | None = None) -> np.ndarray:
        """Start new episodes for some cars.

        :param cars: boolean mask (n,), index sequence, or None for all cars.
        :param rngs: one generator per reset car (in the order of ``cars``); None keeps each car's generator
            (a car that never had one gets fresh entropy).
        :param options: one dict for all reset cars, or one dict (or None) per reset car, with keys from
            :data:`RESET_OPTION_KEYS` overriding the defaults given to the constructor.
        :return: the observation buffer (all cars).
        """
        idx = _as_index_array(cars, self.n)
        if rngs is not None and len(rngs) != len(idx):
            raise ValueError(f"need one generator per reset car: {len(idx)} cars, {len(rngs)} generators")
        if options is None or isinstance(options, Mapping):
            per_car = [options] * len(idx)
        else:
            per_car = list(options)
            if len(per_car) != len(idx):
                raise ValueError(f"need one options dict per reset car: {len(idx)} cars, {len(per_car)} dicts")
        c = self.config
        rows: list[tuple] = []  # per reset car: (B, C, E, theta) of road a and b, peaks, change distance, v0
        for k, i in enumerate(idx):
            opts = per_car[k]
            if opts:
                unknown = sorted(set(opts) - set(RESET_OPTION_KEYS))
                if unknown:
                    raise ValueError(f"unknown reset option(s) {unknown}; valid: {', '.join(RESET_OPTION_KEYS)}")
                spec = {**self.defaults, **opts}
            else:
                spec = self.defaults
            if rngs is not None:
                self.rngs[i] = rngs[k]
            elif self.rngs[i] is None:
                self.rngs[i] = np.random.default_rng()
            rng = self.rngs[i]
            sc = resolve_scenario(spec["road"], spec["v0"], spec["change_distance"], c.v_stop, rng)
            self.scenarios[i] = sc
            self.names[i] = sc.name
            rows.append((*self._road_row(sc.road_a), *self._road_row(sc.road_b), sc.road_a.mu_max,
                         sc.road_b.mu_max, sc.change_distance, sc.v0))
            self._noise[i] = rng.standard_normal((NOISE_BLOCK, N_NOISE))
        if rows:  # one write per array instead of one per car
            table = np.array(rows, dtype=float)
            self.road_a[idx], self.road_b[idx] = table[:, 0:4], table[:, 4:8]
            self.mu_peak_a[idx], self.mu_peak_b[idx] = table[:, 8], table[:, 9]
            self.change_distance[idx], self.v0[idx] = table[:, 10], table[:, 11]
        self._noise_idx[idx] = 0
        self.limit[idx] = limit_distance(self.v0[idx], c.v_stop, self.mu_peak_a[idx], self.mu_peak_b[idx],
                                         self.change_distance[idx], self._p.g)
        self.road[idx] = self.road_a[idx]
        self._set_kernel_road(idx)
        self.mu_peak[idx] = self.mu_peak_a[idx]
        self.switched[idx] = False
        self._next_change[idx] = self.change_distance[idx]
        self.v[idx] = self.v0[idx]
        self.omega[idx] = self.v0[idx] / self._p.r  # free rolling
        self.x[idx] = 0.0
        self.t[idx] = 0
        self.torque[idx] = 0.0
        self.slip[idx] = 0.0
        self.mu[idx] = 0.0
        self.lock_count[idx] = 0
        self.locked[idx] = False
        self.lock_seen[idx] = False
        self.stopped[idx] = False
        self.stop_distance[idx] = np.nan
        self.stop_time[idx] = np.nan
        self.reward[idx] = 0.0
        self.terminated[idx] = False
        self.truncated[idx] = False
        noise = self._take_noise(idx)
        self.meas[idx, 0] = self.omega[idx] + noise[:, 0]
        self.meas[idx, 1] = noise[:, 1]
        self.meas[idx, 2] = noise[:, 2]
        if self.scalar or len(idx) == self.n:
            return self.observe()
        return self._observe_rows(idx)

    def _take_noise(self, idx: np.ndarray | None = None) -> np.ndarray:
        """The next noise row (scaled) of the given cars (all if None); refills exhausted blocks."""
        if idx is None:  # every car: gather one row per car from the flat (n * NOISE_BLOCK, N_NOISE) view
            pos = self._noise_idx
            out = np.take(self._noise_rows, self._row_base + pos, axis=0)
            out *= self._noise_std
            pos += 1
            if pos.max() >= NOISE_BLOCK:
                for i in np.flatnonzero(pos >= NOISE_BLOCK):  # once every NOISE_BLOCK steps per car
                    self._noise[i] = self.rngs[i].standard_normal((NOISE_BLOCK, N_NOISE))
                    pos[i] = 0
            return out
        pos = self._noise_idx[idx]
        out = self._noise[idx, pos] * self._noise_std
        pos += 1
        self._noise_idx[idx] = pos
        full = pos >= NOISE_BLOCK
        if full.any():
            for i in idx[full]:  # once every NOISE_BLOCK steps per car
                self._noise[i] = self.rngs[i].standard_normal((NOISE_BLOCK, N_NOISE))
                self._noise_idx[i] = 0
        return out

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_substep1"] = None  # a closure does not pickle; rebuilt from the config
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        if self.scalar:
            self._substep1 = make_scalar_substep(self._h, self._p)

    def _road_row(self, road: MagicFormula) -> tuple[float, float, float, float]:
        """(B, C, E, theta) of a road as floats, cached per road."""
        row = self._road_rows.get(road)
        if row is None:
            row = self._road_rows[road] = tuple(road.as_array().tolist())
        return row

    def _set_kernel_road(self, idx) -> None:
        """Copy the road in use of cars ``idx`` into the substep kernel's constants."""
        self._kernel.set_road(idx, self.road[idx])
        if self.scalar:
            self._mf1 = tuple(float(q) for q in self.road[0])  # (B, C, E, theta)
            self._road1 = scalar_road(*self._mf1, self._h, self._p)

    # ------------------------------------------------------------------ step
    def command_to_torque(self, action: np.ndarray) -> np.ndarray:
        """Brake torque [N m] after applying the (already clipped) normalized commands."""
        c = self.config
        if c.action_mode == "torque":
            return (action + 1.0) * (0.5 * c.t_max)
        return np.clip(self.torque + action * (c.torque_rate_max * c.dt), 0.0, c.t_max)

    def step(self, action, resetting=None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Advance every car by one control step.

        :param action: normalized commands, shape (n,) (or (n, 1)); NaN raises ValueError, values outside
            [-1, 1] are clipped.
        :param resetting: cars (indices or mask) that the caller resets right after this step and whose results
            it discards (a vector env's next-step autoreset). They are advanced like the others, but draw nothing
            from their generators, so their next episode is the one a single env would draw.
        :return: (observation (n, obs_dim) float32, reward (n,), terminated (n,), truncated (n,)) buffers.
        """
        if resetting is not None:
            # Rewind their noise cursor: no block refill (a generator draw) can happen in this step, and the
            # reset redraws the block anyway.
            self._noise_idx[_as_index_array(resetting, self.n)] = 0
        if self.scalar:
            return self._step_scalar(action)
        a = np.asarray(action, dtype=float)
        if a.shape != (self.n,):
            if a.shape == (self.n, 1):
                a = a[:, 0]
            else:
                raise ValueError(f"action must have shape ({self.n},) (one command per car), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action contains NaN or inf: {a[~np.isfinite(a)][:5].tolist()}")
        a = np.clip(a, -1.0, 1.0)
        c, p, h = self.config, self._p, self._h
        v_stop = c.v_stop
        kernel = self._kernel
        self.torque = Tb = self.command_to_torque(a)
        kernel.set_torque(Tb)
        v_start, w_start = self.v, self.omega
        v, w, x = v_start, w_start, self.x
        n = self.n
        # Substep sums (scaled once at the end): ssum = sum of (v_k + v_k+1), so x = x0 + h/2 ssum (trapezoid: the
        # speed is nearly linear over a 2 ms substep); esum = sum of (v_k^2 - v_k+1^2) and tsum = sum of
        # (v_k + v_k+1) while above v_stop, so the braking energy is esum / (2 g mu_peak) and the travel h/2 tsum.
        ssum, esum, tsum, energy = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
        inv_2g_mu = 1.0 / (2.0 * p.g * self.mu_peak)
        half_h = 0.5 * h
        x0 = x
        # Road switches are checked only if some car can reach its change point in this step.
        reach = c.dt * (float(v_start.max()) + REACH_SPEED_SLACK)
        check_switch = float((self._next_change - x0).min()) <= reach
        v_above = v.min() > v_stop  # every car above the stop speed at the start of the substep
        for sub in range(c.substeps):
            v_new, w_new = kernel.substep(v, w)
            s = v + v_new
            d = v - v_new
            d *= s  # v_k^2 - v_k+1^2
            new_above = v_new.min() > v_stop
            if v_above and new_above:  # every car above the stop speed before and after: the common case
                esum += d
                tsum += s
            else:
                active = v > v_stop
                d *= active  # the same value as np.where(active, d, 0.0), cheaper
                st = s * active
                cross = np.flatnonzero(active & (v_new <= v_stop))
                if cross.size:
                    # v^2 is linear in distance at constant deceleration: locate the stop crossing in the substep.
                    vc, vn, sc = v[cross], v_new[cross], s[cross]
                    frac = (vc * vc - v_stop * v_stop) / np.maximum(vc * vc - vn * vn, 1e-300)
                    is_first = ~self.stopped[cross]  # cars stopping for the first time this episode
                    first = cross[is_first]
                    x_start = x0[cross] + half_h * ssum[cross]
                    self.stop_distance[first] = (x_start + frac * (half_h * sc))[is_first]
                    tfrac = (vc - v_stop) / np.maximum(vc - vn, 1e-300)
                    self.stop_time[first] = ((self.t[cross] + (sub + tfrac) / c.substeps) * c.dt)[is_first]
                    self.stopped[cross] = True
                    d[cross] = vc * vc - v_stop * v_stop
                    st[cross] = frac * sc
                esum += d
                tsum += st
            ssum += s
            v, w = v_new, w_new
            v_above = new_above
            if check_switch:
                switch = np.flatnonzero(x0 + half_h * ssum >= self._next_change)
                if switch.size:
                    energy[switch] += esum[switch] * inv_2g_mu[switch]  # close the energy segment on road a
                    esum[switch] = 0.0
                    self.road[switch] = self.road_b[switch]
                    self._set_kernel_road(switch)
                    self.mu_peak[switch] = self.mu_peak_b[switch]
                    self.switched[switch] = True
                    self._next_change[switch] = np.inf
                    inv_2g_mu = 1.0 / (2.0 * p.g * self.mu_peak)
        esum *= inv_2g_mu
        energy += esum  # sum of (v^2 drop) / (2 g mu_peak) over substeps [m]
        travel = tsum * half_h  # distance travelled while above v_stop [m]
        x = ssum * half_h
        x += x0
        self.v, self.omega, self.x = v, w, x
        self.t += 1
        # Truth and lock detection.
        self.slip = qc.slip(v, w, p)
        self.mu = magic_formula(self.slip, kernel.B, kernel.C, kernel.E, kernel.theta)
        cond = (w * p.r < c.lock_speed_ratio * v) & (v > v_stop)
        self.lock_count = np.where(cond, self.lock_count + 1, 0)
        self.locked = self.lock_count > c.lock_steps
        self.lock_seen |= self.locked
        # Measurements.
        noise = self._take_noise()
        meas = self.meas
        meas[:, 0] = w + noise[:, 0]
        meas[:, 1] = (w_start - w) * (p.r / c.dt) + noise[:, 1]
        meas[:, 2] = (v - v_start) / c.dt + noise[:, 2]
        # Reward (see BrakingEnv docstring): braking efficiency per step, normalised by the limit distance.
        self.reward = (energy - travel) / self.limit - c.lock_penalty * self.locked
        self.terminated = self.stopped.copy()
        self.truncated = (self.t >= self._max_steps) & ~self.terminated
        return self.observe(), self.reward, self.terminated, self.truncated

    def _step_scalar(self, action) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`step` of one car in Python floats (``scalar=True``): the same model, statement by statement."""
        a = np.asarray(action, dtype=float)
        if a.shape not in ((1,), (1, 1)):
            raise ValueError(f"action must have shape (1,) (one command per car), got {a.shape}")
        a = float(a.flat[0])
        if not math.isfinite(a):
            raise ValueError(f"action contains NaN or inf: {[a]}")
        a = -1.0 if a < -1.0 else (1.0 if a > 1.0 else a)  # noqa: FURB136 (no builtin calls in the hot path)
        c, p, h = self.config, self._p, self._h
        v_stop, r, substeps, substep = c.v_stop, p.r, self._substeps, self._substep1
        if c.action_mode == "torque":
            Tb = (a + 1.0) * (0.5 * c.t_max)
        else:
            Tb = float(self.torque[0]) + a * (c.torque_rate_max * c.dt)
            Tb = 0.0 if Tb < 0.0 else (c.t_max if Tb > c.t_max else Tb)  # noqa: FURB136
        v = v_start = self.v.item(0)
        w = w_start = self.omega.item(0)
        x = self.x.item(0)
        road = self._road1
        energy = travel = 0.0
        stopped = self.stopped.item(0)
        change = math.inf if self.switched.item(0) else self.change_distance.item(0)
        inv_2g_mu = 1.0 / (2.0 * p.g * self.mu_peak.item(0))
        steps = self.t.item(0)
        half_h = 0.5 * h
        for sub in range(substeps):
            v_new, w_new = substep(v, w, Tb, road)
            dx = half_h * (v + v_new)
            if v > v_stop:
                if v_new <= v_stop:
                    frac = (v * v - v_stop * v_stop) / max(v * v - v_new * v_new, 1e-300)
                    if not stopped:
                        self.stop_distance[0] = x + frac * dx
                        tfrac = (v - v_stop) / max(v - v_new, 1e-300)
                        self.stop_time[0] = (steps + (sub + tfrac) / substeps) * c.dt
                    stopped = True
                    energy += (v * v - v_stop * v_stop) * inv_2g_mu
                    travel += frac * dx
                else:
                    energy += (v * v - v_new * v_new) * inv_2g_mu
                    travel += dx
            x = x + dx
            v, w = v_new, w_new
            if x >= change:
                self.road[0] = self.road_b[0]
                self._set_kernel_road([0])
                self.mu_peak[0] = self.mu_peak_b[0]
                self.switched[0] = True
                self._next_change[0] = change = math.inf
                road = self._road1
                inv_2g_mu = 1.0 / (2.0 * p.g * self.mu_peak.item(0))
        # State arrays are written in place (read-only by convention for callers, who copy what they keep).
        self.v[0], self.omega[0], self.x[0], self.torque[0] = v, w, x, Tb
        self.t[0] = steps = steps + 1
        self.stopped[0] = stopped
        # Truth and lock detection (quarter_car.slip and the Magic Formula, in floats).
        wr = w * r
        vw = v if v >= wr else wr  # noqa: FURB136
        slip = (v - wr) / (vw if vw > SLIP_SPEED_FLOOR else SLIP_SPEED_FLOOR)  # noqa: FURB136
        B, C, E, theta = self._mf1
        bs = B * slip
        self.slip[0] = slip
        self.mu[0] = theta * math.sin(C * math.atan(bs - E * (bs - math.atan(bs))))
        count = self.lock_count.item(0) + 1 if (wr < c.lock_speed_ratio * v and v > v_stop) else 0
        self.lock_count[0] = count
        locked = count > self._lock_steps
        self.locked[0] = locked
        if locked:
            self.lock_seen[0] = True
        # Measurements: the next noise row of the car's block.
        pos = self._noise_idx.item(0)
        noise, k = self._noise, pos * N_NOISE  # flat index of the row in car 0's block
        n0, n1, n2 = noise.item(k), noise.item(k + 1), noise.item(k + 2)
        pos += 1
        if pos >= NOISE_BLOCK:
            self._noise[0] = self.rngs[0].standard_normal((NOISE_BLOCK, N_NOISE))
            pos = 0
        self._noise_idx[0] = pos
        s0, s1, s2 = self._noise_sd
        meas = self.meas
        meas[0, 0] = m0 = w + n0 * s0
        meas[0, 1] = m1 = (w_start - w) * (r / c.dt) + n1 * s1
        meas[0, 2] = m2 = (v - v_start) / c.dt + n2 * s2
        self.reward[0] = (energy - travel) / self.limit.item(0) - c.lock_penalty * locked
        self.terminated[0] = stopped
        self.truncated[0] = steps >= self._max_steps and not stopped
        return self._observe_scalar(m0, m1, Tb, m2, v, slip, self.mu.item(0)), self.reward, self.terminated, \
            self.truncated

    def _observe_scalar(self, *vals: float) -> np.ndarray:
        """:meth:`observe` of the one car from Python floats (meas 0, meas 1, torque, meas 2, v, slip, mu)."""
        obs = self._obs
        for j, (scale, low, high) in enumerate(self._obs_consts):  # only the layout's entries
            val = vals[j] / scale
            obs[0, j] = low if val < low else (high if val > high else val)  # noqa: FURB136
        return obs

    # ------------------------------------------------------------------ observation
    def observe(self) -> np.ndarray:
        """Scaled, clipped float32 observation of every car, shape (n, obs_dim) (internal buffer)."""
        c = self.config
        if self.scalar:
            m0, m1, m2 = self.meas[0].tolist()
            return self._observe_scalar(m0, m1, self.torque.item(0), m2, self.v.item(0), self.slip.item(0),
                                        self.mu.item(0))
        buf = self._obs64
        buf[:, 0:2] = self.meas[:, 0:2]
        buf[:, 2] = self.torque
        buf[:, 3] = self.meas[:, 2]
        if c.observation == "oracle":
            buf[:, 4], buf[:, 5], buf[:, 6] = self.v, self.slip, self.mu
        buf /= self._scale_t  # one pass over (n, obs_dim): scale (torque by t_max), clip, cast to float32
        np.maximum(buf, self._low, out=buf)
        np.minimum(buf, self._high, out=buf)
        self._obs[...] = buf
        return self._obs

    def _observe_rows(self, idx: np.ndarray) -> np.ndarray:
        """:meth:`observe` for the cars ``idx`` only (the other rows are current already)."""
        meas = self.meas[idx]
        buf = np.empty((len(idx), len(self.layout)))
        buf[:, 0:2] = meas[:, 0:2]
        buf[:, 2] = self.torque[idx]
        buf[:, 3] = meas[:, 2]
        if self.config.observation == "oracle":
            buf[:, 4], buf[:, 5], buf[:, 6] = self.v[idx], self.slip[idx], self.mu[idx]
        buf /= self._scale_t
        np.maximum(buf, self._low, out=buf)
        np.minimum(buf, self._high, out=buf)
        self._obs[idx] = buf
        return self._obs

    @property
    def ratio(self) -> np.ndarray:
        """Stopping distance / physical-limit distance (NaN until a car stops)."""
        return self.stop_distance / self.limit

    def info_arrays(self) -> dict[str, Any]:
        """Per-step truth of every car as arrays (for a vector env's info dict); ``road`` is a list of names."""
        return {"v": self.v.copy(), "slip": self.slip.copy(), "mu": self.mu.copy(), "distance": self.x.copy(),
                "road": list(self.names), "torque": self.torque.copy(), "locked": self.locked.copy(),
                "time": self.t * self.config.dt}

    def car_info(self, i: int, final: bool = False) -> dict[str, Any]:
        """The info dict of car ``i``: truth every step, episode figures when ``final``."""
        info = {
            "v": self.v.item(i),
            "slip": self.slip.item(i),
            "mu": self.mu.item(i),
            "distance": self.x.item(i),
            "road": self.names[i],
            "torque": self.torque.item(i),
            "locked": self.locked.item(i),
            "time": self.t.item(i) * self.config.dt,
        }
        if final:
            info.update(self.final_info(i))
        return info

    def final_info(self, i: int) -> dict[str, Any]:
        """Episode figures of car ``i``: stopping distance, limit distance, ratio, whether it ever locked."""
        return {
            "stopping_distance": float(self.stop_distance[i]),
            "limit_distance": float(self.limit[i]),
            "ratio": float(self.stop_distance[i] / self.limit[i]),
            "lock_seen": bool(self.lock_seen[i]),
            "stopped": bool(self.stopped[i]),
            "v0": float(self.v0[i]),
        }

