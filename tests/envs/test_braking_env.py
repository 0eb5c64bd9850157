"""fricenv/Braking-v0 and its batched core: API contracts, determinism, physics figures, bad input."""

import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import fricenv  # noqa: F401  (registers the envs)
from fricenv.envs.braking import BrakingEnv
from fricenv.envs.braking_sim import BrakingSim
from fricenv.envs.config import BrakingConfig, observation_layout
from fricenv.envs.scenario import limit_distance
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import DRY, ICE, ROADS
from tests.reference import stopping_distance_radau

P = qc.PAPER_PARAMS
G = P.g

ENV_KWARGS = [{}, {"observation": "oracle"}, {"action_mode": "torque_rate"}, {"road": "dry->ice"},
              {"road": "random", "v0": (10.0, 30.0)}]


def _run(env, actions, seed):
    """Observations, rewards and infos of an episode under a fixed action sequence (stops early if done)."""
    obs, info = env.reset(seed=seed)
    out = [(obs, 0.0, info)]
    for a in actions:
        obs, r, term, trunc, info = env.step(np.array([a], dtype=np.float32))
        out.append((obs, r, info))
        if term or trunc:
            break
    return out


def _constant(env, a, seed=0, options=None):
    """Run to the end under a constant action; returns (final info, rewards)."""
    env.reset(seed=seed, options=options)
    rewards = []
    while True:
        _, r, term, trunc, info = env.step(np.array([a], dtype=np.float32))
        rewards.append(r)
        if term or trunc:
            return info, np.array(rewards)


@pytest.mark.parametrize("kwargs", ENV_KWARGS, ids=str)
def test_gymnasium_and_sb3_env_checkers_pass(kwargs):
    env = gym.make("fricenv/Braking-v0", **kwargs)
    gym_check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(BrakingEnv(**kwargs), warn=True)


def test_registered_under_namespace_with_spaces():
    env = gym.make("fricenv/Braking-v0")
    assert env.spec.id == "fricenv/Braking-v0"
    assert env.action_space.shape == (1,) and env.action_space.dtype == np.float32
    assert env.observation_space.shape == (4,) and env.observation_space.dtype == np.float32
    assert np.all(np.isfinite(env.observation_space.low)) and np.all(np.isfinite(env.observation_space.high))
    assert env.unwrapped.observation_names == ("wheel_speed", "wheel_decel", "torque", "a_x")
    oracle = gym.make("fricenv/Braking-v0", observation="oracle")
    assert oracle.unwrapped.observation_names[4:] == ("v", "slip", "mu")


def test_same_seed_same_trajectory_and_other_seed_differs():
    actions = np.random.default_rng(0).uniform(-1, 1, 150)
    env = gym.make("fricenv/Braking-v0", road="random", v0=(15.0, 25.0))
    a, b = _run(env, actions, seed=7), _run(env, actions, seed=7)
    assert len(a) == len(b)
    for (oa, ra, ia), (ob, rb, ib) in zip(a, b):
        np.testing.assert_array_equal(oa, ob)
        assert ra == rb and ia == ib
    c = _run(env, actions, seed=8)
    assert not np.array_equal(a[1][0], c[1][0])


def test_initial_state_is_free_rolling_and_measurements_have_paper_noise():
    env = BrakingEnv(v0=20.0)
    env.reset(seed=0)
    omega = 20.0 / P.r
    err = []
    for _ in range(2000):  # zero torque: free rolling, omega stays v0 / r
        obs, *_ , info = env.step(np.array([-1.0], dtype=np.float32))
        err.append(env.decode_observation(obs)["wheel_speed"] - omega)
    assert info["v"] == pytest.approx(20.0, abs=1e-9) and abs(info["slip"]) < 1e-9
    assert np.var(err) == pytest.approx(0.2, rel=0.1)  # Sui & Johansen: variance 0.2 (rad/s)^2
    assert abs(np.mean(err)) < 0.05


def test_locked_wheel_ratio_and_info_at_episode_end():
    env = BrakingEnv(road="dry")
    info, _ = _constant(env, 1.0)
    assert info["limit_distance"] == pytest.approx((20.0**2 - 2.0**2) / (2 * G * DRY.mu_max), rel=1e-12)
    assert info["limit_distance"] == pytest.approx(20.18, abs=0.01)
    # Locked from the first steps the car slides at mu(1) = 0.788: about mu_max / mu(1) = 1.27 times the limit.
    assert 1.24 < info["ratio"] < 1.29
    assert info["ratio"] == pytest.approx(info["stopping_distance"] / info["limit_distance"], rel=1e-12)
    assert info["lock_seen"] and info["stopped"]
    for key in ("v", "slip", "mu", "distance", "road"):
        assert key in info


