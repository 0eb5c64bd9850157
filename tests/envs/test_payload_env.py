"""fricenv/PayloadExcitation-v0 and the excitation policies: Gymnasium/SB3 contracts and calibration behaviour."""

import pickle

import gymnasium as gym
import numpy as np
import pytest

from agents.excitation import POLICIES, evaluate, make_policy, run_episode
from estimators.base import Health
from fricenv.envs.payload import PayloadExcitationEnv
from fricenv.plants import payload as pl

ENV_ID = "fricenv/PayloadExcitation-v0"


@pytest.mark.parametrize("estimator", [False, True])
def test_env_checkers(estimator):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(ENV_ID, estimator=estimator)
    check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(PayloadExcitationEnv(estimator=estimator))
    n_obs = env.observation_space.shape[0]
    assert n_obs == (22 if estimator else 12)


def test_seeding_is_deterministic():
    def roll(seed):
        env = PayloadExcitationEnv(estimator=True)
        obs, _ = env.reset(seed=seed)
        out = [obs]
        for k in range(30):
            obs, r, *_ = env.step(np.array([0.3, -0.2, 0.1 * np.sin(k)], dtype=np.float32))
            out.append(np.append(obs, r))
        return np.concatenate(out)

    np.testing.assert_array_equal(roll(3), roll(3))
    assert not np.array_equal(roll(3), roll(4))


def test_pickle_round_trip_continues_identically():
    env = PayloadExcitationEnv(estimator=True, render_mode="rgb_array")
    env.reset(seed=1)
    for _ in range(10):
        env.step(np.array([0.5, 0.1, -0.1]))
    env.render()
    clone = pickle.loads(pickle.dumps(env))
    for _ in range(10):
        a = np.array([0.2, -0.3, 0.4])
        o1, r1, *_ = env.step(a)
        o2, r2, *_ = clone.step(a)
        np.testing.assert_array_equal(o1, o2)
        assert r1 == r2


def test_bad_actions_and_options():
    env = PayloadExcitationEnv()
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros(3))
    env.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan, 0.0, 0.0]))
    with pytest.raises(ValueError, match="shape \\(3,\\)"):
        env.step(np.zeros(2))
    with pytest.raises(ValueError, match="numeric"):
        env.step(np.array(["a", "b", "c"]))
    obs, *_ = env.step(np.array([5.0, -5.0, 0.5]))  # clipped, as Gymnasium users expect
    last = env.decode_observation(obs)
    assert (last["last_M"], last["last_fx"], last["last_fy"]) == pytest.approx((1.0, -1.0, 0.5))
    with pytest.raises(ValueError, match="valid: calibration"):
        env.reset(options={"road": "dry"})
    with pytest.raises(ValueError, match="paper, random"):
        env.reset(options={"calibration": "factory"})
    with pytest.raises(ValueError, match="valid: False, True, 'rls'"):
        PayloadExcitationEnv(estimator="ekf")
    with pytest.raises(ValueError, match="noise_scale"):
        PayloadExcitationEnv(noise_scale=-1.0)
    with pytest.raises(TypeError):
        PayloadExcitationEnv(bogus=1)
    with pytest.raises(ValueError, match="unknown policy"):
        make_policy("chirp", env)


def test_info_reward_and_estimate_observation():
    env = PayloadExcitationEnv(estimator=True, effort_weight=0.0)
    obs, info = env.reset(seed=2, options={"calibration": "random"})
    S = info["S"]
    assert np.all(np.abs(S) <= 3) and np.linalg.cond(S) <= 10
    E0 = info["E"]
    assert E0 == pytest.approx(float(pl.calibration_error(np.eye(3), S)))
    policy = make_policy("prbs", env, seed=2)
    policy.reset(2)
    total = 0.0
    for _ in range(200):
        obs, r, term, _, info = env.step(policy.act(obs))
        total += r
    assert not term
    # the calibration rewards telescope to the decades gained
    assert total == pytest.approx(np.log10(E0) - np.log10(info["E"]), rel=1e-9)
    assert info["E"] == pytest.approx(float(pl.calibration_error(info["S_hat"], S)))
    decoded = env.decode_observation(obs)
    S_obs = np.array([decoded[f"S_hat_{i}{j}"] for i in (1, 2, 3) for j in (1, 2, 3)]).reshape(3, 3)
    np.testing.assert_allclose(S_obs, np.clip(info["S_hat"], -10, 10), rtol=1e-6, atol=1e-6)
    assert decoded["excitation"] == pytest.approx(np.log10(1 + info["excitation"]), rel=1e-5)


def test_workspace_termination_and_truncation():
    env = PayloadExcitationEnv(effort_weight=0.0)
    env.reset(seed=0)
    for _ in range(1000):
        _, r, term, trunc, info = env.step(np.array([0.0, 1.0, 0.0]))
        if term or trunc:
            break
    assert term and not trunc and info["out_of_workspace"]
    assert r < -4.0  # the workspace penalty (5) dominates the step
    env = PayloadExcitationEnv(time_limit=0.2)
    env.reset(seed=0)
    flags = [env.step(np.zeros(3))[3] for _ in range(10)]
    assert flags == [False] * 9 + [True]


def test_render_rgb_array():
    env = PayloadExcitationEnv(render_mode="rgb_array")
    env.reset(seed=0)
    env.step(np.array([0.2, 0.3, -0.1]))
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert frame.std() > 0
    with pytest.warns(UserWarning):
        assert PayloadExcitationEnv().render() is None


def test_policies_calibrate_and_zero_does_not():
    env = PayloadExcitationEnv()
    ms = run_episode(env, make_policy("multisine", env), seed=0)
    assert not ms.left_workspace and ms.t[-1] == pytest.approx(20.0)
    assert ms.E_end < 1e-2 and ms.t_below is not None and ms.t_below < 10.0
    zero = run_episode(env, make_policy("zero", env), seed=0)
    assert zero.t_below is None and zero.E_end > 0.5
    assert env.unwrapped._estimate.health == Health.NOT_EXCITED


def test_evaluate_reports_every_policy():
    rows = evaluate(("prbs", "zero"), episodes=1, seed=0, env_kwargs={"time_limit": 6.0})
    assert [r["policy"] for r in rows] == ["prbs", "zero"]
    assert rows[0]["t_below_1e-2"] is not None and rows[0]["E_end"] < 1e-2
    assert rows[1]["t_below_1e-2"] is None and rows[1]["effort"] == 0.0
    assert set(POLICIES) == {"multisine", "prbs", "zero"}
