"""One episode over three plants, and the corrected simulator as an env."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

import fricenv  # noqa: F401  (registers the envs)
from fricenv.effects.quarter_car import make_effect
from fricenv.envs.braking_sim import BrakingSim
from fricenv.envs.braking_vector import BrakingVectorEnv
from fricenv.envs.config import BrakingConfig
from fricenv.envs.effect_plant import EffectPlant
from fricenv.envs.effect_spec import EffectSpecError, parse_effect_args, resolve_effects
from fricenv.plants import quarter_car as qc
from fricenv.plants.braking_plant import BatchPlant, BrakingPlant
from fricenv.plants.tire import ROADS

TOL = 1e-12  # relative (scale max(1, |x|)): math and numpy round transcendentals differently
LAG = [{"effect": "brake_lag", "params": {"tau": 0.04}}]


def _episode(sim: BrakingSim, actions: np.ndarray, seed: int) -> np.ndarray:
    """Truth, measurements, reward and figures of every step of one episode (noise on)."""
    sim.reset_cars(None, [np.random.default_rng(seed)])
    rows = []
    for a in actions:
        obs, r, te, tr = sim.step(np.array([a]))
        rows.append([sim.v[0], sim.omega[0], sim.x[0], r[0], sim.slip[0], sim.mu[0], *sim.meas[0], *obs[0],
                     sim.lock_count[0], te[0], tr[0], sim.stop_distance[0], sim.stop_time[0]])
        if te[0] or tr[0]:
            break
    return np.array(rows, dtype=float)


def _assert_close(a: np.ndarray, b: np.ndarray) -> None:
    assert a.shape == b.shape
    scale = np.maximum(1.0, np.abs(np.nan_to_num(a)))
    np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
    assert np.nanmax(np.abs(a - b) / scale) < TOL


@pytest.mark.parametrize(("road", "mode"), [("dry", "torque"), ("wet->ice", "torque_rate"), ("snow", "torque"),
                                            ("ice->dry", "torque_rate")])
def test_effect_plant_without_effects_equals_braking_v0(road, mode):
    """The effect-carrying plant with no effect, under the one episode logic, is Braking-v0's episode to 1e-12."""
    c = BrakingConfig(action_mode=mode, observation="oracle")
    h = c.dt / c.substeps
    actions = np.random.default_rng(5).uniform(-1.0, 1.0, c.max_steps)
    ref = _episode(BrakingSim(1, c, road=road, scalar=True), actions, seed=11)
    plant = EffectPlant(1, h, c.params, (), None, c.max_steps * c.substeps)
    got = _episode(BrakingSim(1, c, road=road, plant=plant), actions, seed=11)
    assert ref[-1, -4] == 1.0  # the episode ran to its stop (terminated)
    _assert_close(ref, got)
    _assert_close(ref, _episode(BrakingSim(1, c, road=road), actions, seed=11))  # and the batched plant


def test_empty_effects_is_the_plain_env_exactly():
    plain, empty = gym.make("fricenv/Braking-v0"), gym.make("fricenv/Braking-v0", effects=[])
    assert empty.unwrapped.sim.scalar and isinstance(empty.unwrapped.sim.plant, BatchPlant)
    for env in (plain, empty):
        env.reset(seed=3)
    for _ in range(300):
        a = np.array([0.1], dtype=np.float32)
        o1, r1, t1, u1, i1 = plain.step(a)
        o2, r2, t2, u2, i2 = empty.step(a)
        assert np.array_equal(o1, o2) and r1 == r2 and (t1, u1) == (t2, u2) and i1["v"] == i2["v"]
        if t1 or u1:
            break
    assert t1 and t2 and i1["stopping_distance"] == i2["stopping_distance"]


def test_plants_implement_the_protocol_and_equal_the_plant_functions():
    p = qc.PAPER_PARAMS
    assert isinstance(BatchPlant(2, 0.002), BrakingPlant) and isinstance(EffectPlant(1, 0.002), BrakingPlant)
    rng = np.random.default_rng(0)
    for _ in range(50):
        road = list(ROADS.values())[rng.integers(4)]
        v, w = rng.uniform(0.0, 30.0), rng.uniform(0.0, 100.0)
        bp = BatchPlant(1, 0.002)
        bp.set_road([0], road.as_array())
        bp.reset([0], v, w)
        assert bp.slip()[0] == pytest.approx(float(qc.slip(v, w, p)), rel=TOL, abs=TOL)
        assert bp.tire_force()[0] == pytest.approx(float(qc.tire_force(v, w, road.as_array(), p)), rel=TOL, abs=TOL)


def _stop(env: gym.Env, seed: int, action: float = 0.0) -> dict:
    env.reset(seed=seed)
    while True:
        *_, te, tr, info = env.step(np.array([action], dtype=np.float32))
        if te or tr:
            return info


