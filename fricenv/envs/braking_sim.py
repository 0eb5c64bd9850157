"""Batched braking simulation: ``n`` quarter cars stepped in one numpy call (no Gymnasium).

:class:`BrakingSim` is the whole of the ``fricenv/Braking-v0`` environment except the Gymnasium shell: scenario
(road, friction change, initial speed) from :mod:`fricenv.envs.braking_core`, and the episode of
:mod:`fricenv.envs.episode` (brake actuator, physics substeps of a :class:`~fricenv.plants.braking_plant.
BrakingPlant`, ECU measurement, wheel-lock detection, reward, termination and truncation, episode figures). Every
per-step quantity is an array over the ``n`` cars; the batched step has no Python loop over cars, so a vector env
can step 1024 cars at once, and :meth:`BrakingSim.reset_cars` resets any subset of cars (for per-env autoreset).

Randomness. Each car owns a ``numpy.random.Generator``. At reset the car's scenario draws (random road, initial
speed, change distance) come from it first, then the plant's per-episode draws (effect parameters of an
effect-randomised plant; none for the nominal plant), then its measurement noise is drawn from it in blocks of
:data:`~fricenv.envs.braking_core.NOISE_BLOCK` control steps (standard normals, one column per noisy channel) and
consumed by index. A car therefore sees the same noise whether it is simulated alone or in a batch, and whatever
the other cars do.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from fricenv.envs.braking_core import (
    N_NOISE,
    NOISE_BLOCK,
    REACH_SPEED_SLACK,
    RESET_OPTION_KEYS,
    V0_DEFAULT,
    BrakingConfig,
    Scenario,
    _as_index_array,
    limit_distance,
    observation_layout,
    resolve_scenario,
)
from fricenv.envs.episode import EpisodeSteps, brake_torque, measure
from fricenv.plants.braking_plant import BatchPlant, BrakingPlant, ScalarPlant
from fricenv.plants.tire import MagicFormula

__all__ = ["BrakingSim"]


class BrakingSim(EpisodeSteps):
    """``n`` quarter cars braking, each with its own scenario, noise generator and episode clock.

    Typical use::

        sim = BrakingSim(n, BrakingConfig(), road="dry", v0=20.0)
        sim.reset_cars(None, [np.random.default_rng(s) for s in seeds])
        obs, reward, terminated, truncated = sim.step(actions)   # actions: (n,) in [-1, 1]

    Arrays returned by :meth:`observe` and :meth:`step` are internal buffers, valid until the next call: copy
    them to keep them.

    Plant. By default the nominal quarter car: :class:`~fricenv.plants.braking_plant.BatchPlant` (the ROS2
    substep of :func:`fricenv.plants.quarter_car.step` with shared subexpressions, equal to it to 1e-12), or with
    ``scalar=True`` (one car only) :class:`~fricenv.plants.braking_plant.ScalarPlant`, every step in Python floats,
    several times faster for one car than numpy on 1-element arrays and equal to the batched path to about 1e-12
    (``BrakingEnv`` uses it). ``plant=`` takes any other :class:`~fricenv.plants.braking_plant.BrakingPlant`, e.g.
    :class:`fricenv.envs.effect_plant.EffectPlant` (the quarter car with unmodelled effects). Per-car state
    (``v``, ``omega``, ``slip``, ``mu``, ``x``, ``t``, ``torque``, ``locked``, ``lock_seen``, ``stop_distance``,
    ``limit``, ...) is public, read-only by convention.

    :param n: number of cars.
    :param config: constants shared by all cars.
    :param road: default road spec for every car (see :func:`resolve_scenario`), overridable per reset.
    :param v0: default initial speed [m/s] or (low, high) range.
    :param change_distance: default friction-change distance [m] or range; None: 15 m (random-change: 5..30 m).
    :param scalar: step the single car in Python floats (requires ``n == 1`` and no ``plant``).
    :param plant: the plant of the ``n`` cars (default: the nominal one).
    """

    def __init__(self, n: int, config: BrakingConfig | None = None, *, road: str | MagicFormula = "dry",
                 v0=V0_DEFAULT, change_distance=None, scalar: bool = False, plant: BrakingPlant | None = None):
        if not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n must be an int >= 1, got {n!r}")
        if scalar and (n != 1 or plant is not None):
            raise ValueError(f"scalar=True steps one nominal car in Python floats; it needs n == 1 and no plant, "
                             f"got n={n}, plant={type(plant).__name__}")
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
        self.plant = self._make_plant(plant)
        self._road_rows: dict[MagicFormula, tuple[float, float, float, float]] = {}
        self._reach_slack = REACH_SPEED_SLACK
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
            self.plant.new_episode(int(i), rng)
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
        self.plant.set_road(idx, self.road[idx])
        self.mu_peak[idx] = self.mu_peak_a[idx]
        self.switched[idx] = False
        self._next_change[idx] = self.change_distance[idx]
        self.v[idx] = self.v0[idx]
        self.omega[idx] = self.v0[idx] / self.plant.r_eff[idx]  # free rolling
        self.plant.reset(idx, self.v[idx], self.omega[idx])
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
        w, v = self.omega[idx], self.v[idx]  # at rest in the ECU's view: no previous sample, no decelerations
        for j, m in enumerate(measure(w, w, v, v, noise[:, 0], noise[:, 1], noise[:, 2], self._p.r, c.dt)):
            self.meas[idx, j] = m
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
                    self._refill_noise(i)
                    pos[i] = 0
            return out
        pos = self._noise_idx[idx]
        out = self._noise[idx, pos] * self._noise_std
        pos += 1
        self._noise_idx[idx] = pos
        full = pos >= NOISE_BLOCK
        if full.any():
            for i in idx[full]:  # once every NOISE_BLOCK steps per car
                self._refill_noise(i)
                self._noise_idx[i] = 0
        return out

    def _refill_noise(self, i: int) -> None:
        """A new block of standard normals for car ``i`` from its generator."""
        self._noise[i] = self.rngs[i].standard_normal((NOISE_BLOCK, N_NOISE))

    def _make_plant(self, plant: BrakingPlant | None) -> BrakingPlant:
        """The given plant (checked), or the nominal one: :class:`ScalarPlant` if scalar, else :class:`BatchPlant`."""
        if plant is None:
            return ScalarPlant(self._h, self._p) if self.scalar else BatchPlant(self.n, self._h, self._p)
        if not isinstance(plant, BrakingPlant):
            raise TypeError(f"plant must implement fricenv.plants.braking_plant.BrakingPlant, got "
                            f"{type(plant).__name__}")
        if plant.n != self.n or abs(plant.h - self._h) > 1e-12 * self._h:
            raise ValueError(f"plant has n={plant.n}, h={plant.h}; this sim needs n={self.n}, h={self._h}")
        return plant

    def _road_row(self, road: MagicFormula) -> tuple[float, float, float, float]:
        """(B, C, E, theta) of a road as floats, cached per road."""
        row = self._road_rows.get(road)
        if row is None:
            row = self._road_rows[road] = tuple(road.as_array().tolist())
        return row


    # ------------------------------------------------------------------ step
    def command_to_torque(self, action: np.ndarray) -> np.ndarray:
        """Brake torque [N m] after applying the (already clipped) normalized commands."""
        return brake_torque(action, self.torque, self.config)

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
        return self._step_scalar(action) if self.scalar else self._step_batch(action)

    def accel(self) -> np.ndarray:
        """True longitudinal acceleration [m/s^2] of every car now (the plant's, as an accelerometer reads it)."""
        return np.atleast_1d(np.asarray(self.plant.accel(), dtype=float))

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
        """Episode figures of car ``i``: stopping distance, limit distance, ratio, whether it ever locked.

        ``stopping_distance`` and ``ratio`` are None for a car that has not stopped (a truncated episode), so the
        final info holds no NaN (Gymnasium's ``data_equivalence`` treats NaN as unequal to itself).
        """
        stopped = bool(self.stopped[i])
        return {
            "stopping_distance": float(self.stop_distance[i]) if stopped else None,
            "limit_distance": float(self.limit[i]),
            "ratio": float(self.stop_distance[i] / self.limit[i]) if stopped else None,
            "lock_seen": bool(self.lock_seen[i]),
            "stopped": stopped,
            "v0": float(self.v0[i]),
        }

