"""Gymnasium environments, registered under the namespace ``fricenv/`` when :mod:`fricenv` is imported.

One ``register`` call per environment, entry points as strings (the env module is imported by ``gymnasium.make``).
"""

from gymnasium.envs.registration import register, registry

from fricenv.envs.config import BrakingConfig

# Truncation in control steps (time limit / control step) of every registered id: gym.make's TimeLimit and the
# wrappers that read spec.max_episode_steps see the env's own episode length.
BRAKING_MAX_STEPS = BrakingConfig().max_steps
PAYLOAD_MAX_STEPS = 1000  # fricenv.envs.payload: TIME_LIMIT 20 s / CONTROL_DT 0.02 s (checked in the tests)

__all__ = ["BRAKING_MAX_STEPS", "BRAKING_VARIANTS", "ENV_IDS", "PAYLOAD_MAX_STEPS", "PAYLOAD_VARIANTS"]

ENV_IDS: list[str] = []


def _register(env_id: str, **kwargs) -> None:
    """Register once (re-importing, e.g. after a module reload, is harmless)."""
    ENV_IDS.append(env_id)
    if env_id not in registry:
        register(id=env_id, **kwargs)


# The factories return the plain env for estimator="none" and wrap it in EstimatorObservation otherwise, so
# gymnasium.make("fricenv/Braking-v0", estimator="ekf") works.
_BRAKING = {"entry_point": "fricenv.envs.factory:make_braking", "max_episode_steps": BRAKING_MAX_STEPS,
            "vector_entry_point": "fricenv.envs.factory:make_braking_vector"}
_PAYLOAD = {"entry_point": "fricenv.envs.factory:make_payload", "max_episode_steps": PAYLOAD_MAX_STEPS}
_register("fricenv/Braking-v0", **_BRAKING)
_register("fricenv/PayloadExcitation-v0", **_PAYLOAD)
# One id per estimator choice (id -> estimator), for code that can only pass an id.
BRAKING_VARIANTS: dict[str, str] = {
    "fricenv/BrakingEKF-v0": "ekf",
    "fricenv/BrakingMHE-v0": "mhe",
    "fricenv/BrakingEKFRLS-v0": "ekf-rls",
    "fricenv/BrakingOracleEstimate-v0": "oracle",
}
PAYLOAD_VARIANTS: dict[str, str] = {
    "fricenv/PayloadExcitationRLS-v0": "rls",
    "fricenv/PayloadExcitationOracle-v0": "oracle",
}
for _env_id, _estimator in BRAKING_VARIANTS.items():
    _register(_env_id, **_BRAKING, kwargs={"estimator": _estimator})
for _env_id, _estimator in PAYLOAD_VARIANTS.items():
    _register(_env_id, **_PAYLOAD, kwargs={"estimator": _estimator})