def test_stopping_distance_matches_radau_reference():
    torque = 0.8 * DRY.mu_max * P.Fz * P.r  # below the peak: a steady stop
    env = BrakingEnv(road="dry")
    info, _ = _constant(env, 2.0 * torque / env.config.t_max - 1.0)
    ref, _ = stopping_distance_radau(DRY, lambda t: torque)
    assert info["stopping_distance"] == pytest.approx(ref, rel=1e-3)


def test_return_is_one_minus_ratio_without_lock():
    # Below the peak the wheel never locks: the efficiency rewards telescope to 1 - d_stop / L.
    env = BrakingEnv(road="wet")
    info, rewards = _constant(env, 2.0 * 0.7 * 0.82 * P.Fz * P.r / env.config.t_max - 1.0)
    assert not info["lock_seen"]
    assert np.all(rewards <= 1e-12)
    assert rewards.sum() == pytest.approx(1.0 - info["ratio"], abs=1e-9)


def test_lock_is_penalised_per_step():
    env = BrakingEnv(road="dry", lock_penalty=0.5)
    env.reset(seed=0)
    total, locked_steps = 0.0, 0
    while True:
        _, r, term, trunc, info = env.step(np.array([1.0], dtype=np.float32))
        total += r
        locked_steps += info["locked"]
        if term or trunc:
            break
    # Locked after more than 0.1 s of omega r < 0.05 v: the wheel locks within a few steps of full torque.
    assert 200 < locked_steps < 230
    assert total == pytest.approx(1.0 - info["ratio"] - 0.5 * locked_steps, abs=1e-9)


def test_piecewise_limit_over_a_friction_change():
    # dry -> ice at 15 m: the dry limit stop (20.18 m) is not over at 15 m; v^2 there is 400 - 2 g 15.
    vd2 = 20.0**2 - 2 * G * DRY.mu_max * 15.0
    expected = 15.0 + (vd2 - 4.0) / (2 * G * ICE.mu_max)
    assert limit_distance(20.0, 2.0, DRY.mu_max, ICE.mu_max, 15.0) == pytest.approx(expected, rel=1e-12)
    # A change beyond the single-road limit distance does not matter.
    assert limit_distance(20.0, 2.0, DRY.mu_max, ICE.mu_max, 25.0) == pytest.approx(20.18, abs=0.01)
    env = BrakingEnv(road="dry->ice", change_distance=15.0)
    env.reset(seed=0)
    while True:
        *_, info = env.step(np.array([-0.3], dtype=np.float32))
        if info["distance"] > 15.5:
            break
    assert info["road"] == "dry->ice"
    assert abs(info["mu"]) <= ICE.mu_max + 1e-12  # on ice now
    assert env.road.name == "ice"


def test_custom_change_distance_via_reset_options():
    env = BrakingEnv(road="ice->dry")
    info, _ = _constant(env, 1.0, options={"change_distance": 40.0, "v0": 25.0})
    vd2 = 25.0**2 - 2 * G * ICE.mu_max * 40.0
    assert info["limit_distance"] == pytest.approx(40.0 + (vd2 - 4.0) / (2 * G * DRY.mu_max), rel=1e-12)
    assert info["v0"] == 25.0


def test_random_road_draws_every_preset():
    env = BrakingEnv(road="random")
    names = {env.reset(seed=s)[1]["road"] for s in range(40)}
    assert names == set(ROADS)


def test_out_of_range_action_is_clipped():
    env = BrakingEnv()
    env.reset(seed=3)
    a = env.step(np.array([7.5], dtype=np.float32))
    env.reset(seed=3)
    b = env.step(np.array([1.0], dtype=np.float32))
    np.testing.assert_array_equal(a[0], b[0])
    assert a[4]["torque"] == env.config.t_max


def test_torque_rate_mode_integrates_the_command():
    env = BrakingEnv(action_mode="torque_rate")
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([1.0], dtype=np.float32))
    assert info["torque"] == pytest.approx(25000.0 * 0.01)
    _, _, _, _, info = env.step(np.array([-0.4], dtype=np.float32))
    assert info["torque"] == pytest.approx(250.0 - 100.0)
    _, _, _, _, info = env.step(np.array([-1.0], dtype=np.float32))
    assert info["torque"] == 0.0  # kept in [0, t_max]


@pytest.mark.parametrize("action, match", [
    ([np.nan], "finite"),
    ([np.inf], "finite"),
    ([0.1, 0.2], "shape"),
    ([[0.1]], "shape"),
    (0.5, "shape"),
])
def test_bad_action_raises_value_error_naming_the_problem(action, match):
    env = BrakingEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=match):
        env.step(np.array(action, dtype=np.float32))


