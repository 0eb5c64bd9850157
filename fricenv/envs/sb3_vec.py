"""SB3 ``VecEnv`` adapter over the native Braking vector env, so SB3 algorithms step all cars in one numpy call.

:class:`BrakingSB3VecEnv` presents :class:`fricenv.envs.braking_vector.BrakingVectorEnv` (in Gymnasium's
``SAME_STEP`` autoreset mode) with stable-baselines3's conventions: ``reset() -> obs``, ``step_wait() -> (obs,
rewards, dones, infos)`` with ``dones = terminated | truncated``, an automatic reset at episode end, the last
observation in ``infos[i]["terminal_observation"]`` and ``infos[i]["TimeLimit.truncated"]`` for truncations, so
``PPO("MlpPolicy", BrakingSB3VecEnv(64))`` trains on it directly. Seeds set with ``seed(s)`` give sub-env ``i`` the
seed ``s + i`` at the next reset, as ``DummyVecEnv`` does, so trajectories equal those of ``DummyVecEnv`` over
single ``Braking-v0`` envs with the same seeds.

Infos are kept cheap: by default a sub-env's info dict is empty except at episode end, when it carries the single
env's final info (``stopping_distance``, ``limit_distance``, ``ratio``, ``lock_seen``, ``v``, ``road``, ...);
``full_info=True`` fills every step's dicts with the truth keys. Episode returns for SB3's logger come from
``VecMonitor``: :func:`make_sb3_vec_env` wraps it.

Like SB3's own vec envs it has a ``spec`` (``fricenv/Braking-v0``'s registration with the given keyword
arguments) and, with ``render_mode="rgb_array"``, ``render()`` draws its first sub-env's episode (the single env's
frame), so SB3's ``VecVideoRecorder`` can record it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env import VecEnv, VecMonitor

from fricenv.envs.braking import RENDER_FPS
from fricenv.envs.braking_vector import FINAL_INFO_KEYS, STEP_INFO_KEYS, BrakingVectorEnv
from fricenv.envs.estimator_observation import BatchedEstimatorObservation
from fricenv.envs.rendering import EpisodeHistory

__all__ = ["BrakingSB3VecEnv", "make_sb3_vec_env"]


def _item(x: Any) -> Any:
    """A numpy scalar as a Python scalar (object entries unchanged)."""
    return x.item() if isinstance(x, np.generic) else x


class BrakingSB3VecEnv(VecEnv):
    """SB3 view of ``num_envs`` Braking-v0 cars stepped together.

    :param num_envs: number of sub-envs (ignored when ``venv`` is given).
    :param venv: an existing :class:`BrakingVectorEnv` in ``SAME_STEP`` autoreset mode (else one is built).
    :param full_info: fill every step's info dicts with the truth keys (costs a dict per sub-env per step).
    :param render_mode: None or ``"rgb_array"`` (``render()`` draws the first sub-env).
    :param env_kwargs: keyword arguments of :class:`BrakingVectorEnv` (``road``, ``v0``, ``observation``, ...),
        plus ``estimator``: a batched estimator (:data:`estimators.batched.BATCHED`) whose outputs are appended
        (:class:`~fricenv.envs.estimator_observation.BatchedEstimatorObservation`).
    """

    def __init__(self, num_envs: int = 1, *, venv: BrakingVectorEnv | None = None, full_info: bool = False,
                 render_mode: str | None = None, **env_kwargs):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"unknown render_mode {render_mode!r}; valid: rgb_array or None")
        if venv is None:
            if "autoreset_mode" in env_kwargs:
                raise TypeError("autoreset_mode is fixed to SAME_STEP by the SB3 adapter (SB3's convention)")
            kwargs = {k: v for k, v in env_kwargs.items() if k != "estimator"}
            venv = BrakingVectorEnv(num_envs, autoreset_mode=AutoresetMode.SAME_STEP, **kwargs)
            if env_kwargs.get("estimator", "none") != "none":
                venv = BatchedEstimatorObservation(venv, env_kwargs["estimator"])
        else:
            if env_kwargs:
                raise TypeError(f"give either venv or env kwargs, not both: {sorted(env_kwargs)}")
            if not isinstance(venv, (BrakingVectorEnv, BatchedEstimatorObservation)):
                raise TypeError(f"venv must be a BrakingVectorEnv (or one in BatchedEstimatorObservation), "
                                f"got {type(venv).__name__}")
            if venv.autoreset_mode is not AutoresetMode.SAME_STEP:
                raise ValueError(f"venv must use autoreset_mode SAME_STEP for SB3, got {venv.autoreset_mode}")
        self.venv = venv
        self.full_info = bool(full_info)
        self._actions: np.ndarray | None = None
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        self.render_mode = render_mode
        self.metadata = {"render_modes": ["rgb_array"], "render_fps": RENDER_FPS}
        spec = gym.spec("fricenv/Braking-v0")
        self.spec = dataclasses.replace(spec, kwargs={**spec.kwargs, **env_kwargs})
        v_max = float(np.max(env_kwargs.get("v0", venv.sim.defaults["v0"])))
        self._history = EpisodeHistory(venv.config.t_max, v_max) if render_mode else None

    # ------------------------------------------------------------------ VecEnv API
    def reset(self):
        """Reset every sub-env with the seeds/options set by ``seed()``/``set_options()`` (then forgotten)."""
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        options = self._merged_options()
        obs, _ = self.venv.reset(seed=seeds, options=options)
        self._reset_seeds()
        self._reset_options()
        if self._history is not None:
            self._history.reset()
            self._history.record(self.venv.sim, 0)
        return obs

    def _merged_options(self) -> dict[str, Any] | None:
        """SB3 keeps one options dict per sub-env; the vector env takes one dict (``road`` may be per env)."""
        opts = self._options
        if all(not o for o in opts):
            return None
        keys = set().union(*opts)
        merged: dict[str, Any] = {}
        for key in keys:
            values = [o.get(key) for o in opts]
            if all(v == values[0] for v in values):
                merged[key] = values[0]
            elif key == "road":
                merged[key] = values
            else:
                raise ValueError(f"reset option {key!r} differs between sub-envs; only 'road' may be set per "
                                 f"sub-env")
        return merged

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        if self._actions is None:
            raise RuntimeError("step_async() must be called before step_wait()")
        obs, rewards, terminated, truncated, infos = self.venv.step(self._actions)
        self._actions = None
        dones = terminated | truncated
        if self._history is not None:  # the first sub-env's episode (restarted by its autoreset)
            if dones[0]:
                self._history.reset()
            self._history.record(self.venv.sim, 0)
        n = self.num_envs
        if self.full_info:
            cols = [infos[k] for k in STEP_INFO_KEYS]
            out = [{k: _item(c[i]) for k, c in zip(STEP_INFO_KEYS, cols)} for i in range(n)]
        else:
            out = [{} for _ in range(n)]
        if dones.any():
            final_obs, final_info = infos["final_obs"], infos["final_info"]
            keys = STEP_INFO_KEYS + FINAL_INFO_KEYS
            for i in np.flatnonzero(dones):
                d = {k: _item(final_info[k][i]) if final_info["_" + k][i] else None for k in keys}
                d["terminal_observation"] = final_obs[i]
                d["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
                out[i] = d
        return obs, rewards.astype(np.float32), dones, out

    def close(self) -> None:
        self.venv.close()

    def _indices(self, indices) -> list[int]:
        return list(self._get_indices(indices))

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        """An attribute of the vector env, once per requested sub-env (the sub-envs share one simulator)."""
        value = getattr(self.venv, attr_name)
        return [value for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        """Set an attribute on the vector env (shared by all sub-envs)."""
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        """Call a vector-env method once and return its result per requested sub-env."""
        result = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [result for _ in self._indices(indices)]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        """The first sub-env's frame (None for the others: they share one simulator and are not drawn)."""
        first = self._history.frame() if self._history is not None else None
        return [first] + [None] * (self.num_envs - 1)

    def render(self, mode: str | None = None) -> np.ndarray | None:
        """The first sub-env's frame (``render_mode="rgb_array"``), as SB3's ``VecVideoRecorder`` records it."""
        if (mode or self.render_mode) != "rgb_array" or self._history is None:
            gym.logger.warn("BrakingSB3VecEnv renders only with render_mode='rgb_array'")
            return None
        return self._history.frame()


def make_sb3_vec_env(num_envs: int, *, monitor: bool = True, seed: int | None = None,
                     **env_kwargs) -> VecEnv:
    """A :class:`BrakingSB3VecEnv`, wrapped in SB3's ``VecMonitor`` (episode returns for the logger) if asked.

    :param num_envs: number of sub-envs.
    :param monitor: wrap in ``VecMonitor``.
    :param seed: seed for the first reset (sub-env ``i`` gets ``seed + i``).
    :param env_kwargs: keyword arguments of :class:`BrakingSB3VecEnv`.
    :return: the SB3 vec env.
    """
    env: VecEnv = BrakingSB3VecEnv(num_envs, **env_kwargs)
    if seed is not None:
        env.seed(seed)
    return VecMonitor(env) if monitor else env

