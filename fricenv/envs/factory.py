"""Env factories with an ``estimator`` choice, usable as Gymnasium entry points.

``make_braking(estimator="ekf", road="random")`` is ``BrakingEnv(road="random")`` wrapped in
:class:`~fricenv.envs.estimator_observation.EstimatorObservation`; with ``estimator="none"`` it is the plain env.
Registered as the entry point of ``fricenv/Braking-v0`` it makes ``gymnasium.make("fricenv/Braking-v0",
estimator="ekf")`` work; ``fricenv.envs`` also registers one id per estimator (``BRAKING_VARIANTS``, e.g.
``fricenv/BrakingEKF-v0``) and the payload equivalents.

``make_payload(estimator="rls")`` does the same for ``fricenv/PayloadExcitation-v0``: ``none`` (raw readings
only), ``rls`` (the env's RLS estimate of S, run inside the env at 1 ms, plus its excitation measure) or
``oracle`` (the true S appended).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from fricenv.envs.action_map import LINEAR, ActionMapWrapper, check_action_map
from fricenv.envs.braking import BrakingEnv
from fricenv.envs.estimator_observation import (
    ESTIMATOR_NAMES,
    BatchedEstimatorObservation,
    EstimatorObservation,
    PayloadEstimatorObservation,
    batched_names,
    check_estimator_name,
)

__all__ = [
    "PAYLOAD_ESTIMATOR_NAMES",
    "make_braking",
    "make_braking_vector",
    "make_payload",
]

PAYLOAD_ESTIMATOR_NAMES: tuple[str, ...] = ("none", "rls", "oracle")

def make_braking(estimator: str = "none", action_map: str = LINEAR, **env_kwargs) -> gym.Env:
    """A ``Braking-v0`` env, with the outputs of ``estimator`` appended to its observation.

    :param estimator: one of ``none``, ``ekf``, ``mhe``, ``ekf-rls``, ``oracle``.
    :param action_map: the policy's output map in front of the env (:mod:`fricenv.envs.action_map`; ``linear``:
        none).
    :param env_kwargs: arguments of :class:`~fricenv.envs.braking.BrakingEnv` (unknown ones raise TypeError).
    :return: the env (wrapped unless ``estimator="none"`` and ``action_map="linear"``).
    """
    check_estimator_name(estimator, ESTIMATOR_NAMES)
    check_action_map(action_map)
    env = BrakingEnv(**env_kwargs)
    env = env if estimator == "none" else EstimatorObservation(env, estimator)
    return env if action_map == LINEAR else ActionMapWrapper(env, action_map)


make_braking.metadata = BrakingEnv.metadata  # lets gymnasium.make validate render_mode


def make_braking_vector(num_envs: int = 1, estimator: str = "none", render_mode: str | None = None,
                        max_episode_steps: int | None = None, action_map: str = LINEAR, **env_kwargs):
    """Vector entry point of every ``Braking`` id: the native
    :class:`~fricenv.envs.braking_vector.BrakingVectorEnv` (wrapped in
    :class:`~fricenv.envs.estimator_observation.BatchedEstimatorObservation` for an estimator with a batched form,
    :func:`~fricenv.envs.estimator_observation.batched_names`), or, for the keywords it does not take (another
    estimator, a ``render_mode``), Gymnasium's ``SyncVectorEnv`` over :func:`make_braking` envs (each in a ``TimeLimit`` of ``max_episode_steps``), with a warning.

    :param num_envs: number of sub-envs.
    :param estimator: as :func:`make_braking`.
    :param render_mode: None (native) or ``rgb_array`` (sync fallback; ``render()`` gives each sub-env's frame).
    :param max_episode_steps: truncation in control steps (``make_vec`` passes the registration's).
    :param action_map: as :func:`make_braking`.
    :param env_kwargs: the single env's keyword arguments.
    """
    from fricenv.envs.braking_vector import BrakingVectorEnv

    check_estimator_name(estimator, ESTIMATOR_NAMES)
    mapping = check_action_map(action_map)
    if (estimator == "none" or estimator in batched_names()) and render_mode is None:
        venv = BrakingVectorEnv(num_envs, max_episode_steps=max_episode_steps, **env_kwargs)
        venv = venv if estimator == "none" else BatchedEstimatorObservation(venv, estimator)
        if action_map == LINEAR:
            return venv
        from gymnasium.wrappers.vector import TransformAction

        return TransformAction(venv, lambda a: mapping(np.asarray(a, dtype=float)).astype(np.float32),
                               venv.action_space)
    if "autoreset_mode" in env_kwargs:
        raise TypeError("autoreset_mode is not available with the sync fallback (estimator or render_mode given)")
    gym.logger.warn(f"fricenv/Braking vector env: estimator={estimator!r}, render_mode={render_mode!r} are not "
                    f"supported by the native vector env; using gymnasium.vector.SyncVectorEnv over single envs")

    def one() -> gym.Env:
        env = make_braking(estimator, render_mode=render_mode, action_map=action_map, **env_kwargs)
        return gym.wrappers.TimeLimit(env, max_episode_steps) if max_episode_steps is not None else env

    return gym.vector.SyncVectorEnv([one for _ in range(num_envs)])


def make_payload(estimator: str | bool = "none", **env_kwargs) -> gym.Env:
    """A ``PayloadExcitation-v0`` env with or without an estimate of the calibration S in its observation.

    :param estimator: ``none`` (or False), ``rls`` (or True), ``oracle``.
    :param env_kwargs: arguments of :class:`~fricenv.envs.payload.PayloadExcitationEnv`.
    """
    from fricenv.envs.payload import PayloadExcitationEnv

    if estimator is True:
        estimator = "rls"
    elif estimator is False:
        estimator = "none"
    check_estimator_name(estimator, PAYLOAD_ESTIMATOR_NAMES)
    env = PayloadExcitationEnv(estimator="rls" if estimator == "rls" else False, **env_kwargs)
    return PayloadEstimatorObservation(env) if estimator == "oracle" else env