def test_brake_lag_env_applies_the_lag_and_stops_later():
    env = gym.make("fricenv/Braking-v0", effects=LAG, road="wet")
    env.reset(seed=0)
    env.step(np.array([1.0], dtype=np.float32))
    sim = env.unwrapped.sim.plant.sim
    assert 0.0 < sim.applied[0] < 0.5 * env.unwrapped.config.t_max  # the applied torque trails the command
    lagged = _stop(env, 0, action=-0.2)["stopping_distance"]
    plain = _stop(gym.make("fricenv/Braking-v0", road="wet"), 0, action=-0.2)["stopping_distance"]
    assert lagged > plain + 0.2  # ~ v0 x the lag's dead time on the onset


def test_brake_delay_env_starts_with_the_brake_released_and_equals_the_shifted_commands():
    """A delay of three samples: the car sees the commands three samples late and no torque before the first (the
    brake is released when an episode starts), that is, the plain env fed (0, 0, 0, T_0, T_1, ...)."""
    shift = 3
    delayed = gym.make("fricenv/Braking-v0", road="wet",
                       effects=[{"effect": "brake_delay", "params": {"delay": shift * 0.01}}])
    plain = gym.make("fricenv/Braking-v0", road="wet")
    actions = np.random.default_rng(2).uniform(-1.0, 0.2, 40).astype(np.float32)  # torque (a + 1) t_max / 2
    released = np.full(shift, -1.0, dtype=np.float32)

    def speeds(env, acts):
        env.reset(seed=0)
        return np.array([env.step(np.array([a]))[4]["v"] for a in acts])

    got, want = speeds(delayed, actions), speeds(plain, np.r_[released, actions[:-shift]])
    assert np.all(got[:shift] == 20.0)  # no drag, no torque: the car rolls on at its v0
    np.testing.assert_allclose(got, want, rtol=1e-9)


def test_radius_error_sets_free_rolling_and_the_lock_test_on_r_eff():
    env = gym.make("fricenv/Braking-v0", effects=[{"effect": "radius_error", "params": {"r_eff": 0.30}}])
    _, info = env.reset(seed=1)
    sim = env.unwrapped.sim
    assert sim.omega[0] == pytest.approx(20.0 / 0.30) and info["slip"] == 0.0
    info = _stop(env, 1, action=1.0)  # full torque: the wheel locks (omega r_eff ~ 0)
    assert info["lock_seen"]


def test_report_path_effects_list_verdict_and_none(tmp_path):
    path = tmp_path / "report.json"
    path.write_text(json.dumps({"verdict": "brake_lag", "params": {"tau": 0.03}}))
    assert resolve_effects(path) == (make_effect("brake_lag", tau=0.03),)
    path.write_text(json.dumps({"verdict": "drag", "params": {}, "effects": [
        {"effect": "drag", "params": {"c0": 10.0, "c2": 0.5}}, {"effect": "brake_gain", "params": {"gain": 0.9}}]}))
    env = gym.make("fricenv/Braking-v0", effects=str(path))
    assert env.unwrapped.sim.plant.fixed == (make_effect("drag", c0=10.0, c2=0.5), make_effect("brake_gain", gain=0.9))
    for verdict in ("none", "unexplained"):
        path.write_text(json.dumps({"verdict": verdict, "params": {}}))
        assert gym.make("fricenv/Braking-v0", effects=path).unwrapped.sim.scalar
    with pytest.raises(EffectSpecError, match="cannot read"):
        resolve_effects(tmp_path / "missing.json")


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"effects": [{"effect": "warp_drive", "params": {}}]}, "warp_drive.*valid effects: brake_lag"),
    ({"effects": [{"effect": "brake_lag", "params": {"tau": 0.04, "k": 1}}]}, "no parameter.*k; its parameters"),
    ({"effects": [{"effect": "brake_lag", "params": {}}]}, "missing parameter.*tau"),
    ({"effects": LAG + LAG}, "once"),
    ({"effects_randomization": {"brake_lag": {"tua": (0.02, 0.08)}}}, "tua"),
    ({"effects_randomization": {"brakelag": {"tau": (0.02, 0.08)}}}, "brakelag"),
    ({"effects_randomization": {"brake_lag": {"tau": (0.08, 0.02)}}}, "low <= high"),
    ({"effects_randomization": {"brake_lag": {"tau": (-0.1, 0.02)}}}, "tau must be"),
    ({"effects_randomization": {"drag": {"c0": (0.0, 50.0)}}}, "'c2' needs a range"),
    ({"effects_randomization": {"one_of": {"brake_lag": {"tau": (0.02, 0.08)}}, "drag": {"c0": (0.0, 50.0)}}},
     "'one_of' .* stands alone"),
    ({"effects_randomization": {"one_of": {"brake_lag": {"tua": (0.02, 0.08)}}}}, "tua"),
])
def test_bad_effects_are_rejected_naming_them(kwargs, match):
    with pytest.raises(EffectSpecError, match=match):
        gym.make("fricenv/Braking-v0", **kwargs)
    assert issubclass(EffectSpecError, ValueError)


