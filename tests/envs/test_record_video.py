"""RecordVideo works on the headless rgb_array render of every env, single and vector."""

import warnings
from pathlib import Path

import gymnasium as gym
import pytest
from gymnasium.wrappers import RecordVideo

import fricenv  # noqa: F401  (registers the envs)


def assert_one_video(folder: Path) -> None:
    """Exactly one non-trivial mp4 in ``folder``."""
    videos = list(Path(folder).glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000


def _record(env, steps: int = 25) -> None:
    env.reset(seed=0)
    for _ in range(steps):
        env.step(env.action_space.sample())
    env.close()


@pytest.mark.parametrize("env_id", ["fricenv/Braking-v0", "fricenv/PayloadExcitation-v0"])
def test_record_video_writes_an_mp4(tmp_path, env_id):
    _record(RecordVideo(gym.make(env_id, render_mode="rgb_array"), video_folder=str(tmp_path / "videos"),
                        episode_trigger=lambda episode: True, disable_logger=True), steps=20)
    assert_one_video(tmp_path / "videos")


@pytest.mark.parametrize("env_id", ["fricenv/Braking-v0", "fricenv/BrakingEKF-v0", "fricenv/PayloadExcitation-v0"])
def test_vector_record_video(tmp_path, env_id):
    """make_vec with render_mode (the Braking ids fall back to SyncVectorEnv, with a warning) and the vector
    RecordVideo."""
    from gymnasium.wrappers.vector import RecordVideo as VectorRecordVideo

    kw = {"v0": 3.0} if "Braking" in env_id else {"time_limit": 0.4}
    with pytest.warns(UserWarning, match="SyncVectorEnv") if "Braking" in env_id else warnings.catch_warnings():
        venv = gym.make_vec(env_id, 2, render_mode="rgb_array", **kw)
    assert isinstance(venv, gym.vector.SyncVectorEnv)
    _record(VectorRecordVideo(venv, str(tmp_path / "videos"), episode_trigger=lambda ep: ep == 0,
                              disable_logger=True))
    assert_one_video(tmp_path / "videos")
