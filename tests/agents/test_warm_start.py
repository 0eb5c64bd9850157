"""A training run started from another (``fricenv train --init RUN``): the source's weights and normalisation
statistics are loaded, the run records its source, and a run the source does not fit is refused before training."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest
import torch

from agents.training import PPOConfig, make_training_model, train
from agents.warm_start import check_warm_start, warm_start

pytestmark = pytest.mark.filterwarnings("ignore:tensorboard is not installed")

TINY_PPO = PPOConfig(n_envs=2, n_steps=128, batch_size=64, n_epochs=2)


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    out = tmp_path_factory.mktemp("source")
    train(out, estimator="ekf-rls", algo="ppo", steps=256, seed=3, config=TINY_PPO, progress_bar=False,
          checkpoint_every=0)
    return out


def test_warm_start_loads_the_source_weights_and_statistics(source):
    from stable_baselines3 import PPO

    model = make_training_model("braking", "ekf-rls", "ppo", TINY_PPO, seed=5, vec="native")
    fresh = {k: v.clone() for k, v in model.policy.state_dict().items()}
    warm_start(model, source)
    theirs = PPO.load(str(source / "model.zip"), device="cpu").policy.state_dict()
    ours = model.policy.state_dict()
    assert any(not torch.equal(fresh[k], theirs[k]) for k in theirs)  # a fresh network differs from the source
    assert all(torch.equal(ours[k], theirs[k]) for k in theirs)
    with open(source / "vecnormalize.pkl", "rb") as fh:
        stats = pickle.load(fh)
    venv = model.get_env()
    np.testing.assert_array_equal(venv.obs_rms.mean, stats.obs_rms.mean)
    np.testing.assert_array_equal(venv.obs_rms.var, stats.obs_rms.var)
    assert venv.obs_rms.count == stats.obs_rms.count > 0


def test_a_source_of_another_observation_is_refused_before_its_weights_load(source):
    model = make_training_model("braking", "none", "ppo", TINY_PPO, seed=5, vec="native")
    with pytest.raises(ValueError, match=r"observation statistics of shape \(\d+,\), this run's observation has "
                                         r"shape \(\d+,\)"):
        warm_start(model, source)


def test_a_warm_started_run_names_its_source(source, tmp_path):
    result = train(tmp_path / "tuned", estimator="ekf-rls", algo="ppo", steps=256, seed=4, config=TINY_PPO,
                   progress_bar=False, checkpoint_every=0, init=source,
                   env_kwargs={"effects_randomization": {"brake_lag": {"tau": [0.001, 0.08]}}})
    meta = json.loads((tmp_path / "tuned" / "train.json").read_text())
    assert meta["init"] == {"run": str(source), "steps": 256, "env_kwargs": {}}
    assert result.steps == 256


@pytest.mark.parametrize("settings, message", [
    ({"estimator": "ekf"}, "estimator 'ekf-rls', this run 'ekf'"),
    ({"algo": "sac"}, "algo 'ppo', this run 'sac'"),
    ({"frame_stack": 4}, "frame_stack 0, this run 4"),
    ({"net_arch": [32, 32]}, "net_arch"),
])
def test_a_source_that_does_not_fit_is_refused(source, settings, message):
    args = {"env": "braking", "estimator": "ekf-rls", "algo": "ppo", "frame_stack": 0, "net_arch": [64, 64],
            **settings}
    with pytest.raises(ValueError, match=message):
        check_warm_start(source, **args)


def test_cli_refuses_a_missing_init_run_before_training(tmp_path, capsys):
    from fricenv.cli import main

    assert main(["train", "--estimator", "ekf-rls", "--steps", "64", "--init", str(tmp_path / "nowhere"),
                 "--out", str(tmp_path / "run"), "--no-progress"]) != 0
    err = capsys.readouterr().err
    assert "--init" in err and "train.json is missing" in err
    assert not (tmp_path / "run").exists()
