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

from fricenv.envs.braking import BrakingEnv
from fricenv.envs.estimator_observation import (
    ESTIMATOR_NAMES,
    EstimatorObservation,
    PayloadEstimatorObservation,
    check_estimator_name,
)

__all__ = [
    "PAYLOAD_ESTIMATOR_NAMES",
    "make_braking",
    "make_payload",
]

PAYLOAD_ESTIMATOR_NAMES: tuple[str, ...] = ("none", "rls", "oracle")

def make_braking(estimator: str = "none", **env_kwargs) -> gym.Env:
    """A ``Braking-v0`` env, with the outputs of ``estimator`` appended to its observation.

    :param estimator: one of ``none``, ``ekf``, ``mhe``, ``ekf-rls``, ``oracle``.
    :param env_kwargs: arguments of :class:`~fricenv.envs.braking.BrakingEnv` (unknown ones raise TypeError).
    :return: the env (wrapped unless ``estimator="none"``).
    """
    check_estimator_name(estimator, ESTIMATOR_NAMES)
    env = BrakingEnv(**env_kwargs)
    return env if estimator == "none" else EstimatorObservation(env, estimator)


make_braking.metadata = BrakingEnv.metadata  # lets gymnasium.make validate render_mode


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
