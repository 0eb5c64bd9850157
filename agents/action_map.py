"""The output map of an ABS policy in the SB3 training vector env; the maps themselves are
:mod:`fricenv.envs.action_map` (the env applies the same map with ``gymnasium.make(..., action_map=NAME)``).

The map is part of the policy: training applies it to the vector env's actions (:class:`ActionMapVecEnv`),
:class:`agents.training.TrainedPolicy` to its predictions, and a run directory's ``env_kwargs.yml`` names it, so a
policy loaded with plain ``PPO.load`` runs on ``gymnasium.make("fricenv/Braking-v0", **env_kwargs)``.
"""

from __future__ import annotations

import numpy as np
from stable_baselines3.common.vec_env import VecEnvWrapper

from fricenv.envs.action_map import ACTION_MAPS, LOG_RANGE, ActionMapError, check_action_map, log_torque

__all__ = ["ACTION_MAPS", "LOG_RANGE", "ActionMapError", "ActionMapVecEnv", "check_action_map", "log_torque"]


class ActionMapVecEnv(VecEnvWrapper):
    """An SB3 vector env whose actions pass through an action map before the wrapped env sees them.

    :param venv: the vector env.
    :param name: a key of :data:`ACTION_MAPS`.
    """

    def __init__(self, venv, name: str):
        self.action_map = check_action_map(name)
        super().__init__(venv)

    def step_async(self, actions: np.ndarray) -> None:
        self.venv.step_async(self.action_map(np.asarray(actions, dtype=float)).astype(np.float32))

    def step_wait(self):
        return self.venv.step_wait()

    def reset(self):
        return self.venv.reset()
