"""Native vector env, SB3 adapter and compiled substeps of fricenv/Braking-v0.

Equivalence is the point: the vector env must be N single envs (same seeds, same trajectories, across autoresets),
and the compiled substeps must be the numpy ROS2 substep of ``quarter_car.step``.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import fricenv  # noqa: F401  (registers the envs)
from fricenv.envs.braking import BrakingEnv
from fricenv.envs.braking_sim import BrakingSim
from fricenv.envs.braking_vector import BrakingVectorEnv
from fricenv.envs.config import BrakingConfig
from fricenv.envs.episode import CAR_OUTPUTS, car_substeps_compiled, cars_substeps_compiled
from fricenv.plants import compiled, rosenbrock
from fricenv.plants import quarter_car as qc
from fricenv.plants.braking_plant import BatchPlant
from fricenv.plants.tire import ROADS

# Short stops so that a few hundred steps cover several episodes (autoresets) per sub-env.
SHORT_V0 = (4.0, 7.0)
ROADS_PER_ENV = ["dry", "ice", "random", "wet->snow"]
OBS_TOL = 1e-5  # float32 observations of the scalar (single env) and batched (vector env) paths
STATE_TOL = 1e-12  # float64 truth of the two paths, relative (compiled and numpy transcendentals may round apart)
P = qc.PAPER_PARAMS


def _random_states(n: int, seed: int):
    """Quarter-car states covering braking, traction, wheel lock-up within the substep and the slip floor."""
    rng = np.random.default_rng(seed)
    roads = np.array([r.as_array() for r in ROADS.values()])[rng.integers(len(ROADS), size=n)]
    v = rng.uniform(0.0, 40.0, n)
    v[:50] = rng.uniform(0.0, 0.15, 50)  # floored slip denominator
    w = v / qc.PAPER_PARAMS.r * rng.uniform(0.0, 1.3, n)  # > 1: traction slip
    w[50:100] = 0.0  # locked
    w[100:150] = rng.uniform(0.0, 0.3, 50)  # about to lock
    Tb = rng.uniform(-500.0, 3000.0, n)
    return v, w, Tb, roads


def test_compiled_substeps_equal_the_numpy_reference():
    """The env's compiled substep (all cars, and one car) against :func:`quarter_car.step` on numpy arrays."""
    v, w, Tb, roads = _random_states(3000, 1)
    h = 0.002
    ref_v, ref_w = qc.step(v, w, Tb, roads, h, qc.PAPER_PARAMS, 1)
    assert np.sum((ref_w == 0.0) & (w > 0.0)) > 20  # the lock event is exercised
    plant = BatchPlant(len(v), h)
    plant.set_road(slice(None), roads)
    plant.set_torque(Tb)
    plant.reset(slice(None), v, w)
    bv, bw = plant.substep()
    scale_v, scale_w = np.maximum(1.0, np.abs(ref_v)), np.maximum(1.0, np.abs(ref_w))
    assert np.max(np.abs(bv - ref_v) / scale_v) < 1e-12
    assert np.max(np.abs(bw - ref_w) / scale_w) < 1e-12
    # locked wheels cross omega = 0 in every substep
    locked = np.zeros_like(w)
    ref_lv, ref_lw = qc.step(v, locked, np.full_like(v, 3000.0), roads, h, qc.PAPER_PARAMS, 1)
    plant.set_torque(np.full_like(v, 3000.0))
    plant.reset(slice(None), v, locked)
    lv, lw = plant.substep()
    assert np.max(np.abs(lv - ref_lv) / np.maximum(1.0, np.abs(ref_lv))) < 1e-12
    assert np.max(np.abs(lw - ref_lw) / np.maximum(1.0, np.abs(ref_lw))) < 1e-12
    assert np.mean(lw == 0.0) > 0.9  # most stayed locked (crossed zero again)
    p = qc.PAPER_PARAMS
    one = np.array([compiled.substep_refined(v[i], w[i], Tb[i], *roads[i], plant.road[i, 4], h, p.r, p.m, p.J, p.Fz)
                    for i in range(len(v))])
    assert np.max(np.abs(one[:, 0] - ref_v) / scale_v) < 1e-12
    assert np.max(np.abs(one[:, 1] - ref_w) / scale_w) < 1e-12