def test_bad_roads_and_options_list_the_valid_ones():
    with pytest.raises(ValueError, match="valid: dry, wet, snow, ice"):
        BrakingEnv(road="gravel")
    with pytest.raises(ValueError, match="dry->ice"):
        BrakingEnv(road="dry->gravel")
    with pytest.raises(ValueError, match="torque, torque_rate"):
        BrakingEnv(action_mode="pressure")
    with pytest.raises(ValueError, match="default, oracle"):
        BrakingEnv(observation="perfect")
    with pytest.raises(ValueError, match="rgb_array"):
        BrakingEnv(render_mode="human")
    with pytest.raises(TypeError, match="friction"):
        BrakingEnv(friction=0.5)
    with pytest.raises(ValueError, match="physics_dt"):
        BrakingEnv(physics_dt=0.003)
    with pytest.raises(ValueError, match="v0"):
        BrakingEnv(v0=1.0)  # not above v_stop
    env = BrakingEnv()
    with pytest.raises(ValueError, match="road, v0, change_distance"):
        env.reset(seed=0, options={"mu": 0.3})
    with pytest.raises(ValueError, match="valid"):
        env.reset(seed=0, options={"road": "mud"})


def test_pickle_round_trip_continues_identically():
    env = BrakingEnv(road="wet")
    env.reset(seed=5)
    for _ in range(10):
        env.step(np.array([0.0], dtype=np.float32))
    clone = pickle.loads(pickle.dumps(env))
    for _ in range(20):
        a = env.step(np.array([0.1], dtype=np.float32))
        b = clone.step(np.array([0.1], dtype=np.float32))
        np.testing.assert_array_equal(a[0], b[0])
        assert a[1:] == b[1:]


def test_subproc_vec_env_round_trip():
    from stable_baselines3.common.vec_env import SubprocVecEnv

    vec = SubprocVecEnv([lambda: BrakingEnv(road="dry"), lambda: BrakingEnv(road="ice")], start_method="fork")
    try:
        vec.seed(3)
        obs = vec.reset()
        assert obs.shape == (2, 4)
        for _ in range(5):
            obs, rewards, _, infos = vec.step(np.full((2, 1), 0.2, dtype=np.float32))
        assert obs.shape == (2, 4) and rewards.shape == (2,)
        assert [i["road"] for i in infos] == ["dry", "ice"]
    finally:
        vec.close()


def test_rgb_array_render_is_an_image():
    env = gym.make("fricenv/Braking-v0", render_mode="rgb_array")
    env.reset(seed=0)
    for _ in range(30):
        env.step(np.array([0.0], dtype=np.float32))
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    assert frame.shape[0] > 100 and frame.shape[1] > 100
    assert frame.std() > 0  # something was drawn
    env.close()


def test_batched_core_equals_single_runs():
    roads = ["dry", "wet", "snow", "ice", "dry->ice", "random"]
    n, steps = len(roads), 300
    acts = np.random.default_rng(1).uniform(-1.2, 1.2, (steps, n))
    cfg = BrakingConfig(observation="oracle")
    sim = BrakingSim(n, cfg)
    sim.reset_cars(None, [np.random.default_rng(10 + i) for i in range(n)], [{"road": r} for r in roads])
    batch = []
    for k in range(steps):
        o, r, te, _ = sim.step(acts[k])
        batch.append((o.copy(), r.copy(), te.copy()))  # step returns internal buffers
    for i in range(n):
        single = BrakingSim(1, cfg)
        single.reset_cars(None, [np.random.default_rng(10 + i)], {"road": roads[i]})
        for k in range(steps):
            o, r, te, _ = single.step(acts[k, i:i + 1])
            np.testing.assert_array_equal(o[0], batch[k][0][i])
            assert r[0] == batch[k][1][i] and te[0] == batch[k][2][i]


def test_resetting_one_car_leaves_the_others_alone():
    cfg = BrakingConfig()
    a = BrakingSim(3, cfg, road="wet")
    b = BrakingSim(3, cfg, road="wet")
    for sim in (a, b):
        sim.reset_cars(None, [np.random.default_rng(s) for s in range(3)])
    for k in range(40):
        oa = a.step(np.full(3, 0.1))[0].copy()
        if k == 20:
            b.reset_cars([1], [np.random.default_rng(99)], {"road": "ice"})
        ob = b.step(np.full(3, 0.1))[0]
        np.testing.assert_array_equal(oa[[0, 2]], ob[[0, 2]])
    assert b.names == ["wet", "ice", "wet"]


def test_core_rejects_bad_config_and_actions():
    with pytest.raises(ValueError, match="divide"):
        BrakingConfig(physics_dt=0.004)
    sim = BrakingSim(2, BrakingConfig())
    sim.reset_cars(None, [np.random.default_rng(0), np.random.default_rng(1)])
    with pytest.raises(ValueError, match="shape"):
        sim.step(np.zeros(3))
    with pytest.raises(ValueError, match="NaN"):
        sim.step(np.array([0.0, np.nan]))
    with pytest.raises(ValueError, match="one generator per reset car"):
        sim.reset_cars([0, 1], [np.random.default_rng(0)])
    assert [f.name for f in observation_layout("oracle")][-3:] == ["v", "slip", "mu"]