def test_randomization_draws_per_episode_from_np_random():
    spec = {"brake_lag": {"tau": (0.02, 0.08)}, "drag": {"c0": (0.0, 50.0)}}
    env = gym.make("fricenv/Braking-v0", effects=[{"effect": "drag", "params": {"c0": 0.0, "c2": 0.4}}],
                   effects_randomization=spec)
    plant = env.unwrapped.sim.plant
    draws = []
    for seed in (0, 1, 0):
        env.reset(seed=seed)
        lag, drag = sorted(plant.effects[0], key=lambda e: e.name)
        assert 0.02 <= lag.tau <= 0.08 and 0.0 <= drag.c0 <= 50.0 and drag.c2 == 0.4
        draws.append((lag.tau, drag.c0))
    assert draws[0] == draws[2] and draws[0] != draws[1]  # the seed decides the draw
    env.reset()
    assert (plant.effects[0][0].tau, plant.effects[0][1].c0) not in draws  # a new episode, a new draw


def test_vector_env_with_effects_equals_single_envs():
    kw = {"v0": (6.0, 9.0), "effects": LAG, "effects_randomization": {"brake_gain": {"gain": (0.8, 1.2)}}}
    venv = gym.make_vec("fricenv/Braking-v0", 3, vectorization_mode="vector_entry_point", road="wet", **kw)
    singles = [gym.make("fricenv/Braking-v0", road="wet", **kw) for _ in range(3)]
    obs, _ = venv.reset(seed=4)
    for i, env in enumerate(singles):
        np.testing.assert_allclose(obs[i], env.reset(seed=4 + i)[0], atol=1e-6)
    actions = np.random.default_rng(0).uniform(-1.0, 0.6, (120, 3, 1)).astype(np.float32)
    ended = 0
    for a in actions:
        obs, rew, term, trunc, infos = venv.step(a)
        for i, env in enumerate(singles):
            if ended & (1 << i):
                continue
            o, r, te, tr, info = env.step(a[i])
            assert (te, tr) == (term[i], trunc[i])
            np.testing.assert_allclose(obs[i], o, atol=1e-6)  # float32 observations
            assert rew[i] == pytest.approx(r, rel=TOL, abs=TOL)
            assert infos["v"][i] == pytest.approx(info["v"], rel=TOL, abs=TOL)
            if te or tr:
                assert infos["stopping_distance"][i] == pytest.approx(info["stopping_distance"], rel=TOL)
                ended |= 1 << i
    assert ended == 0b111


def test_cli_effect_parser_is_public_and_clear():
    effects = parse_effect_args(["brake_lag", "drag"], ["tau=0.05", "drag.c0=10", "c2=1"])
    assert effects == [make_effect("brake_lag", tau=0.05), make_effect("drag", c0=10.0, c2=1.0)]
    with pytest.raises(EffectSpecError, match="unknown parameter 'x'"):
        parse_effect_args(["brake_lag"], ["x=1"])
    with pytest.raises(EffectSpecError, match="unknown effect 'lag'"):
        parse_effect_args(["lag"], [])


def test_vector_cars_with_drawn_effects_equal_single_cars():
    """The cars of a vector env are the elements of one effect simulator: each car's episode, with the effects its
    own generator draws, equals the same episode of a one-car plant."""
    ranges = {"brake_lag": {"tau": (0.001, 0.08)}, "brake_delay": {"delay": (0.0, 0.06)},
              "drag": {"c0": (0.0, 150.0), "c2": (0.0, 0.6)}, "relaxation_length": {"sigma": (0.001, 0.6)}}
    vec = BrakingVectorEnv(num_envs=3, effects_randomization=ranges, road="wet")
    vec.reset(seed=[11, 12, 13])
    singles = [gym.make("fricenv/Braking-v0", effects_randomization=ranges, road="wet") for _ in range(3)]
    for env, seed in zip(singles, (11, 12, 13)):
        env.reset(seed=seed)
    actions = np.linspace(-1.0, 1.0, 40)
    for a in actions:
        obs, *_ = vec.step(np.full((3, 1), a, dtype=np.float32))
        for i, env in enumerate(singles):
            single, *_ = env.step(np.array([a], dtype=np.float32))
            np.testing.assert_allclose(obs[i], single, rtol=1e-12, atol=1e-12)
    assert len({tuple(map(str, e)) for e in vec.sim.plant.effects}) == 3  # three different draws


def test_one_of_randomization_draws_one_effect_or_none_per_episode():
    spec = {"one_of": {"brake_lag": {"tau": (0.02, 0.08)}, "brake_gain": {"gain": (0.8, 1.25)}}}
    env = gym.make("fricenv/Braking-v0", effects_randomization=spec)
    plant = env.unwrapped.sim.plant
    counts = {(): 0, ("brake_lag",): 0, ("brake_gain",): 0}
    for seed in range(300):
        env.reset(seed=seed)
        names = tuple(e.name for e in plant.effects[0])
        counts[names] += 1  # a KeyError if both were drawn at once
        if names == ("brake_lag",):
            assert 0.02 <= plant.effects[0][0].tau <= 0.08
    assert all(70 <= c <= 130 for c in counts.values()), counts  # 1/3 each: 100 +- 3 sd