def test_batched_compiled_substeps_are_the_one_car_substeps():
    """The batched kernel (the ROS2 formula on arrays over the cars, the accounting car by car) gives every car
    what the one-car kernel gives it: stops inside a substep, friction changes, wheel lock and refined substeps."""
    n, h, substeps, v_stop = 3000, 0.002, 5, 0.5
    v, w, Tb, _ = _random_states(n, 4)
    rng = np.random.default_rng(5)
    v[150:400] = v_stop + rng.uniform(0.0, 0.05, 250)  # stopping within the step
    w[150:400] = v[150:400] / P.r * rng.uniform(0.0, 1.0, 250)
    Tb[150:400] = rng.uniform(500.0, 3000.0, 250)
    rows = np.array([(*r.as_array(), r.mu_locked) for r in ROADS.values()])
    roads = rows[rng.integers(len(rows), size=(n, 2))]  # (n, 2, 5): the road in use and after the change point
    x = rng.uniform(0.0, 50.0, n)
    change = np.where(rng.random(n) < 0.5, x + rng.uniform(0.0, 0.2, n), np.inf)  # half pass it in this step
    stopped = rng.random(n) < 0.1
    inv = 1.0 / (2.0 * 9.81 * rng.uniform(0.1, 1.2, (n, 2)))
    out = np.empty((len(CAR_OUTPUTS), n))
    cars_substeps_compiled(v, w, x, Tb, roads, change, stopped, inv, substeps, h, v_stop, P.r, P.m, P.J, P.Fz, out)
    one = np.array([car_substeps_compiled(v[i], w[i], x[i], Tb[i], roads[i], change[i], stopped[i], substeps, h,
                                          v_stop, inv[i, 0], inv[i, 1], P.r, P.m, P.J, P.Fz) for i in range(n)],
                   dtype=float).T
    np.testing.assert_allclose(out, one, rtol=STATE_TOL, atol=STATE_TOL)
    got = dict(zip(CAR_OUTPUTS, out))
    assert np.isfinite(got["stop_x"]).sum() > 100 and got["switched"].sum() > 500  # stops and changes happened
    assert np.sum(got["omega"] == 0.0) > 100  # locked wheels
    broken = rosenbrock.ros2_substep(v, w, Tb, *roads[:, 0].T, h, P.r, P.m, P.J, P.Fz)[2]
    assert broken.sum() > 10  # the refinement ran


def test_scalar_core_path_equals_batched_path():
    """One car stepped in floats, by the batched compiled kernel and by the plant's substeps with the accounting on
    arrays (the path of any plant): the same episode."""
    cfg = BrakingConfig(observation="oracle")
    acts = np.random.default_rng(3).uniform(-1.2, 1.2, 400)
    runs = []
    for kind in ("scalar", "compiled", "plant"):
        plant = BatchPlant(1, cfg.dt / cfg.substeps) if kind == "plant" else None
        sim = BrakingSim(1, cfg, road="ice->dry", v0=(5.0, 8.0), change_distance=(1.0, 3.0), scalar=kind == "scalar",
                         plant=plant)
        sim.reset_cars(None, [np.random.default_rng(7)])
        rows = []
        for a in acts:
            o, r, te, tr = sim.step(np.array([a]))
            rows.append(np.r_[o[0], r[0], te[0], tr[0], sim.v[0], sim.x[0], sim.stop_distance[0], sim.switched[0]])
            if te[0] or tr[0]:
                sim.reset_cars([0])
        runs.append(np.array(rows))
    np.testing.assert_allclose(runs[1], runs[0], rtol=STATE_TOL, atol=STATE_TOL)
    np.testing.assert_allclose(runs[2], runs[0], rtol=STATE_TOL, atol=STATE_TOL)
    assert runs[0][:, 8].sum() >= 3  # several episodes ended (terminated column)
    assert runs[0][:, 13].sum() > 0  # the friction change happened (switched column)
    with pytest.raises(ValueError, match="n == 1"):
        BrakingSim(2, cfg, scalar=True)


