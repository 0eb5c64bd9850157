"""The training signal: the policy's log torque map, the lock-onset penalty, the small LSTM."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.action_map import LOG_RANGE, ActionMapError, check_action_map, log_torque
from agents.lock_shaping import LockOnsetPenaltyVecEnv
from agents.training import PPOConfig, RecurrentPPOConfig, load_policy, make_training_model, train
from fricenv.envs.config import T_MAX
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import ICE

TINY = PPOConfig(n_envs=4, n_steps=32, batch_size=64, n_epochs=1, net_arch=(16, 16))


def _torque(a_env: np.ndarray) -> np.ndarray:
    return (a_env + 1.0) * 0.5 * T_MAX  # the env's linear map (Braking-v0, torque mode)


def test_log_map_ends_and_relative_resolution():
    assert log_torque(np.array([-1.0, 1.0, -3.0, 2.0])).tolist() == pytest.approx([-1.0, 1.0, -1.0, 1.0], abs=1e-15)
    a = np.linspace(-0.99, 0.99, 199)
    t = _torque(log_torque(a))
    assert np.all(np.diff(t) > 0)
    h = 1e-6
    slope = (_torque(log_torque(a + h)) - _torque(log_torque(a - h))) / (2 * h)
    np.testing.assert_allclose(slope, 0.5 * math.log(LOG_RANGE) * (t + T_MAX / (LOG_RANGE - 1)), rtol=1e-6)
    # ice's peak torque r F_z mu_max (110 N m) is mid-range, not 0.088 from the lower bound as with the linear map
    p = qc.PAPER_PARAMS
    u = math.log1p(p.r * p.Fz * ICE.mu_max / T_MAX * (LOG_RANGE - 1)) / math.log(LOG_RANGE)
    assert _torque(log_torque(np.array([2 * u - 1]))) == pytest.approx(p.r * p.Fz * ICE.mu_max, rel=1e-12)
    assert -0.3 < 2 * u - 1 < -0.2


def test_unknown_action_map_is_rejected():
    with pytest.raises(ActionMapError, match="unknown action_map 'cubic'; valid: linear, log"):
        check_action_map("cubic")
    with pytest.raises(ValueError, match="lock_onset_penalty"):
        train("unused", env="payload", estimator="none", steps=64, config=PPOConfig(action_map="log"),
              progress_bar=False)


def test_trained_policy_applies_its_action_map(tmp_path):
    cfg = PPOConfig(**{**TINY.__dict__, "action_map": "log"})
    run = train(tmp_path, steps=128, seed=0, config=cfg, progress_bar=False, checkpoint_every=0)
    policy = load_policy(run.out)
    obs = np.array([0.5, 0.1, 0.3, -0.4], dtype=np.float32)
    raw, _ = policy.model.predict(policy.vecnormalize.normalize_obs(obs), deterministic=True)
    np.testing.assert_allclose(policy.act(obs), log_torque(np.asarray(raw, dtype=float)), atol=1e-7)


@pytest.mark.parametrize("vec", ["native", "dummy"])
def test_lock_onset_is_penalised_from_its_first_step(vec):
    cfg = PPOConfig(**{**TINY.__dict__, "norm_reward": False})
    plain = make_training_model("braking", "none", "ppo", cfg, 3, vec).get_env()
    shaped_cfg = PPOConfig(**{**cfg.__dict__, "lock_onset_penalty": 0.25})
    shaped = make_training_model("braking", "none", "ppo", shaped_cfg, 3, vec).get_env()
    diffs = []
    for env in (plain, shaped):
        env.reset()
        rewards = []
        for _ in range(40):  # full torque: the wheel enters the lock condition within a few steps and stays
            env.step_async(np.ones((4, 1), dtype=np.float32))
            rewards.append(env.step_wait()[1])
        diffs.append(np.array(rewards))
    onset = (diffs[0] - diffs[1]) / 0.25
    np.testing.assert_allclose(onset, np.round(onset), atol=1e-12)  # 0 or 1 per step
    # every sub-env is penalised on exactly the lock_steps (10) steps before its lock counts, once
    np.testing.assert_array_equal(onset.sum(axis=0), np.full(4, 10.0))
    with pytest.raises(ValueError, match="onset_penalty"):
        LockOnsetPenaltyVecEnv(plain, -1.0)


def test_recurrent_config_sets_the_lstm(tmp_path):
    cfg = RecurrentPPOConfig(**{**TINY.__dict__, "lstm_hidden_size": 8, "enable_critic_lstm": False})
    run = train(tmp_path, algo="recurrent-ppo", steps=128, seed=0, config=cfg, progress_bar=False,
                checkpoint_every=0)
    policy = load_policy(run.out).model.policy
    assert policy.lstm_actor.hidden_size == 8
    assert policy.lstm_critic is None  # MLP critic
