"""RecordVideo works on the headless rgb_array render of every env."""

import gymnasium as gym
import pytest
from gymnasium.wrappers import RecordVideo

import fricenv  # noqa: F401  (registers the envs)


@pytest.mark.parametrize("env_id", ["fricenv/Braking-v0", "fricenv/PayloadExcitation-v0"])
def test_record_video_writes_an_mp4(tmp_path, env_id):
    env = RecordVideo(gym.make(env_id, render_mode="rgb_array"), video_folder=str(tmp_path / "videos"),
                      episode_trigger=lambda episode: True, disable_logger=True)
    env.reset(seed=0)
    for _ in range(20):
        env.step(env.action_space.sample())
    env.close()
    videos = list((tmp_path / "videos").glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000
