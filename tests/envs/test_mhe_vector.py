"""The native vector env with the batched MHE equals single envs wrapped in EstimatorObservation (issue 17)."""

from __future__ import annotations

import gymnasium as gym
import pytest

import fricenv  # noqa: F401  (registers the envs)
from estimators.mhe_batched import BatchedMHE
from fricenv.envs.braking_vector import BrakingVectorEnv
from fricenv.envs.estimator_observation import BatchedEstimatorObservation, batched_names
from fricenv.envs.factory import make_braking
from tests.envs.test_braking_vector import ROADS_PER_ENV, SHORT_V0, _compare_with_single_envs


@pytest.mark.parametrize("same_step", [False, True])
def test_batched_mhe_vector_env_equals_wrapped_single_envs(same_step):
    kw = {"v0": SHORT_V0, "change_distance": (0.5, 2.0)}
    mode = "SameStep" if same_step else "NextStep"
    venv = BatchedEstimatorObservation(BrakingVectorEnv(4, road=ROADS_PER_ENV, autoreset_mode=mode, **kw), "mhe")
    assert isinstance(venv.batched, BatchedMHE)
    singles = [make_braking("mhe", road=r, **kw) for r in ROADS_PER_ENV]
    assert venv.observation_fields == singles[0].observation_fields
    assert venv.single_observation_space == singles[0].observation_space
    ended, _ = _compare_with_single_envs(venv, singles, seed=7, steps=300, same_step=same_step)
    assert ended >= 8


def test_make_vec_with_mhe_uses_the_batched_mhe():
    assert {"mhe", "mhe-full"} <= set(batched_names())
    envs = gym.make_vec("fricenv/Braking-v0", num_envs=2, vectorization_mode="vector_entry_point",
                        estimator="mhe-full", road="wet")
    assert isinstance(envs, BatchedEstimatorObservation)
    assert envs.batched.t.model.estimated == ("theta", "B", "C", "E")
