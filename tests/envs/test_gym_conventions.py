"""Gymnasium and SB3 conventions on every registered ``fricenv/`` id."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.utils.env_match import check_environments_match
from gymnasium.wrappers import TimeAwareObservation

import fricenv  # noqa: F401  (registers the envs)
from fricenv.envs import ENV_IDS
from fricenv.envs.sb3_vec import BrakingSB3VecEnv
from tests.envs.test_record_video import assert_one_video

SHORT = 0.3  # time limit [s] that truncates every episode of the tests below


def _short_kwargs(env_id: str) -> dict:
    """Keyword arguments giving short episodes that end by truncation."""
    if "Braking" in env_id:
        return {"time_limit": SHORT, "v0": 20.0}
    return {"time_limit": SHORT}


def _own_max_steps(env: gym.Env) -> int:
    base = env.unwrapped
    return base.config.max_steps if hasattr(base, "config") else base.max_steps


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_max_episode_steps_is_the_envs_own_truncation(env_id):
    env = gym.make(env_id)
    assert env.spec.max_episode_steps == _own_max_steps(env) > 0


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_check_env_and_environments_match_through_truncation(env_id):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        check_env(gym.make(env_id).unwrapped if "Braking-v0" in env_id else gym.make(env_id),
                  skip_render_check=True)
    kw = _short_kwargs(env_id)
    env = gym.make(env_id, **kw)
    env.reset(seed=0)
    truncated = terminated = False
    while not (truncated or terminated):
        *_, terminated, truncated, info = env.step(np.zeros(env.action_space.shape, env.action_space.dtype))
    assert truncated and not terminated
    assert not any(isinstance(v, float) and math.isnan(v) for v in info.values())  # no NaN in the final info
    if "stopping_distance" in info:
        assert info["stopping_distance"] is None and info["ratio"] is None and info["stopped"] is False
    check_environments_match(gym.make(env_id, **kw), gym.make(env_id, **kw), num_steps=3 * round(SHORT / 0.01),
                             seed=1, skip_render=True)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_time_aware_observation_and_time_feature_wrapper(env_id):
    from sb3_contrib.common.wrappers import TimeFeatureWrapper

    env = TimeAwareObservation(gym.make(env_id), normalize_time=True)  # needs spec.max_episode_steps
    obs, _ = env.reset(seed=0)
    for _ in range(3):
        obs, *_ = env.step(env.action_space.sample())
    assert obs[-1] == pytest.approx(3 / env.spec.max_episode_steps)
    assert env.observation_space.contains(obs)
    tf = TimeFeatureWrapper(gym.make(env_id, **_short_kwargs(env_id)))
    obs, _ = tf.reset(seed=0)
    done = False
    while not done:
        assert tf.observation_space.contains(obs)
        obs, _, te, tr, _ = tf.step(tf.action_space.sample())
        done = te or tr
    assert tf.observation_space.contains(obs)
    assert tf._max_steps == gym.make(env_id).spec.max_episode_steps  # the spec's, not the 1000 guess


def test_vector_entry_point_takes_estimator_with_a_fallback_and_keeps_native_otherwise():
    with pytest.warns(UserWarning, match="SyncVectorEnv"):
        venv = gym.make_vec("fricenv/Braking-v0", 2, estimator="ekf")
    obs, _ = venv.reset(seed=0)
    single = gym.make("fricenv/Braking-v0", estimator="ekf")
    np.testing.assert_array_equal(obs[1], single.reset(seed=1)[0])
    assert obs.shape == (2, *single.observation_space.shape)
    native = gym.make_vec("fricenv/Braking-v0", 2, time_limit=0.5)
    assert type(native).__name__ == "BrakingVectorEnv" and native.unwrapped.config.time_limit == 0.5


def test_sb3_vec_env_has_a_spec_and_records_video(tmp_path):
    from stable_baselines3.common.vec_env import VecVideoRecorder

    venv = BrakingSB3VecEnv(3, render_mode="rgb_array", v0=4.0)
    assert venv.spec.id == "fricenv/Braking-v0" and venv.spec.kwargs["v0"] == 4.0
    assert venv.spec.max_episode_steps == gym.spec("fricenv/Braking-v0").max_episode_steps
    rec = VecVideoRecorder(venv, str(tmp_path), record_video_trigger=lambda step: step == 0, video_length=30)
    rec.reset()
    for _ in range(40):
        rec.step(np.zeros((3, 1), dtype=np.float32))
    frame = venv.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    rec.close()
    assert_one_video(tmp_path)
    with pytest.raises(ValueError, match="render_mode"):
        BrakingSB3VecEnv(2, render_mode="human")
