"""Gymnasium environments, registered under the namespace ``fricenv/`` when :mod:`fricenv` is imported.

One ``register`` call per environment, entry points as strings (the env module is imported by ``gymnasium.make``).
"""

from gymnasium.envs.registration import register, registry

__all__ = ["BRAKING_VARIANTS", "ENV_IDS", "PAYLOAD_VARIANTS"]

ENV_IDS: list[str] = []


def _register(env_id: str, entry_point: str, **kwargs) -> None:
    """Register once (re-importing, e.g. after a module reload, is harmless)."""
    ENV_IDS.append(env_id)
    if env_id not in registry:
        register(id=env_id, entry_point=entry_point, **kwargs)


# The factories return the plain env for estimator="none" and wrap it in EstimatorObservation otherwise, so
# gymnasium.make("fricenv/Braking-v0", estimator="ekf") works.
_register("fricenv/Braking-v0", "fricenv.envs.factory:make_braking",
          vector_entry_point="fricenv.envs.braking_vector:BrakingVectorEnv")
_register("fricenv/PayloadExcitation-v0", "fricenv.envs.factory:make_payload")
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
    _register(_env_id, "fricenv.envs.factory:make_braking", kwargs={"estimator": _estimator})
for _env_id, _estimator in PAYLOAD_VARIANTS.items():
    _register(_env_id, "fricenv.envs.factory:make_payload", kwargs={"estimator": _estimator})
