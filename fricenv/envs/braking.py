"""``fricenv/Braking-v0``: straight-line ABS braking of a quarter car, a thin Gymnasium shell over
:class:`fricenv.envs.braking_sim.BrakingSim` with one car."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from fricenv.envs import config as cfg
from fricenv.envs.actions import check_action
from fricenv.envs.braking_sim import BrakingSim
from fricenv.envs.effect_plant import effect_plant_or_none
from fricenv.envs.rendering import EpisodeHistory
from fricenv.envs.scenario import RESET_OPTION_KEYS, V0_DEFAULT
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import MagicFormula

__all__ = ["BrakingEnv"]

RENDER_FPS = 100  # one frame per 10 ms control step


class BrakingEnv(gym.Env):
    """
    ## Description

    A quarter car (Sui & Johansen, Table I: m = 325 kg, J = 1 kg m^2, r = 0.345 m, F_z = 3188 N) brakes in a
    straight line from ``v0`` (default 20 m/s) to the stop speed ``v_stop`` (default 2 m/s). The agent is the ABS
    ECU: every 10 ms it commands the brake torque, seeing only what an ECU sees (wheel speed, wheel deceleration,
    its own last command and the longitudinal acceleration, all noisy). Friction follows the Magic Formula of the
    road, which may change during the stop (e.g. dry -> ice at 15 m). The goal is the shortest stop without locking
    the wheel. The physics run in substeps (default 2 ms) of the L-stable Rosenbrock (ROS2) step of
    :func:`fricenv.plants.rosenbrock.ros2_substep`, which handles wheel lock; a step of this env runs a control
    step's substeps in one call of :func:`fricenv.envs.episode.car_substeps_compiled` (that ROS2 substep compiled
    by numba, with the substep refinement of :func:`fricenv.plants.quarter_car.step`).

    ## Action Space

    ``Box(-1, 1, (1,), float32)``. Out-of-range values are clipped; NaN/inf or a wrong shape raise ``ValueError``.

    | action_mode             | Num | Action                           | Min | Max | Effect                                  |
    |-------------------------|-----|----------------------------------|-----|-----|-----------------------------------------|
    | ``"torque"`` (default)  | 0   | normalised brake torque command  | -1  | 1   | ``T_b = (a + 1) / 2 * t_max`` [N m]     |
    | ``"torque_rate"``       | 0   | normalised modulator rate        | -1  | 1   | ``T_b += a * torque_rate_max * dt``, kept in [0, t_max] |

    ``t_max`` defaults to 2500 N m (the wheel locks on dry asphalt above about 1100 N m), ``torque_rate_max`` to
    25000 N m/s (the full range in 0.1 s).

    ## Observation Space

    ``Box(float32)`` with finite bounds; each entry is a physical value divided by a scale and clipped to bounds.
    The layout is also available by name: ``env.unwrapped.observation_fields`` (name, unit, scale, bounds) and
    ``env.unwrapped.decode_observation(obs) -> dict`` (physical units).

    | Num | Name          | Observation                                                  | Scale        | Min  | Max |
    |-----|---------------|--------------------------------------------------------------|--------------|------|-----|
    | 0   | wheel_speed   | measured wheel speed, noise variance 0.2 (rad/s)^2           | 100 rad/s    | -1   | 2   |
    | 1   | wheel_decel   | measured wheel deceleration ``-r omega'`` (noise 1 m/s^2)    | 9.81 m/s^2   | -50  | 50  |
    | 2   | torque        | last brake torque command ``T_b / t_max``                    | 1            | 0    | 1   |
    | 3   | a_x           | measured longitudinal acceleration (noise 0.1 m/s^2), < 0 braking | 9.81 m/s^2 | -5 | 5 |
    | 4   | v             | (``observation="oracle"`` only) true vehicle speed           | 50 m/s       | 0    | 2   |
    | 5   | slip          | (oracle only) true wheel slip                                | 1            | -1   | 1   |
    | 6   | mu            | (oracle only) true friction coefficient in use               | 1            | -2   | 2   |

    ## Rewards

    Per control step, with ``d_k`` the distance travelled (above ``v_stop``), ``v`` the vehicle speed,
    ``mu_max`` the peak friction of the road under the car, and ``L`` the episode's physical-limit distance:

    | Term              | Value                                                                  |
    |-------------------|------------------------------------------------------------------------|
    | braking efficiency| ``((v_{k-1}^2 - v_k^2) / (2 g mu_max) - d_k) / L``  (summed over the physics substeps) |
    | wheel lock        | ``- lock_penalty`` (default 0.01) for every step the wheel is locked  |

    The efficiency term is <= 0 in every step (the car can never decelerate faster than ``g mu_max``) and is 0
    only when the tire works at its friction peak. On one road of the nominal plant its episode sum is
    ``1 - d_stop / L``, i.e. ``1 - ratio``: maximising the return minimises the stopping distance. The lock term
    makes a locked wheel cost more than any distance it could save (on snow, whose friction keeps rising to slip 1,
    it is what keeps the wheel rolling). Lock is penalised, not terminated.

    ## Wheel lock

    The wheel is *locked* when ``omega r < 0.05 v`` has held for more than 0.1 s (10 steps) while ``v > v_stop``.
    ``info["locked"]`` says whether it is locked now, ``info["lock_seen"]`` (episode end) whether it ever was.

    ## Starting State

    Free rolling (``omega = v0 / r``) at ``v0`` with zero torque. ``v0`` is a number or a ``(low, high)`` range
    drawn uniformly from ``self.np_random``.

    ## Episode End

    * Termination: the vehicle speed reaches ``v_stop`` (default 2 m/s). The stopping distance is interpolated
      within the physics substep where the speed crosses ``v_stop``.
    * Truncation: ``time_limit`` (default 60 s, 6000 steps; a locked wheel on ice needs 42 s from 40 m/s).

    ## Roads

    ``road`` (constructor or ``reset(options={"road": ...})``): a preset ``"dry"``, ``"wet"``, ``"snow"``,
    ``"ice"``; ``"random"`` (a preset drawn uniformly from ``self.np_random`` each episode); a friction change
    ``"a->b"`` between two presets (e.g. ``"dry->ice"``, ``"ice->dry"``) at ``change_distance`` metres (default
    15 m, a number or a range); ``"random-change"`` (two different presets, change distance drawn on 5..30 m); or a
    :class:`~fricenv.plants.tire.MagicFormula`.

    ## Info

    Every step: ``v`` [m/s], ``slip``, ``mu``, ``distance`` [m], ``road``, ``torque`` [N m], ``locked``, ``time``
    [s]. At episode end also ``stopping_distance`` [m], ``limit_distance`` [m] (the physical limit
    ``(v0^2 - v_stop^2) / (2 g mu_max)``, piecewise over a friction change; with ``effects``, the limit of that plant:
    :func:`~fricenv.envs.scenario.effect_limit_distance`), ``ratio`` (stopping / limit),
    ``lock_seen``, ``stopped``, ``v0``. A truncated episode (no stop) has ``stopping_distance`` and ``ratio``
    None: its final info holds no NaN, so two identical envs compare equal (Gymnasium's ``data_equivalence``).

    ## Arguments

    ``gymnasium.make("fricenv/Braking-v0", road="dry", v0=20.0, change_distance=None, action_mode="torque",
    observation="default", render_mode=None, t_max=2500.0, torque_rate_max=25000.0, v_stop=2.0, time_limit=60.0,
    physics_dt=0.002, lock_penalty=0.01, decel_noise_std=1.0, ax_noise_std=0.1, omega_noise_var=0.2,
    params=PAPER_PARAMS, effects=None, effects_randomization=None)``. Unknown arguments raise ``TypeError``;
    unknown values raise ``ValueError`` listing the valid ones. ``reset(options=...)`` accepts ``road``, ``v0`` and
    ``change_distance``. Every id is registered with ``max_episode_steps = time_limit / dt`` (6000): ``gym.make``
    adds a ``TimeLimit`` at the same step the env truncates itself, and wrappers that read the spec
    (``TimeAwareObservation``, sb3-contrib's ``TimeFeatureWrapper``) see the true episode length; with a
    ``time_limit`` above 60 s pass ``max_episode_steps`` too.

    ## Vectorized

    ``gymnasium.make_vec("fricenv/Braking-v0", num_envs=N)`` (``vectorization_mode="vector_entry_point"``, the
    default for this id) builds :class:`fricenv.envs.braking_vector.BrakingVectorEnv`: all ``N`` cars step in one
    batched numpy call, with next-step autoreset (or ``autoreset_mode="SameStep"``/``"Disabled"``), per-env seeds
    (``seed + i``) and per-env roads (``road=[...]``), and the same trajectories as ``N`` single envs. For SB3,
    :class:`fricenv.envs.sb3_vec.BrakingSB3VecEnv` is a ``VecEnv`` over it. Keywords the native vector env does
    not take (``estimator`` other than ``"none"``, ``render_mode``) make ``make_vec`` fall back to Gymnasium's
    ``SyncVectorEnv`` over single envs, with a warning. Wrappers need ``vectorization_mode="sync"``.

    ## The corrected simulator: effects

    ``effects`` steps the quarter car with unmodelled effects (the registry's effect names): a list of
    ``{"effect": "brake_lag", "params": {"tau": 0.04}}`` entries, or the path of a ``gap diagnose`` report.json (its
    ``effects`` list if present, else its ``verdict`` and ``params``; ``none``/``unexplained`` give no effects).
    ``effects_randomization={"brake_lag": {"tau": (0.02, 0.08)}, ...}`` draws parameters per episode from
    ``self.np_random`` (after the scenario's draws) for robust training; a parameter without a range keeps its value
    from ``effects``. ``effects=[]`` (the default None too) is exactly the plain env. Unknown effect or parameter
    names raise :class:`fricenv.envs.effect_spec.EffectSpecError` (a ``ValueError``) naming them. The plant is then
    :class:`fricenv.envs.effect_plant.EffectPlant` (slower: numpy per substep). ``mu_change``'s ``t_change`` counts
    from the episode start; ``radius_error`` moves free rolling, slip and the lock test to ``r_eff``.

    ## Version History

    * v0: initial version.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": RENDER_FPS}

    def __init__(
        self,
        render_mode: str | None = None,
        road: str | MagicFormula = "dry",
        v0: float | tuple[float, float] = V0_DEFAULT,
        change_distance: float | tuple[float, float] | None = None,
        action_mode: str = "torque",
        observation: str = "default",
        t_max: float = cfg.T_MAX,
        torque_rate_max: float = cfg.TORQUE_RATE_MAX,
        v_stop: float = cfg.V_STOP,
        time_limit: float = cfg.TIME_LIMIT,
        physics_dt: float = cfg.PHYSICS_DT,
        lock_penalty: float = cfg.LOCK_PENALTY,
        decel_noise_std: float = cfg.DECEL_NOISE_STD,
        ax_noise_std: float = cfg.AX_NOISE_STD,
        omega_noise_var: float = cfg.OMEGA_NOISE_VAR,
        params: qc.QuarterCarParams = qc.PAPER_PARAMS,
        effects: Any = None,
        effects_randomization: Mapping[str, Any] | None = None,
    ):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"unknown render_mode {render_mode!r}; valid: "
                             f"{', '.join(self.metadata['render_modes'])} or None")
        self.render_mode = render_mode
        self.config = cfg.BrakingConfig(
            physics_dt=physics_dt, t_max=t_max, torque_rate_max=torque_rate_max, v_stop=v_stop,
            time_limit=time_limit, omega_noise_var=omega_noise_var, decel_noise_std=decel_noise_std,
            ax_noise_std=ax_noise_std, lock_penalty=lock_penalty, action_mode=action_mode,
            observation=observation, params=params)
        plant = effect_plant_or_none(1, self.config, effects, effects_randomization)
        self.sim = BrakingSim(1, self.config, road=road, v0=v0, change_distance=change_distance,
                                   scalar=plant is None, plant=plant)
        self.dt = self.config.dt
        self.observation_fields = self.sim.layout
        self.observation_names = tuple(f.name for f in self.observation_fields)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.observation_space = spaces.Box(
            low=np.array([f.low for f in self.observation_fields], dtype=np.float32),
            high=np.array([f.high for f in self.observation_fields], dtype=np.float32),
            dtype=np.float32,
        )
        self._history: EpisodeHistory | None = None
        self._v_render_max = float(np.max(v0))

    # ------------------------------------------------------------------ Gymnasium API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if options is not None and not isinstance(options, dict):
            raise ValueError(f"options must be a dict with keys from {RESET_OPTION_KEYS}, "
                             f"got {type(options).__name__}")
        obs = self.sim.reset_cars([0], [self.np_random], options)
        if self.render_mode is not None:
            if self._history is None:
                self._history = EpisodeHistory(self.config.t_max, self._v_render_max)
            self._history.reset()
            self._history.record(self.sim)
        return obs[0].copy(), self.sim.car_info(0)

    def step(self, action):
        if self.sim.scenarios[0] is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        obs, reward, terminated, truncated = self.sim.advance(check_action(action, (1,)))
        term, trunc = terminated.item(0), truncated.item(0)
        if self.render_mode is not None:
            self._history.record(self.sim)
        return obs[0].copy(), reward.item(0), term, trunc, self.sim.car_info(0, final=term or trunc)

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; use render_mode='rgb_array'")
            return None
        if self._history is None:
            raise gym.error.ResetNeeded("call reset() before render()")
        return self._history.frame()

    def close(self):
        if self._history is not None:
            self._history.close()

    # ------------------------------------------------------------------ helpers
    def decode_observation(self, obs) -> dict[str, float]:
        """Physical values (units of :attr:`observation_fields`) of an observation, by name."""
        return cfg.decode_observation(self.observation_fields, obs)

    @property
    def road(self) -> MagicFormula | None:
        """The road under the car now (after any friction change), or None before reset."""
        sc = self.sim.scenarios[0]
        if sc is None:
            return None
        return sc.road_b if self.sim.switched[0] else sc.road_a
