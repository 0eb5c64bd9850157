"""A training run loads the standard way: PPO.load and VecNormalize.load on the env gym.make builds from the run's
env_kwargs.yml give the env the same commands as agents.training.load_policy; --steps rounds up to whole rollouts."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

import fricenv  # noqa: F401  (registers the envs)
from agents.run_files import rounded_steps
from agents.training import PPOConfig, SACConfig, load_policy, train
from fricenv.envs.action_map import ActionMapWrapper, log_torque

TINY = PPOConfig(n_envs=2, n_steps=32, batch_size=32, n_epochs=1, net_arch=(16, 16), action_map="log")


def _zoo_env(run: Path):
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    config = yaml.safe_load((run / "config.yml").read_text())
    kwargs = yaml.safe_load((run / "env_kwargs.yml").read_text())
    venv = DummyVecEnv([lambda: gym.make(config["env_id"], **kwargs)])
    venv = VecNormalize.load(str(run / "vecnormalize.pkl"), venv)
    venv.training, venv.norm_reward = False, False
    return config, kwargs, venv


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("run")
    train(out, estimator="ekf", steps=100, seed=0, config=TINY, progress_bar=False, checkpoint_every=0)
    return out


def test_run_leaves_the_rl_zoo_files(run_dir):
    config, kwargs, _ = _zoo_env(run_dir)
    assert (run_dir / "model.zip").is_file() and (run_dir / "vecnormalize.pkl").is_file()
    assert config["env_id"] == "fricenv/Braking-v0" and config["algo"] == "ppo"
    assert config["hyperparams"]["action_map"] == "log" and config["normalize"]["norm_obs"] is True
    assert kwargs == {"estimator": "ekf", "action_map": "log"}


def test_plain_sb3_gives_the_commands_of_load_policy(run_dir):
    from stable_baselines3 import PPO

    _, _, venv = _zoo_env(run_dir)
    model = PPO.load(str(run_dir / "model.zip"), device="cpu")
    policy = load_policy(run_dir)
    wrapper = venv.envs[0]
    while not isinstance(wrapper, ActionMapWrapper):
        wrapper = wrapper.env
    obs = venv.reset()
    commands, raw_actions = [], []
    for _ in range(120):
        action, _ = model.predict(obs, deterministic=True)
        raw_actions.append(float(action[0, 0]))
        command = wrapper.action(action[0])  # what the plant receives from plain SB3
        reference = policy.act(venv.get_original_obs()[0])  # what load_policy commands on the same observation
        np.testing.assert_allclose(command, reference, atol=1e-6)
        commands.append(float(command[0]))
        obs, _, done, _ = venv.step(action)
        if done[0]:
            break
    # the map is not the identity on these actions: without it in the env the commands would differ
    assert np.max(np.abs(np.array(commands) - np.clip(raw_actions, -1, 1))) > 0.05
    np.testing.assert_allclose(commands, log_torque(np.array(raw_actions)), atol=1e-6)


def test_steps_round_up_to_whole_rollouts(run_dir):
    config, _, _ = _zoo_env(run_dir)
    assert rounded_steps("ppo", TINY, 100) == 128 == config["n_timesteps"]
    assert rounded_steps("ppo", TINY, 128) == 128
    assert rounded_steps("sac", SACConfig(n_envs=4), 10) == 12


def test_cli_says_when_steps_round(tmp_path, capsys):
    import json

    from fricenv.cli import main

    hyper = tmp_path / "h.json"
    hyper.write_text(json.dumps({"ppo": {k: list(v) if isinstance(v, tuple) else v for k, v in TINY.__dict__.items()}}))
    code = main(["-q", "train", "--out", str(tmp_path / "r"), "--steps", "100", "--hyperparams", str(hyper),
                 "--no-progress"])
    err = capsys.readouterr().err
    assert code == 0
    assert "fricenv train: note: --steps 100 rounds up to 128 env steps" in err
    assert yaml.safe_load((tmp_path / "r" / "config.yml").read_text())["n_timesteps"] == 128


@pytest.mark.slow
def test_robust_training_switch_draws_the_grid_effects(tmp_path):
    import json

    from fricenv.cli import main
    from fricenv.effects.grid import grid_randomization

    hyper = tmp_path / "h.json"
    hyper.write_text(json.dumps({"ppo": {k: list(v) if isinstance(v, tuple) else v for k, v in TINY.__dict__.items()}}))
    run = tmp_path / "robust"
    assert main(["-q", "train", "--out", str(run), "--steps", "64", "--hyperparams", str(hyper),
                 "--effects-randomization", "grid", "--no-progress"]) == 0
    _, kwargs, venv = _zoo_env(run)
    expected = {e: {p: list(r) for p, r in ranges.items()} for e, ranges in grid_randomization().items()}
    assert kwargs["effects_randomization"] == expected
    plant = venv.envs[0].unwrapped.sim.plant
    venv.reset()
    assert {e.name for e in plant.effects[0]} == set(expected)  # the saved env draws the grid's effects too
