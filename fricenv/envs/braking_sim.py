"""Batched braking simulation: ``n`` quarter cars stepped in one numpy call (no Gymnasium).

:class:`BrakingSim` is the whole of the ``fricenv/Braking-v0`` environment except the Gymnasium shell: the scenario
(road, friction change, initial speed) of :mod:`fricenv.envs.scenario`, and the episode (brake actuator, physics
substeps of a :class:`~fricenv.plants.braking_plant.BrakingPlant`, ECU measurement, wheel-lock detection, reward,
termination and truncation, episode figures) built from the functions of :mod:`fricenv.envs.episode`. Every
per-step quantity is an array over the ``n`` cars; the batched step has no Python loop over cars, so a vector env
can step 1024 cars at once, and :meth:`BrakingSim.reset_cars` resets any subset of cars (for per-env autoreset).

Randomness. Each car owns a ``numpy.random.Generator``. At reset the car's scenario draws (random road, initial
speed, change distance) come from it first, then the plant's per-episode draws (effect parameters of an
effect-randomised plant; none for the nominal plant), then its measurement noise (:class:`~fricenv.envs.episode.
NoiseBlocks`). A car therefore sees the same noise whether it is simulated alone or in a batch, and whatever the
other cars do.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from fricenv.envs.actions import check_action
from fricenv.envs.config import N_NOISE, BrakingConfig, observation_layout
from fricenv.envs.episode import (
    ACCOUNTING_ROWS,
    CAR_OUTPUTS,
    NoiseBlocks,
    brake_torque,
    car_substeps_compiled,
    cars_accounting,
    cars_substeps_compiled,
    clip_float,
    lock_count,
    measure,
    start_accounting,
    step_reward,
)
from fricenv.envs.scenario import RESET_OPTION_KEYS, V0_DEFAULT, Scenario, episode_limits, resolve_scenario
from fricenv.plants.braking_plant import BatchPlant, BrakingPlant
from fricenv.plants.tire import MagicFormula

__all__ = ["BrakingSim"]


class BrakingSim:
    """``n`` quarter cars braking, each with its own scenario, noise generator and episode clock.

    Typical use::

        sim = BrakingSim(n, BrakingConfig(), road="dry", v0=20.0)
        sim.reset_cars(None, [np.random.default_rng(s) for s in seeds])
        obs, reward, terminated, truncated = sim.step(actions)   # actions: (n,) in [-1, 1]

    Arrays returned by :meth:`observe` and :meth:`step` are internal buffers, valid until the next call: copy
    them to keep them.

    Plant. By default the nominal quarter car, :class:`~fricenv.plants.braking_plant.BatchPlant` (the ROS2 substep
    of :mod:`fricenv.plants.rosenbrock`, compiled): the substeps of a control step of every car, with their
    accounting (distance, stop, friction change, braking energy), run in one compiled call
    (:func:`fricenv.envs.episode.cars_substeps_compiled`), the rest of the step on arrays. With ``scalar=True``
    (one nominal car) that car's substeps run in one compiled call
    (:func:`fricenv.envs.episode.car_substeps_compiled`, the same arithmetic) and the rest of the step in Python
    floats, several times faster for one car than numpy on 1-element arrays (``BrakingEnv`` uses it). ``plant=``
    takes any other :class:`~fricenv.plants.braking_plant.BrakingPlant`, e.g.
    :class:`fricenv.envs.effect_plant.EffectPlant` (the quarter car with unmodelled effects): its cars advance one
    :meth:`~fricenv.plants.braking_plant.BrakingPlant.substep` at a time, each substep's accounting in one compiled
    call (:func:`fricenv.envs.episode.cars_accounting`, the nominal cars' own). Per-car state (``v``, ``omega``, ``slip``, ``mu``,
    ``x``, ``t``, ``torque``, ``locked``, ``lock_seen``, ``stop_distance``, ``limit``, ...) is public, read-only by
    convention.

    :param n: number of cars.
    :param config: constants shared by all cars.
    :param road: default road spec for every car (see :func:`resolve_scenario`), overridable per reset.
    :param v0: default initial speed [m/s] or (low, high) range.
    :param change_distance: default friction-change distance [m] or range; None: 15 m (random-change: 5..30 m).
    :param scalar: step the single car in floats (requires ``n == 1`` and no ``plant``).
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
        self._compiled = plant is None and not self.scalar  # the nominal cars: one compiled call per control step
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
        self._road_rows: dict[MagicFormula, tuple[float, ...]] = {}  # (B, C, E, theta, mu(1)) per road
        self._substeps, self._max_steps, self._lock_steps = c.substeps, c.max_steps, c.lock_steps
        # Observation scales with the torque entry's times t_max (the value scaled is T_b itself); scalar path:
        # (scale, low, high) per entry; noise standard deviations.
        torque_scale = np.ones(len(self.layout))
        torque_scale[2] = c.t_max
        self._scale_t = self._scale * torque_scale
        # the batched observation is scaled with one row per entry (contiguous rows over the cars), then transposed
        self._obs_rows = np.zeros((len(self.layout), self.n))
        self._scale_col, self._low_col, self._high_col = self._scale_t[:, None], self._low[:, None], self._high[:, None]
        self._obs_consts = tuple(zip(self._scale_t.tolist(), self._low.tolist(), self._high.tolist()))
        n = self.n
        z = lambda: np.zeros(n)
        # Physical state and scenario, per car.
        self.v, self.omega, self.x, self.torque = z(), z(), z(), z()
        self.t = np.zeros(n, dtype=np.int64)  # control steps since reset
        self.road_a, self.road_b = np.zeros((n, 4)), np.zeros((n, 4))
        self.road = np.zeros((n, 4))  # road in use
        # (B, C, E, theta, mu(1)) of the road in use and of the road after the change point, and 1 / (2 g mu_max)
        # of each: the compiled substeps' roads
        self._roads, self._inv_2g_mu_ab = np.zeros((n, 2, 5)), np.zeros((n, 2))
        self._car_roads = self._roads[0]  # the one car's (scalar path)
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
        self.noise = NoiseBlocks(n, self._noise_std)
        self.rngs = self.noise.rngs  # each car's generator
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
        self._draw_scenarios(idx, rngs, per_car)
        self._start_episodes(idx)
        if self.scalar or len(idx) == self.n:
            return self.observe()
        return self._observe_rows(idx)

    def _draw_scenarios(self, idx: np.ndarray, rngs, per_car: list) -> None:
        """Each reset car's generator, scenario, plant draws and noise block, in that order (see the module
        docstring), and the per-car scenario arrays."""
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
            rng = rngs[k] if rngs is not None else self.rngs[i]
            rng = np.random.default_rng() if rng is None else rng
            self.rngs[i] = rng
            sc = resolve_scenario(spec["road"], spec["v0"], spec["change_distance"], self.config.v_stop, rng)
            self.scenarios[i] = sc
            self.names[i] = sc.name
            self.plant.new_episode(int(i), rng)
            rows.append((*self._road_constants(sc.road_a), *self._road_constants(sc.road_b), sc.road_a.mu_max,
                         sc.road_b.mu_max, sc.change_distance, sc.v0))
            self.noise.start(int(i), rng)
        if rows:  # one write per array instead of one per car
            table = np.array(rows, dtype=float)
            self._roads[idx, 0], self._roads[idx, 1] = table[:, 0:5], table[:, 5:10]
            self.road_a[idx], self.road_b[idx] = table[:, 0:4], table[:, 5:9]
            self.mu_peak_a[idx], self.mu_peak_b[idx] = table[:, 10], table[:, 11]
            self.change_distance[idx], self.v0[idx] = table[:, 12], table[:, 13]

    def _start_episodes(self, idx: np.ndarray) -> None:
        """Cars ``idx`` at the start of their drawn scenario: free rolling at ``v0``, clocks and figures cleared,
        the first measurement taken."""
        c = self.config
        self.limit[idx] = episode_limits(self.plant, idx, self.v0[idx], c.v_stop, self.road_a[idx], self.road_b[idx],
                                         self.mu_peak_a[idx], self.mu_peak_b[idx], self.change_distance[idx], self._p)
        self.road[idx] = self.road_a[idx]
        self._set_plant_road(idx)
        self.mu_peak[idx] = self.mu_peak_a[idx]
        self._inv_2g_mu_ab[idx, 0] = 1.0 / (2.0 * self._p.g * self.mu_peak_a[idx])
        self._inv_2g_mu_ab[idx, 1] = 1.0 / (2.0 * self._p.g * self.mu_peak_b[idx])
        self.switched[idx] = False
        self._next_change[idx] = self.change_distance[idx]
        self.v[idx] = self.v0[idx]
        self.omega[idx] = self.v0[idx] / self.plant.r_eff[idx]  # free rolling
        self.plant.reset(idx, self.v[idx], self.omega[idx])
        for name in ("x", "torque", "slip", "mu", "reward"):
            getattr(self, name)[idx] = 0.0
        for name in ("t", "lock_count", "locked", "lock_seen", "stopped", "terminated", "truncated"):
            getattr(self, name)[idx] = 0
        self.stop_distance[idx] = np.nan
        self.stop_time[idx] = np.nan
        if self.scalar:
            self._inv_2g_mu = tuple(self._inv_2g_mu_ab[0].tolist())
        noise = self.noise.take(idx)
        w, v = self.omega[idx], self.v[idx]  # at rest in the ECU's view: no previous sample, no decelerations
        for j, m in enumerate(measure(w, w, v, v, noise[0], noise[1], noise[2], self._p.r, c.dt)):
            self.meas[idx, j] = m

    def _make_plant(self, plant: BrakingPlant | None) -> BrakingPlant:
        """The given plant (checked), or the nominal one (:class:`BatchPlant`)."""
        if plant is None:
            return BatchPlant(self.n, self._h, self._p)
        if not isinstance(plant, BrakingPlant):
            raise TypeError(f"plant must implement fricenv.plants.braking_plant.BrakingPlant, got "
                            f"{type(plant).__name__}")
        if plant.n != self.n or abs(plant.h - self._h) > 1e-12 * self._h:
            raise ValueError(f"plant has n={plant.n}, h={plant.h}; this sim needs n={self.n}, h={self._h}")
        return plant

    def _set_plant_road(self, idx) -> None:
        """The plant's road of cars ``idx``: the road in use (the nominal plant takes the compiled substeps' rows)."""
        if self.scalar or self._compiled:
            self.plant.set_road_constants(idx, self._roads[idx, 0])
        else:
            self.plant.set_road(idx, self.road[idx])

    def _road_constants(self, road: MagicFormula) -> tuple[float, ...]:
        """(B, C, E, theta, mu(1)) of a road as floats, cached per road (the compiled substeps' road)."""
        row = self._road_rows.get(road)
        if row is None:
            row = self._road_rows[road] = (*road.as_array().tolist(), float(road.mu_locked))
        return row

    # ------------------------------------------------------------------ step
    def step(self, action, resetting=None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Advance every car by one control step.

        :param action: normalized commands, shape (n,) (or (n, 1)); NaN, inf, a wrong shape or a non-numeric
            action raise ValueError (:func:`fricenv.envs.actions.check_action`), values outside [-1, 1] are
            clipped.
        :param resetting: cars (indices or mask) that the caller resets right after this step and whose results
            it discards (a vector env's next-step autoreset). They are advanced like the others, but draw nothing
            from their generators, so their next episode is the one a single env would draw.
        :return: (observation (n, obs_dim) float32, reward (n,), terminated (n,), truncated (n,)) buffers.
        """
        return self.advance(check_action(action, (self.n,), "(one command per car)", column=True), resetting)

    def advance(self, action: np.ndarray, resetting=None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`step` with an action the caller checked already (:func:`~fricenv.envs.actions.check_action`'s
        result, shape (n,)): the one check of an env's step is its own."""
        if resetting is not None:
            # Rewind their noise cursor: no block refill (a generator draw) can happen in this step, and the
            # reset redraws the block anyway.
            self.noise.pos[_as_index_array(resetting, self.n)] = 0
        if self.scalar:
            return self._step_scalar(float(action.item(0)))
        action = np.clip(np.asarray(action, dtype=float), -1.0, 1.0)
        return self._step_compiled(action) if self._compiled else self._step_plant(action)

    def _step_compiled(self, action) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`step` of ``n`` nominal cars: the substeps and their accounting of every car in one compiled call
        (:func:`~fricenv.envs.episode.cars_substeps_compiled`), the rest on arrays (``action`` checked, clipped)."""
        c, p, plant = self.config, self._p, self.plant
        self.torque = brake_torque(action, self.torque, c)
        v_start, w_start, stopped_before = self.v, self.omega, self.stopped
        out = np.empty((len(CAR_OUTPUTS), self.n))  # rows of CAR_OUTPUTS; the new state arrays are its rows
        cars_substeps_compiled(v_start, w_start, self.x, self.torque, self._roads, self._next_change, stopped_before,
                               self._inv_2g_mu_ab, self._substeps, self._h, c.v_stop, p.r, p.m, p.J, p.Fz, out)
        self.v, self.omega, self.slip, self.mu = out[0], out[1], out[9], out[10]
        energy, travel = self._close_accounting(out[2:9], stopped_before)
        switch = np.flatnonzero(out[8])
        if switch.size:
            self._switch_road(switch)
        np.copyto(plant.v, self.v)
        np.copyto(plant.omega, self.omega)
        self.t += 1
        return self._finish_step(v_start, w_start, energy, travel)

    def _step_plant(self, action) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`step` of ``n`` cars of any plant (``action`` checked, clipped): the plant advanced one substep at a
        time, each substep's accounting in one compiled call (:func:`~fricenv.envs.episode.cars_accounting`); a car
        passing its change point drives on road b from the next substep."""
        c, plant = self.config, self.plant
        self.torque = brake_torque(action, self.torque, c)
        plant.set_torque(self.torque)
        v_start, w_start, stopped_before = self.v, self.omega, self.stopped
        acc = np.empty((len(ACCOUNTING_ROWS), self.n))
        start_accounting(self.x, stopped_before, acc)
        v = v_start
        for sub in range(self._substeps):
            v_new = plant.substep()[0]
            cars_accounting(sub, v, v_new, acc, self._next_change, self._h, c.v_stop, self._inv_2g_mu_ab)
            switch = np.flatnonzero((acc[6] != 0.0) & ~self.switched)
            if switch.size:
                self._switch_road(switch)
            v = v_new
        self.v, self.omega = plant.v.copy(), plant.omega.copy()
        self.slip = plant.slip()
        self.mu = plant.friction(self.slip)
        energy, travel = self._close_accounting(acc, stopped_before)
        self.t += 1
        return self._finish_step(v_start, w_start, energy, travel)

    def _close_accounting(self, acc, stopped_before) -> tuple[np.ndarray, np.ndarray]:
        """Take a control step's accounting (:data:`~fricenv.envs.episode.ACCOUNTING_ROWS`): distance, stop flag, the
        first stop of the episode located inside its substep; return (energy, travel) [m] per car."""
        self.x, energy, travel, stopped, stop_x, stop_sub = acc[0], acc[1], acc[2], acc[3], acc[4], acc[5]
        self.stopped = stopped != 0.0
        first = np.flatnonzero(self.stopped & ~stopped_before)  # the first stop of the episode, in this step
        if first.size:
            self.stop_distance[first] = stop_x[first]
            self.stop_time[first] = (self.t[first] + stop_sub[first] / self._substeps) * self.config.dt
        return energy, travel

    def _finish_step(self, v_start, w_start, energy, travel) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The rest of a batched step after the substeps: wheel lock, measurement, reward, episode end."""
        c, p, v, w = self.config, self._p, self.v, self.omega
        self.lock_count = lock_count(self.lock_count, w, v, self.plant.r_eff, c)
        self.locked = self.lock_count > c.lock_steps
        self.lock_seen |= self.locked
        noise = self.noise.take()
        self.meas[:, 0], self.meas[:, 1], self.meas[:, 2] = measure(
            w, w_start, v, v_start, noise[0], noise[1], noise[2], p.r, c.dt)
        self.reward = step_reward(energy, travel, self.limit, self.locked, c.lock_penalty)
        self.terminated = self.stopped.copy()
        self.truncated = (self.t >= self._max_steps) & ~self.terminated
        return self.observe(), self.reward, self.terminated, self.truncated

    def _switch_road(self, idx) -> None:
        """Cars ``idx`` pass their friction-change point: road b from now on."""
        self.road[idx] = self.road_b[idx]
        self._roads[idx, 0] = self._roads[idx, 1]
        self._inv_2g_mu_ab[idx, 0] = self._inv_2g_mu_ab[idx, 1]
        if self.scalar:
            self._inv_2g_mu = (self._inv_2g_mu[1], self._inv_2g_mu[1])
        self._set_plant_road(idx)
        self.mu_peak[idx] = self.mu_peak_b[idx]
        self.switched[idx] = True
        self._next_change[idx] = np.inf

    def _step_scalar(self, a: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`step` of the one nominal car: its substeps in one compiled call, the rest in floats."""
        c, p, plant = self.config, self._p, self.plant
        Tb = brake_torque(clip_float(a, -1.0, 1.0), self.torque.item(0), c, clip_float)
        v_start, w_start = self.v.item(0), self.omega.item(0)
        stopped_before = self.stopped.item(0)
        inv_a, inv_b = self._inv_2g_mu
        v, w, x, energy, travel, stopped, stop_x, stop_sub, switched, slip, mu = car_substeps_compiled(
            v_start, w_start, self.x.item(0), Tb, self._car_roads, self._next_change.item(0), stopped_before,
            self._substeps, self._h, c.v_stop, inv_a, inv_b, p.r, p.m, p.J, p.Fz)
        plant.v[0], plant.omega[0] = v, w
        if switched:
            self._switch_road([0])
        if stopped and not stopped_before:  # the first stop of the episode, in this step
            self.stop_distance[0] = stop_x
            self.stop_time[0] = (self.t.item(0) + stop_sub / self._substeps) * c.dt
        self.v[0], self.omega[0], self.torque[0], self.x[0], self.stopped[0] = v, w, Tb, x, stopped
        self.t[0] = steps = self.t.item(0) + 1
        self.slip[0], self.mu[0] = slip, mu
        count = lock_count(self.lock_count.item(0), w, v, plant.r_eff.item(0), c)
        self.lock_count[0] = count
        locked = count > self._lock_steps
        self.locked[0] = locked
        if locked:
            self.lock_seen[0] = True
        n0, n1, n2 = self.noise.take_one()
        m0, m1, m2 = measure(w, w_start, v, v_start, n0, n1, n2, p.r, c.dt)
        self.meas[0, 0], self.meas[0, 1], self.meas[0, 2] = m0, m1, m2
        self.reward[0] = step_reward(energy, travel, self.limit.item(0), locked, c.lock_penalty)
        self.terminated[0] = stopped
        self.truncated[0] = steps >= self._max_steps and not stopped
        return self._observe_scalar(m0, m1, Tb, m2, v, slip, mu), self.reward, self.terminated, self.truncated

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
        if self.scalar:
            m0, m1, m2 = self.meas[0].tolist()
            return self._observe_scalar(m0, m1, self.torque.item(0), m2, self.v.item(0), self.slip.item(0),
                                        self.mu.item(0))
        self._obs[...] = self._scaled_rows(self._obs_rows, self.meas, self.torque, self.v, self.slip, self.mu).T
        return self._obs

    def _observe_rows(self, idx: np.ndarray) -> np.ndarray:
        """:meth:`observe` for the cars ``idx`` only (the other rows are current already)."""
        buf = np.empty((len(self.layout), len(idx)))
        self._obs[idx] = self._scaled_rows(buf, self.meas[idx], self.torque[idx], self.v[idx], self.slip[idx],
                                           self.mu[idx]).T
        return self._obs

    def _scaled_rows(self, buf: np.ndarray, meas, torque, v, slip, mu) -> np.ndarray:
        """``buf`` (obs_dim, k) filled with the observation entries of k cars, one row per entry, scaled (the torque
        by t_max) and clipped."""
        buf[0], buf[1], buf[2], buf[3] = meas[:, 0], meas[:, 1], torque, meas[:, 2]
        if self.config.observation == "oracle":
            buf[4], buf[5], buf[6] = v, slip, mu
        buf /= self._scale_col
        np.maximum(buf, self._low_col, out=buf)
        np.minimum(buf, self._high_col, out=buf)
        return buf

    @property
    def ratio(self) -> np.ndarray:
        """Stopping distance / physical-limit distance (NaN until a car stops)."""
        return self.stop_distance / self.limit

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