def _compare_with_single_envs(venv: BrakingVectorEnv, singles: list[BrakingEnv], seed: int, steps: int,
                              same_step: bool = False) -> tuple[int, int]:
    """Step the vector env and the single envs with the same random actions.

    :return: (episodes ended, steps on which some sub-env's road had changed).
    """
    n = venv.num_envs
    obs, infos = venv.reset(seed=seed)
    for i, env in enumerate(singles):
        o, info = env.reset(seed=seed + i)
        np.testing.assert_allclose(obs[i], o, atol=OBS_TOL)
        assert infos["road"][i] == info["road"]
    rng = np.random.default_rng(seed + 1000)
    pending = [False] * n
    ended = switched = 0
    for _ in range(steps):
        actions = rng.uniform(-1.0, 0.4, (n, 1)).astype(np.float32)
        obs, rew, term, trunc, infos = venv.step(actions)
        switched += bool(venv.sim.switched.any())
        for i, env in enumerate(singles):
            if pending[i]:  # next-step autoreset: this step is the reset
                o, info = env.reset()
                r, te, tr = 0.0, False, False
            else:
                o, r, te, tr, info = env.step(actions[i])
            assert (te, tr) == (bool(term[i]), bool(trunc[i]))
            done = te or tr
            if same_step and done:
                np.testing.assert_allclose(infos["final_obs"][i], o, atol=OBS_TOL)
                fin = infos["final_info"]
                assert fin["_ratio"][i] == (info["ratio"] is not None)  # left out when truncated, as None
                if info["ratio"] is not None:
                    assert fin["ratio"][i] == pytest.approx(info["ratio"], rel=STATE_TOL, abs=STATE_TOL)
                o, info = env.reset()
            np.testing.assert_allclose(obs[i], o, atol=OBS_TOL)
            assert rew[i] == pytest.approx(r, rel=STATE_TOL, abs=STATE_TOL)
            assert infos["v"][i] == pytest.approx(info["v"], rel=STATE_TOL, abs=STATE_TOL)
            assert infos["distance"][i] == pytest.approx(info["distance"], rel=STATE_TOL, abs=STATE_TOL)
            assert infos["road"][i] == info["road"]
            if done and not same_step:
                assert infos["_limit_distance"][i]
                assert infos["limit_distance"][i] == pytest.approx(info["limit_distance"], rel=STATE_TOL, abs=STATE_TOL)
                assert infos["_stopping_distance"][i] == (info["stopping_distance"] is not None)
                if info["stopping_distance"] is not None:
                    assert infos["stopping_distance"][i] == pytest.approx(info["stopping_distance"], rel=STATE_TOL)
            pending[i] = done and not same_step
            ended += done
    return ended, switched


def test_vector_env_equals_single_envs_across_autoresets():
    kw = {"v0": SHORT_V0, "change_distance": (0.5, 2.0)}  # the friction change happens within the short stops
    venv = BrakingVectorEnv(4, road=ROADS_PER_ENV, **kw)
    assert venv.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    singles = [BrakingEnv(road=r, **kw) for r in ROADS_PER_ENV]
    ended, switched = _compare_with_single_envs(venv, singles, seed=11, steps=400)
    assert ended >= 8 and switched > 0


def test_same_step_autoreset_and_oracle_torque_rate_equal_single_envs():
    kw = {"v0": SHORT_V0, "observation": "oracle", "action_mode": "torque_rate", "time_limit": 0.8,
          "change_distance": 1.0}
    venv = BrakingVectorEnv(3, road=["snow", "dry->ice", "wet"], autoreset_mode="SameStep", **kw)
    singles = [BrakingEnv(road=r, **kw) for r in ["snow", "dry->ice", "wet"]]
    ended, switched = _compare_with_single_envs(venv, singles, seed=3, steps=250, same_step=True)
    assert ended >= 6 and switched > 0


def test_vector_env_seeding_and_make_vec():
    envs = gym.make_vec("fricenv/Braking-v0", num_envs=3, vectorization_mode="vector_entry_point",
                        road="random", v0=(10.0, 30.0))
    assert isinstance(envs.unwrapped, BrakingVectorEnv)
    assert envs.observation_space.shape == (3, 4) and envs.action_space.shape == (3, 1)
    a, _ = envs.reset(seed=5)
    b, _ = envs.reset(seed=5)
    c, _ = envs.reset(seed=[5, 6, 7])
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, c)
    d, _ = envs.reset(seed=6)
    np.testing.assert_array_equal(a[1:], d[:2])  # sub-env i gets seed + i
    assert not np.allclose(a[0], a[1])
    assert envs.observation_space.contains(a)
    envs.close()


def test_disabled_autoreset_and_reset_mask():
    venv = BrakingVectorEnv(2, v0=SHORT_V0, autoreset_mode=AutoresetMode.DISABLED)
    venv.reset(seed=0)
    done = np.zeros(2, dtype=bool)
    for _ in range(300):
        _, _, te, tr, _ = venv.step(np.ones((2, 1), np.float32))
        done |= te | tr
        if done.all():
            break
    assert done.all()
    _, infos = venv.reset(options={"reset_mask": np.array([False, True])})
    assert list(infos["_v"]) == [False, True]
    assert infos["distance"][1] == 0.0 and venv.sim.x[0] > 0.0  # only sub-env 1 restarted
    with pytest.raises(ValueError, match="reset_mask"):
        venv.reset(options={"reset_mask": np.array([1, 0])})


