"""Native vector env for ``fricenv/Braking-v0``: all sub-envs step in one batched plant call.

``gymnasium.make_vec("fricenv/Braking-v0", num_envs=N, vectorization_mode="vector_entry_point")`` builds a
:class:`BrakingVectorEnv`: one :class:`fricenv.envs.braking_sim.BrakingSim` over ``N`` quarter cars instead of ``N``
Python env objects, so a step costs one set of numpy calls over ``N`` cars.

Equivalence with single envs. Sub-env ``i`` is the same process as a single ``BrakingEnv`` with the same arguments:
``reset(seed=s)`` seeds sub-env ``i`` with ``s + i`` (a list gives one seed per sub-env, as in
:class:`gymnasium.vector.SyncVectorEnv`), each sub-env owns its generator (scenario draws, then its measurement
noise), and an autoreset draws the next episode from that same generator, exactly as ``env.reset()`` without a seed
does on a single env. So ``make_vec(..., num_envs=N)`` reset with seed ``s`` produces the trajectories of ``N``
single envs reset with seeds ``s, s+1, ...`` and reset without a seed at every episode end (tested to 1e-9).

Autoreset (Gymnasium 1.x, https://farama.org/Vector-Autoreset-Mode), chosen with ``autoreset_mode=``:

=========================  ==========================================================================================
mode                       behaviour
=========================  ==========================================================================================
``NEXT_STEP`` (default)    the step that ends an episode returns its last observation, reward and
                           ``terminated``/``truncated``; the *next* ``step`` ignores that sub-env's action, resets it
                           and returns its first observation with reward 0 and ``terminated = truncated = False``
                           (Gymnasium's default, as ``SyncVectorEnv``).
``SAME_STEP``              the step that ends an episode resets the sub-env at once: it returns the new episode's
                           first observation, the last one in ``info["final_obs"]`` and the episode's info in
                           ``info["final_info"]`` (what SB3's ``VecEnv`` convention needs; used by
                           :mod:`fricenv.envs.sb3_vec`).
``DISABLED``               no autoreset; reset finished sub-envs with ``reset(options={"reset_mask": mask})``.
=========================  ==========================================================================================

Info (Gymnasium's dict of arrays, each key ``k`` with a boolean mask ``_k``): every step and reset carries, for
all sub-envs, ``v``, ``slip``, ``mu``, ``distance``, ``road`` (object array of names), ``torque``, ``locked``,
``time``; when a sub-env's episode ends it also carries ``stopping_distance``, ``limit_distance``, ``ratio``,
``lock_seen``, ``stopped`` and ``v0`` (masked to the sub-envs that ended), the keys of the single env's info;
``stopping_distance`` and ``ratio`` are masked to the sub-envs that stopped (a truncated one has them left out,
where a single env has None: no NaN in any info).

Per-env roads: ``road`` may be one road spec for all sub-envs or a sequence of ``num_envs`` specs (names or
:class:`~fricenv.plants.tire.MagicFormula`); ``reset(options={"road": [...]})`` does the same for one reset.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from fricenv.envs import config as cfg
from fricenv.envs.braking_sim import BrakingSim
from fricenv.envs.effect_plant import effect_plant_or_none
from fricenv.envs.scenario import RESET_OPTION_KEYS, V0_DEFAULT, resolve_scenario
from fricenv.plants.tire import MagicFormula

__all__ = ["CONFIG_KWARGS", "FINAL_INFO_KEYS", "STEP_INFO_KEYS", "BrakingVectorEnv"]

# Keyword arguments that go to BrakingConfig (the same names as BrakingEnv's); dt is fixed by the env.
CONFIG_KWARGS = tuple(f.name for f in dataclasses.fields(cfg.BrakingConfig) if f.name != "dt")
STEP_INFO_KEYS = ("v", "slip", "mu", "distance", "road", "torque", "locked", "time")
FINAL_INFO_KEYS = ("stopping_distance", "limit_distance", "ratio", "lock_seen", "stopped", "v0")
STOP_KEYS = ("stopping_distance", "ratio")  # present (mask True) only for sub-envs that stopped
RESET_MASK_KEY = "reset_mask"


def _is_per_env(spec: Any) -> bool:
    """Whether a road spec is a per-env sequence (a list/tuple of names or MagicFormulas) rather than one spec."""
    return isinstance(spec, (list, tuple)) and not isinstance(spec, MagicFormula)


class BrakingVectorEnv(VectorEnv):
    """``num_envs`` Braking-v0 sub-envs stepped together (see the module docstring for autoreset and info).

    :param num_envs: number of sub-envs.
    :param road: road spec for all sub-envs, or a sequence of ``num_envs`` specs (see ``BrakingEnv``).
    :param v0: initial speed [m/s] or (low, high) range, for all sub-envs.
    :param change_distance: friction-change distance [m] or range, for all sub-envs.
    :param autoreset_mode: an :class:`gymnasium.vector.AutoresetMode` or its value (``"NextStep"``,
        ``"SameStep"``, ``"Disabled"``).
    :param max_episode_steps: optional truncation in control steps (the shorter of it and ``time_limit`` holds, as
        for a single env in ``gym.make``'s ``TimeLimit``); passed by ``make_vec`` from the registration.
    :param render_mode: only None (the vector env does not render; use single envs for videos).
    :param effects: effects of every sub-env's plant (see ``BrakingEnv``; None or [] is the plain env).
    :param effects_randomization: per-episode effect parameter ranges, drawn from each sub-env's generator.
    :param scenarios: optional per-episode scenario draw ``rng -> reset options`` (e.g. the training mix
        :class:`agents.training.ScenarioSampler`), called at every reset of a sub-env with that sub-env's own
        scenario generator (seeded with the sub-env's seed); explicit reset options win over its draw. It is
        what :class:`gymnasium.Wrapper` ``ScenarioMix`` does to a single env, with the same draws.
    :param config_kwargs: ``BrakingConfig`` fields, the same keyword arguments as ``BrakingEnv``
        (``action_mode``, ``observation``, ``t_max``, ``physics_dt``, ...).
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, *, road: str | MagicFormula | Sequence = "dry",
                 v0: float | tuple[float, float] = V0_DEFAULT,
                 change_distance: float | tuple[float, float] | None = None,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
                 max_episode_steps: int | None = None, render_mode: str | None = None, effects: Any = None,
                 effects_randomization: dict[str, Any] | None = None,
                 scenarios: Callable[[np.random.Generator], dict[str, Any]] | None = None, **config_kwargs):
        if not isinstance(num_envs, (int, np.integer)) or isinstance(num_envs, bool) or num_envs < 1:
            raise ValueError(f"num_envs must be an int >= 1, got {num_envs!r}")
        unknown = sorted(set(config_kwargs) - set(CONFIG_KWARGS))
        if unknown:
            raise TypeError(f"unknown argument(s) {unknown} for BrakingVectorEnv; valid: "
                            f"num_envs, road, v0, change_distance, autoreset_mode, max_episode_steps, "
                            f"render_mode, effects, effects_randomization, scenarios, {', '.join(CONFIG_KWARGS)}")
        if render_mode is not None:
            raise ValueError(f"BrakingVectorEnv does not render (render_mode must be None, got {render_mode!r}); "
                             f"use single envs with render_mode='rgb_array'")
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise ValueError(f"unknown autoreset_mode {autoreset_mode!r}; valid: "
                             f"{', '.join(m.value for m in AutoresetMode)}") from None
        if max_episode_steps is not None:
            if not isinstance(max_episode_steps, (int, np.integer)) or max_episode_steps < 1:
                raise ValueError(f"max_episode_steps must be an int >= 1 or None, got {max_episode_steps!r}")
            # The registration's limit (6000 steps = the default 60 s) never lengthens a shorter time_limit.
            limit = int(max_episode_steps) * cfg.CONTROL_DT
            config_kwargs["time_limit"] = min(config_kwargs.get("time_limit", limit), limit)
        self.num_envs = n = int(num_envs)
        self.config = cfg.BrakingConfig(**config_kwargs)
        self._env_roads = self._per_env_roads(road, "road")
        first_road = self._env_roads[0] if self._env_roads is not None else road
        plant = effect_plant_or_none(n, self.config, effects, effects_randomization)
        self.sim = BrakingSim(n, self.config, road=first_road, v0=v0, change_distance=change_distance,
                                   scalar=n == 1 and plant is None, plant=plant)  # one car: the Python-float path
        if self._env_roads is not None:  # validate every per-env road now, not at the first reset
            for spec in self._env_roads:
                resolve_scenario(spec, v0, change_distance, self.config.v_stop, np.random.default_rng(0))
        self.render_mode = None
        self.metadata = {**type(self).metadata, "autoreset_mode": self.autoreset_mode}
        self.dt = self.config.dt
        self.observation_fields = self.sim.layout
        self.single_action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.single_observation_space = spaces.Box(
            low=np.array([f.low for f in self.observation_fields], dtype=np.float32),
            high=np.array([f.high for f in self.observation_fields], dtype=np.float32),
            dtype=np.float32,
        )
        self.action_space = batch_space(self.single_action_space, n)
        self.observation_space = batch_space(self.single_observation_space, n)
        self._autoreset = np.zeros(n, dtype=bool)
        self._road_names = np.full(n, "", dtype=object)
        self._was_reset = False
        if scenarios is not None and not callable(scenarios):
            raise TypeError(f"scenarios must be callable rng -> reset options, got {type(scenarios).__name__}")
        self.scenarios = scenarios
        self._scenario_rngs = [np.random.default_rng() for _ in range(n)]

    # ------------------------------------------------------------------ helpers
    def _per_env_roads(self, road: Any, name: str) -> list | None:
        """A per-env road list checked for length, or None when ``road`` is one spec for all sub-envs."""
        if not _is_per_env(road):
            return None
        if len(road) != self.num_envs:
            raise ValueError(f"{name} given per sub-env must have num_envs={self.num_envs} entries, got {len(road)}")
        return list(road)

    def _car_options(self, idx: np.ndarray, options: dict[str, Any] | None) -> list[dict[str, Any]]:
        """One reset-options dict per car in ``idx``: the per-env road, then the given options."""
        opts = dict(options or {})
        roads = self._per_env_roads(opts.pop("road"), "options['road']") if _is_per_env(opts.get("road")) else None
        per_car = []
        for i in idx:
            o = {}
            if self._env_roads is not None:
                o["road"] = self._env_roads[i]
            if self.scenarios is not None:  # the draw replaces the constructor's defaults
                o.update(self.scenarios(self._scenario_rngs[i]))
            o.update(opts)
            if roads is not None:
                o["road"] = roads[i]
            per_car.append(o)
        return per_car

    def _reset_cars(self, idx: np.ndarray, rngs=None, options: dict[str, Any] | None = None) -> None:
        self.sim.reset_cars(idx, rngs, self._car_options(idx, options))
        names = self.sim.names
        for i in idx:
            self._road_names[i] = names[i]

    def _infos(self, mask: np.ndarray | None = None) -> dict[str, Any]:
        """The per-step info keys of every car (arrays), with masks (all True unless ``mask`` is given)."""
        s = self.sim
        values = (s.v.copy(), s.slip.copy(), s.mu.copy(), s.x.copy(), self._road_names.copy(), s.torque.copy(),
                  s.locked.copy(), s.t * self.dt)
        mask = np.ones(self.num_envs, dtype=bool) if mask is None else mask.copy()
        infos: dict[str, Any] = {}
        for key, value in zip(STEP_INFO_KEYS, values):  # the keys share one mask array (read-only by convention)
            infos[key] = value
            infos["_" + key] = mask
        return infos

    def _add_final_info(self, infos: dict[str, Any], done: np.ndarray) -> None:
        """Episode figures of the cars that ended (``done``), FINAL_INFO_KEYS with their masks. ``stopping_distance``
        and ``ratio`` are masked to the cars that stopped: a truncated car has them left out (value 0, mask False)
        instead of NaN, as a single env's final info has them None."""
        s = self.sim
        stopped = done & s.stopped
        values = (np.where(stopped, s.stop_distance, 0.0), s.limit.copy(), np.where(stopped, s.ratio, 0.0),
                  s.lock_seen.copy(), s.stopped.copy(), s.v0.copy())
        for key, value in zip(FINAL_INFO_KEYS, values):
            infos[key], infos["_" + key] = value, (stopped if key in STOP_KEYS else done).copy()

    # ------------------------------------------------------------------ Gymnasium API
    def reset(self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None):
        """Reset all sub-envs (or those in ``options["reset_mask"]``).

        :param seed: None (keep each sub-env's generator; fresh entropy on the first reset), an int ``s`` (sub-env
            ``i`` gets ``s + i``) or a list of ``num_envs`` ints/None.
        :param options: reset options for the sub-envs (``road``, ``v0``, ``change_distance``; ``road`` may be a
            list with one spec per sub-env), plus ``reset_mask`` (bool array (num_envs,)) to reset only some.
        :return: (observations (num_envs, obs_dim) float32, infos).
        """
        n = self.num_envs
        if options is not None and not isinstance(options, dict):
            raise ValueError(f"options must be a dict with keys from {RESET_OPTION_KEYS + (RESET_MASK_KEY,)}, "
                             f"got {type(options).__name__}")
        if seed is None:
            seeds = [None] * n
        elif isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            super().reset(seed=int(seed))
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = list(seed)
            if len(seeds) != n:
                raise ValueError(f"seed given as a list must have num_envs={n} entries, got {len(seeds)}")
        options = dict(options) if options is not None else None
        mask = None
        if options is not None and RESET_MASK_KEY in options:
            mask = np.asarray(options.pop(RESET_MASK_KEY))
            if mask.shape != (n,) or mask.dtype != np.bool_:
                raise ValueError(f"options['{RESET_MASK_KEY}'] must be a bool array of shape ({n},), "
                                 f"got dtype {mask.dtype}, shape {mask.shape}")
            if not mask.any():
                raise ValueError(f"options['{RESET_MASK_KEY}'] must select at least one sub-env")
            if not self._was_reset and not mask.all():
                raise ValueError("the first reset must reset every sub-env (no partial reset_mask)")
        idx = np.arange(n) if mask is None else np.flatnonzero(mask)
        rngs = []
        for i in idx:
            if seeds[i] is not None and self.scenarios is not None:
                self._scenario_rngs[i] = np.random.default_rng(int(seeds[i]))
            if seeds[i] is not None:
                rngs.append(seeding.np_random(int(seeds[i]))[0])
            else:
                rngs.append(self.sim.rngs[i] if self.sim.rngs[i] is not None else seeding.np_random()[0])
        self._reset_cars(idx, rngs, options)
        self._autoreset[idx] = False
        self._was_reset = True
        return self.sim.observe().copy(), self._infos(mask)

    def step(self, actions):
        """Step every sub-env with its action (shape (num_envs, 1) or (num_envs,)); see the module docstring.

        :return: (observations, rewards, terminations, truncations, infos).
        """
        if not self._was_reset:
            raise RuntimeError("call reset() before step()")
        n, s = self.num_envs, self.sim
        mode = self.autoreset_mode
        pending = np.flatnonzero(self._autoreset) if mode is AutoresetMode.NEXT_STEP else None
        # Cars pending a next-step autoreset are advanced with the rest (one batched call) and their result is
        # thrown away; `resetting` keeps that step from drawing on their generators.
        obs = s.step(actions, resetting=pending if pending is not None and pending.size else None)[0]
        reward = s.reward.copy()
        terminated = s.terminated.copy()
        truncated = s.truncated.copy()
        done = terminated | truncated
        final = None
        if mode is AutoresetMode.SAME_STEP and done.any():
            idx = np.flatnonzero(done)
            final_obs = np.full(n, None, dtype=object)
            for i in idx:
                final_obs[i] = obs[i].copy()
            final_info = self._infos(done)
            self._add_final_info(final_info, done)
            final = (final_obs, final_info)
            self._reset_cars(idx)
        elif pending is not None and pending.size:
            self._reset_cars(pending)
            reward[pending] = 0.0
            terminated[pending] = False
            truncated[pending] = False
            done[pending] = False
        infos = self._infos()
        if mode is not AutoresetMode.SAME_STEP and done.any():
            self._add_final_info(infos, done)
        if final is not None:
            infos["final_obs"], infos["_final_obs"] = final[0], done.copy()
            infos["final_info"], infos["_final_info"] = final[1], done.copy()
        if mode is AutoresetMode.NEXT_STEP:
            self._autoreset = done
        return obs.copy(), reward, terminated, truncated, infos  # the buffer: resets updated their rows

    def close_extras(self, **kwargs: Any) -> None:
        pass
