"""The native vector env with the batched MHE equals single envs wrapped in EstimatorObservation."""

from __future__ import annotations

import gymnasium as gym

import fricenv  # noqa: F401  (registers the envs)
from fricenv.envs.estimator_observation import BatchedEstimatorObservation, batched_names


def test_make_vec_with_mhe_uses_the_batched_mhe():
    assert {"mhe", "mhe-full"} <= set(batched_names())
    envs = gym.make_vec("fricenv/Braking-v0", num_envs=2, vectorization_mode="vector_entry_point",
                        estimator="mhe-full", road="wet")
    assert isinstance(envs, BatchedEstimatorObservation)
    assert envs.batched.t.model.estimated == ("theta", "B", "C", "E")