def test_vector_env_rejects_bad_input():
    venv = BrakingVectorEnv(2)
    with pytest.raises(RuntimeError, match="reset"):
        venv.step(np.zeros((2, 1)))
    venv.reset(seed=0)
    with pytest.raises(ValueError, match="NaN"):
        venv.step(np.array([[0.0], [np.nan]]))
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((3, 1)))
    with pytest.raises(TypeError, match="unknown argument.*valid"):
        BrakingVectorEnv(2, roadd="dry")
    with pytest.raises(ValueError, match="num_envs=2"):
        BrakingVectorEnv(2, road=["dry", "wet", "ice"])
    with pytest.raises(ValueError, match="unknown road 'tarmac'; valid: dry"):
        BrakingVectorEnv(2, road=["dry", "tarmac"])
    with pytest.raises(ValueError, match="autoreset_mode"):
        BrakingVectorEnv(2, autoreset_mode="Sometimes")
    with pytest.raises(ValueError, match="seed"):
        venv.reset(seed=[1, 2, 3])
    # out-of-range actions are clipped, as in the single env
    venv.reset(seed=1)
    o_big = venv.step(np.full((2, 1), 7.0))[0]
    venv.reset(seed=1)
    o_one = venv.step(np.full((2, 1), 1.0))[0]
    np.testing.assert_array_equal(o_big, o_one)


def test_sb3_adapter_equals_dummy_vec_env_and_trains():
    torch = pytest.importorskip("torch")
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecCheckNan

    from fricenv.envs.sb3_vec import BrakingSB3VecEnv, make_sb3_vec_env

    torch.set_num_threads(1)
    kw = {"v0": SHORT_V0, "road": "wet"}
    ours = BrakingSB3VecEnv(3, **kw)
    ref = DummyVecEnv([lambda: BrakingEnv(**kw) for _ in range(3)])
    ours.seed(21)
    ref.seed(21)
    np.testing.assert_allclose(ours.reset(), ref.reset(), atol=OBS_TOL)
    rng = np.random.default_rng(0)
    episodes = 0
    for _ in range(200):
        act = rng.uniform(-1.0, 0.4, (3, 1)).astype(np.float32)
        o1, r1, d1, i1 = ours.step(act)
        o2, r2, d2, i2 = ref.step(act)
        np.testing.assert_allclose(o1, o2, atol=OBS_TOL)
        np.testing.assert_allclose(r1, r2, atol=1e-6)
        np.testing.assert_array_equal(d1, d2)
        for i in np.flatnonzero(d1):
            np.testing.assert_allclose(i1[i]["terminal_observation"], i2[i]["terminal_observation"], atol=OBS_TOL)
            assert i1[i]["TimeLimit.truncated"] == i2[i]["TimeLimit.truncated"]
            assert i1[i]["ratio"] == pytest.approx(i2[i]["ratio"], abs=STATE_TOL, nan_ok=True)
            episodes += 1
    assert episodes >= 6
    # SB3's NaN checker and a short PPO run on the adapter
    env = VecCheckNan(make_sb3_vec_env(4, seed=0, road="random", v0=(2.5, 3.5)), raise_exception=True)
    model = PPO("MlpPolicy", env, n_steps=32, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=256)
    assert model.num_timesteps >= 256
    assert len(model.ep_info_buffer) > 0  # VecMonitor saw finished episodes


def test_bench_command_writes_the_json_contract(tmp_path):
    import argparse
    import json

    from fricenv.commands import bench

    parser = argparse.ArgumentParser()
    bench.add_arguments(parser)
    path = tmp_path / "bench.json"
    for target in ("env", "vector"):
        args = parser.parse_args([target, "--repeats", "1", "--steps", "100", "--json", str(path)])
        assert bench.run(args) == 0
        figures = json.loads(path.read_text())
        assert figures["pendulum_steps_per_s"] > 0
    assert set(figures["vector_steps_per_s"]) == {"1", "64", "1024"}
    ratio = figures["ratio_to_pendulum"]["vector"]["64"]
    assert ratio == pytest.approx(figures["vector_steps_per_s"]["64"] / figures["pendulum_steps_per_s"])


@pytest.mark.slow
def test_two_substeps_stay_within_a_tenth_of_a_percent_of_radau():
    """physics_dt=0.005 (2 substeps, the bench's coarse option) against the plant tests' Radau cases."""
    from tests.plants.test_quarter_car_plant import CASES, _stop_distance_ros2, _zoh
    from tests.reference import stopping_distance_radau

    p = qc.PAPER_PARAMS
    for road, profile in CASES:
        t_safe = 0.8 * road.mu_max * p.Fz * p.r
        torque = {"below_peak": lambda t, ts=t_safe: ts,
                  "lock_up": lambda t: 3000.0 * min(t / 0.2, 1.0),
                  "modulated": lambda t, ts=t_safe: ts * (1 + 0.3 * np.sin(2 * np.pi * 3 * t))}[profile]
        ref, _ = stopping_distance_radau(road, _zoh(torque))
        ours = _stop_distance_ros2(road, torque, substeps=2)
        assert abs(ours - ref) / ref < 1e-3, (road.name, profile, ours, ref)
