"""Gymnasium environments, registered under the namespace ``fricenv/`` when :mod:`fricenv` is imported.

One ``register`` call per environment, entry points as strings (the env module is imported by ``gymnasium.make``).
"""

from gymnasium.envs.registration import register, registry

__all__ = ["ENV_IDS"]

ENV_IDS: list[str] = []


def _register(env_id: str, entry_point: str, **kwargs) -> None:
    """Register once (re-importing, e.g. after a module reload, is harmless)."""
    ENV_IDS.append(env_id)
    if env_id not in registry:
        register(id=env_id, entry_point=entry_point, **kwargs)


_register("fricenv/Braking-v0", "fricenv.envs.braking:BrakingEnv")
_register("fricenv/PayloadExcitation-v0", "fricenv.envs.payload:PayloadExcitationEnv")
