"""Classical ABS controllers against the physical limit and each other."""

import numpy as np
import pytest

from agents.controllers import (
    ControlSpec,
    FullBraking,
    ObsReader,
    OracleSlipController,
    OracleSource,
    RuleBasedABS,
    SlipController,
    make_controller,
    rollout,
    slip_reference,
)
from fricenv.envs.braking import BrakingEnv
from fricenv.envs.braking_sim import BrakingSim
from fricenv.envs.config import BrakingConfig
from fricenv.plants.tire import DRY, ICE, SNOW, WET


def _ratio(road, name, seed=0, **kwargs):
    env = BrakingEnv(road=road, observation="oracle", **kwargs)
    return rollout(env, make_controller(name, env), seed=seed).info


@pytest.mark.parametrize("road", ["dry", "wet"])
def test_oracle_slip_controller_within_one_percent_of_the_limit(road):
    info = _ratio(road, "oracle-slip")
    assert info["stopped"] and not info["lock_seen"]
    assert 1.0 <= info["ratio"] < 1.01


@pytest.mark.parametrize("road", ["dry", "wet"])
@pytest.mark.parametrize("seed", [0, 1])
def test_rule_abs_beats_a_locked_wheel_and_never_locks(road, seed):
    abs_info = _ratio(road, "rule-abs", seed)
    locked = _ratio(road, "locked", seed)
    assert locked["lock_seen"] and not abs_info["lock_seen"]
    assert abs_info["stopping_distance"] < locked["stopping_distance"]


@pytest.mark.parametrize("road, reference", [("dry", 1.18), ("wet", 1.13), ("snow", 1.04), ("ice", 1.04)])
def test_rule_abs_at_least_as_good_as_the_reference_implementation(road, reference):
    info = _ratio(road, "rule-abs", seed=3)
    assert info["ratio"] <= reference and not info["lock_seen"]


def test_locked_wheel_ratio_on_dry():
    info = _ratio("dry", "locked")
    assert info["ratio"] == pytest.approx(1.27, abs=0.02)


def test_slip_reference_is_the_true_peak_capped_for_snow():
    assert slip_reference(DRY)[0] == pytest.approx(DRY.peak_slip)
    assert slip_reference(WET)[1] == pytest.approx(WET.mu_max)
    lam, mu = slip_reference(SNOW)  # C < 1: peak at slip 1, capped
    assert lam < 0.5 and mu > 0.99 * SNOW.mu_max
    assert slip_reference(ICE)[0] == pytest.approx(ICE.peak_slip)


def test_slip_controller_tracks_a_fixed_reference_from_a_plain_callable():
    env = BrakingEnv(road="wet", observation="oracle")
    ctrl = SlipController(env, lambda values: (values["v"], np.full_like(values["v"], 0.07)))
    ro = rollout(env, ctrl, seed=0)
    settled = ro.slip[(ro.t > 0.3) & (ro.v > 5.0)]
    assert abs(np.median(settled) - 0.07) < 0.01
    assert ro.info["ratio"] < 1.06  # mu(0.07) is 1.5 % below the wet peak, plus the start-up transient


def test_controllers_work_in_torque_rate_mode():
    # The modulator needs 45 ms to build the 1120 N m peak torque at 25000 N m/s: ~2 % over the limit.
    info = _ratio("dry", "oracle-slip", action_mode="torque_rate")
    assert info["ratio"] < 1.03 and not info["lock_seen"]


def test_measured_signal_controllers_ignore_oracle_entries():
    # The rule ABS reads its entries by name: the same episode with and without the oracle entries.
    a = BrakingEnv(road="wet")
    b = BrakingEnv(road="wet", observation="oracle")
    ra, rb = rollout(a, RuleBasedABS(a), seed=2), rollout(b, RuleBasedABS(b), seed=2)
    np.testing.assert_array_equal(ra.torque, rb.torque)


def test_missing_observation_entries_are_named():
    env = BrakingEnv()  # default observation: no true v / slip
    with pytest.raises(ValueError, match="'v'"):
        OracleSlipController(env)
    src = OracleSource(slip_ref=0.1)
    with pytest.raises(ValueError, match="oracle"):
        src(ObsReader(env.observation_fields).decode(np.zeros(4, dtype=np.float32)))
    with pytest.raises(ValueError, match="valid: oracle-slip"):
        make_controller("pid", env)
    with pytest.raises(ValueError, match="shape"):
        FullBraking(env).act(np.zeros(3))


def test_controllers_act_on_a_batch_like_on_single_envs():
    roads = ["dry", "wet", "ice"]
    seeds = [4, 5, 6]
    sim = BrakingSim(3, BrakingConfig())
    obs = sim.reset_cars(None, [np.random.default_rng(s) for s in seeds], [{"road": r} for r in roads])
    ctrl = RuleBasedABS(ControlSpec.from_sim(sim))
    ctrl.reset()
    torques = []
    for _ in range(150):
        obs, *_ = sim.step(ctrl.act(obs))
        torques.append(sim.torque.copy())
    torques = np.array(torques)
    for i, (road, seed) in enumerate(zip(roads, seeds)):
        env = BrakingEnv(road=road)
        ro = rollout(env, RuleBasedABS(env), seed=seed)
        n = min(150, len(ro.torque) - 1)
        np.testing.assert_array_equal(ro.torque[1:n + 1], torques[:n, i])
