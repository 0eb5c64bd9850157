"""The native vector env with a batched estimator equals single envs wrapped in EstimatorObservation."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import fricenv  # noqa: F401  (registers the envs)
from fricenv.envs.braking_vector import BrakingVectorEnv
from fricenv.envs.estimator_observation import BatchedEstimatorObservation, EstimatorObservation
from fricenv.envs.factory import make_braking
from tests.envs.test_braking_vector import OBS_TOL, ROADS_PER_ENV, SHORT_V0, _compare_with_single_envs


def _lockstep(ours, ref, seed: int | None, steps: int) -> list[dict]:
    """Step two SB3 vec envs with the same random actions; their observations and terminal observations agree.

    :return: the final infos of the episodes that ended (ours).
    """
    if seed is not None:
        ours.seed(seed)
        ref.seed(seed)
    np.testing.assert_allclose(ours.reset(), ref.reset(), atol=OBS_TOL)
    rng = np.random.default_rng(1)
    ended = []
    for _ in range(steps):
        act = rng.uniform(-1.0, 0.4, (ours.num_envs, 1)).astype(np.float32)
        o1, _, d1, i1 = ours.step(act)
        o2, _, d2, i2 = ref.step(act)
        np.testing.assert_allclose(o1, o2, atol=OBS_TOL)
        np.testing.assert_array_equal(d1, d2)
        for i in np.flatnonzero(d1):
            np.testing.assert_allclose(i1[i]["terminal_observation"], i2[i]["terminal_observation"], atol=OBS_TOL)
            ended.append(i1[i])
    return ended


@pytest.mark.parametrize("same_step, estimator", [(False, "ekf-rls"), (True, "ekf-rls"), (False, "mhe"),
                                                  pytest.param(True, "mhe", marks=pytest.mark.slow)])
def test_batched_estimator_vector_env_equals_wrapped_single_envs(same_step, estimator):
    kw = {"v0": SHORT_V0, "change_distance": (0.5, 2.0)}
    mode = "SameStep" if same_step else "NextStep"
    venv = BatchedEstimatorObservation(BrakingVectorEnv(4, road=ROADS_PER_ENV, autoreset_mode=mode, **kw),
                                       estimator)
    singles = [make_braking(estimator, road=r, **kw) for r in ROADS_PER_ENV]
    assert venv.observation_fields == singles[0].observation_fields
    assert venv.single_observation_space == singles[0].observation_space
    ended, _ = _compare_with_single_envs(venv, singles, seed=5, steps=300, same_step=same_step)
    assert ended >= 8


def test_make_vec_uses_the_batched_estimator_and_sb3_adapter_matches_dummy_vec_env():
    from stable_baselines3.common.vec_env import DummyVecEnv

    from fricenv.envs.sb3_vec import BrakingSB3VecEnv

    envs = gym.make_vec("fricenv/Braking-v0", num_envs=3, vectorization_mode="vector_entry_point",
                        estimator="ekf-rls", road="wet")
    assert isinstance(envs, BatchedEstimatorObservation)
    kw = {"v0": SHORT_V0, "road": "ice->dry", "change_distance": 1.0}
    ours = BrakingSB3VecEnv(3, estimator="ekf-rls", **kw)
    ref = DummyVecEnv([lambda: make_braking("ekf-rls", **kw) for _ in range(3)])
    assert len(_lockstep(ours, ref, seed=4, steps=200)) >= 6


def test_batched_wrapper_refuses_an_estimator_without_batched_form():
    with pytest.raises(ValueError, match="no batched form"):
        BatchedEstimatorObservation(BrakingVectorEnv(2), "oracle")
    assert isinstance(make_braking("oracle"), EstimatorObservation)


def test_native_training_env_draws_the_scenarios_of_scenario_mix():
    from stable_baselines3.common.vec_env import DummyVecEnv

    from agents.training import SEED_STRIDE, ScenarioSampler, make_env_fn
    from fricenv.envs.sb3_vec import make_sb3_vec_env

    ours = make_sb3_vec_env(3, monitor=False, estimator="ekf-rls",
                            scenarios=ScenarioSampler(change_probability=0.5, v0_range=SHORT_V0))
    ref = DummyVecEnv([make_env_fn("braking", "ekf-rls", i) for i in range(3)])
    for e in ref.envs:  # the same short stops as ours (ScenarioMix is the Monitor's inner env)
        e.env.sampler = ScenarioSampler(change_probability=0.5, v0_range=SHORT_V0)
    ours.seed(2 * SEED_STRIDE)
    ref.seed(2 * SEED_STRIDE)
    roads = {info["road"] for info in _lockstep(ours, ref, seed=None, steps=300)}
    assert any("->" in r for r in roads) and any("->" not in r for r in roads)
