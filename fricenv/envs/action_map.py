"""The output map of an ABS policy: the network's action ``a`` in [-1, 1] -> the env's torque command in [-1, 1].

``Braking-v0`` applies ``T = (a_env + 1) t_max / 2`` (t_max 2500 N m). The torque that holds the friction peak is
``r F_z mu_max``: 1100 N m on dry, 902 on wet, 325 on snow, 110 on ice, i.e. 4.4 % of the action range on ice.
With the linear map and PPO's Gaussian exploration (std 0.22 of the range), the noise on ice (280 N m) is 2.5 times
the whole useful torque: half of the samples are clipped at zero torque and most of the others lock the wheel.

:data:`ACTION_MAPS`:

========== ===========================================================================================
``linear``  ``a_env = a`` (the env's own map).
``log``     ``T / t_max = (R^u - 1) / (R - 1)`` with ``u = (a + 1) / 2`` and ``R = LOG_RANGE`` (100): zero
            torque at ``a = -1``, ``t_max`` at ``+1``, and ``dT/da = ln R / 2 (T + t_max / (R - 1))``: the same
            *relative* torque resolution on every road (ice's peak torque sits at ``a = -0.27``, dry's at
            ``+0.64``), so one exploration noise fits ice and dry.
========== ===========================================================================================

``gymnasium.make("fricenv/Braking-v0", action_map="log")`` puts the map in front of the env
(:class:`ActionMapWrapper`), so a policy trained with the map runs on that env with plain Stable-Baselines3.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import gymnasium as gym
import numpy as np

from fricenv.errors import InvalidInputError

__all__ = ["ACTION_MAPS", "LINEAR", "LOG_RANGE", "ActionMapError", "ActionMapWrapper", "check_action_map",
           "log_torque"]

LOG_RANGE = 100.0  # t_max over the torque one step above zero of the log map's scale [-]
LINEAR = "linear"


class ActionMapError(InvalidInputError):
    """An unknown action map name."""


def log_torque(a: np.ndarray) -> np.ndarray:
    """The ``log`` map (module docstring) of actions in [-1, 1] (clipped first)."""
    u = 0.5 * (np.clip(a, -1.0, 1.0) + 1.0)
    share = np.expm1(math.log(LOG_RANGE) * u) / (LOG_RANGE - 1.0)  # T / t_max
    return 2.0 * share - 1.0


ACTION_MAPS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    LINEAR: lambda a: np.clip(a, -1.0, 1.0),
    "log": log_torque,
}


def check_action_map(name: str) -> Callable[[np.ndarray], np.ndarray]:
    """The map called ``name``; :class:`ActionMapError` listing the valid names."""
    try:
        return ACTION_MAPS[name]
    except (KeyError, TypeError):
        raise ActionMapError(f"unknown action_map {name!r}; valid: {', '.join(ACTION_MAPS)}") from None


class ActionMapWrapper(gym.ActionWrapper):
    """A braking env whose actions pass through an action map; the observation layout of the wrapped env stays
    readable (``observation_fields``, ``observation_names``, ``decode_observation``).

    :param env: a ``Braking-v0`` env (possibly wrapped).
    :param name: a key of :data:`ACTION_MAPS`.
    """

    def __init__(self, env: gym.Env, name: str):
        self._map = check_action_map(name)
        super().__init__(env)
        self.action_map = name
        for attr in ("observation_fields", "observation_names", "appended_fields", "decode_observation"):
            if hasattr(env, attr):
                setattr(self, attr, getattr(env, attr))

    def action(self, action) -> np.ndarray:
        """The env's command for the policy's ``action``."""
        return self._map(np.asarray(action, dtype=float)).astype(np.float32)
