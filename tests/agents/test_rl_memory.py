"""Reproducible training and the memory baselines (frame stack, RecurrentPPO), on short runs."""

from __future__ import annotations

import numpy as np
import pytest

from agents.training import PPOConfig, load_policy, train
from fricenv.envs.factory import make_braking

TINY = PPOConfig(n_envs=4, n_steps=32, batch_size=64, n_epochs=2, net_arch=(16, 16))


def _params(run) -> dict:
    return {k: v.detach().numpy().copy() for k, v in load_policy(run.out).model.policy.state_dict().items()}


@pytest.mark.parametrize("estimator", ["none", "ekf-rls"])
def test_same_seed_gives_the_same_policy(tmp_path, estimator):
    runs = [train(tmp_path / f"r{i}", estimator=estimator, steps=256, seed=s, config=TINY, progress_bar=False,
                  checkpoint_every=0) for i, s in enumerate((7, 7, 8))]
    assert runs[0].meta["vec"] == "native"
    a, b, c = (_params(r) for r in runs)
    assert all(np.array_equal(a[k], b[k]) for k in a)  # same seed: bit for bit
    assert not all(np.array_equal(a[k], c[k]) for k in a)  # another seed: another policy


@pytest.mark.parametrize("algo, frame_stack", [("ppo", 3), ("recurrent-ppo", 0)])
def test_memory_baselines_train_and_act_with_memory(tmp_path, algo, frame_stack):
    run = train(tmp_path, estimator="none", algo=algo, steps=256, seed=0, config=TINY, progress_bar=False,
                checkpoint_every=0, frame_stack=frame_stack)
    policy = load_policy(run.out)
    env = make_braking("none", road="wet", v0=20.0)
    obs, _ = env.reset(seed=0)
    policy.reset()
    first = policy.act(obs)
    assert first.shape == (1,) and np.all(np.abs(first) <= 1.0 + 1e-6)
    if frame_stack:
        assert policy._stack.shape == (frame_stack * obs.size,)
        np.testing.assert_array_equal(policy._stack[-obs.size:], obs)
        assert not policy._stack[:-obs.size].any()  # zeros before the first observation, as VecFrameStack
    else:
        assert policy._state is not None  # the LSTM state is carried to the next step
    policy.reset()
    np.testing.assert_array_equal(policy.act(obs), first)  # reset forgets the memory


def test_bad_frame_stack_is_rejected(tmp_path):
    with pytest.raises(ValueError, match="frame_stack"):
        train(tmp_path, steps=64, config=TINY, frame_stack=-1, progress_bar=False)


def test_recurrent_ppo_has_ppo_hyperparameters_and_a_small_lstm():
    import dataclasses

    from agents.training import DEFAULT_CONFIGS, RecurrentPPOConfig

    rec, ppo = DEFAULT_CONFIGS[("braking", "recurrent-ppo")], DEFAULT_CONFIGS[("braking", "ppo")]
    assert isinstance(rec, RecurrentPPOConfig)
    assert {k: v for k, v in dataclasses.asdict(rec).items() if k in dataclasses.asdict(ppo)} == \
        dataclasses.asdict(ppo)
    assert rec.lstm_hidden_size == 32 and not rec.enable_critic_lstm and not rec.shared_lstm
