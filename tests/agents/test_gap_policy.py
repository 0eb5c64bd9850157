"""Policy-level sim-to-real gap: closed loop on the effect simulator, the three distances, the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agents.controllers import make_controller, rollout
from agents.gap_policy import (
    UnknownPolicyError,
    closed_loop_log,
    effects_from_report,
    make_env,
    policy_gap,
    resolve_policy,
    stopping_distances,
)
from fricenv.effects.quarter_car import make_effect
from fricenv.envs.braking import BrakingEnv
from fricenv.gap.quarter_car.simulate import STAND_IN_SUBSTEPS
from fricenv.logs import read_log

SEEDS = [0, 1, 2]
LAG = [make_effect("brake_lag", tau=0.04)]


@pytest.mark.parametrize("name", ["rule-abs", "oracle-slip"])
def test_nominal_closed_loop_is_braking_env(name):
    """No effect, no free roll: the closed loop is Braking-v0 itself, the same stop for the same seed."""
    pol = resolve_policy(name)
    env = BrakingEnv(road="wet", observation=pol.config_kwargs["observation"])
    ref = rollout(env, make_controller(name, env), seed=4).info["stopping_distance"]
    got = stopping_distances(pol, "wet", (), [4], free_roll=0.0)[0].distance
    assert got == ref


def test_closed_loop_env_is_braking_v0_with_effects():
    """The gap tool's simulators are Braking-v0 with effects: the observation layout and the lagged torque."""
    env = make_env(resolve_policy("rule-abs"), "dry", LAG)
    assert isinstance(env.unwrapped, BrakingEnv)
    obs, _ = env.reset(seed=0)
    assert obs.shape == env.observation_space.shape and obs.dtype == np.float32
    assert obs[0] * 100.0 == pytest.approx(20.0 / 0.345, abs=3.0)  # measured wheel speed, free rolling
    obs, *_ = env.step(np.array([0.0], dtype=np.float32))  # action 0 = half of t_max
    assert obs[2] == pytest.approx(0.5)
    applied = env.unwrapped.sim.plant.sim.applied[0]
    assert 0.0 < applied < 0.5 * env.unwrapped.config.t_max  # the lag: the applied torque trails the command
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan], dtype=np.float32))


def test_brake_lag_gap_and_true_effect_reproduces_real():
    """rule-abs under a brake lag stops later than the nominal sim predicts; the sim with the true effect
    (its own 5-substep integration, the stand-in's is 10) reproduces the stand-in's distance within 1 %."""
    pol = resolve_policy("rule-abs")
    nominal = np.mean([e.distance for e in stopping_distances(pol, "dry", (), SEEDS)])
    real = np.mean([e.distance for e in stopping_distances(pol, "dry", LAG, SEEDS, substeps=STAND_IN_SUBSTEPS)])
    augmented = np.mean([e.distance for e in stopping_distances(pol, "dry", LAG, SEEDS)])
    assert real > 1.03 * nominal
    assert augmented == pytest.approx(real, rel=0.01)


def test_closed_loop_log_format(tmp_path):
    pol = resolve_policy("rule-abs")
    log = closed_loop_log(pol, "dry", LAG, seed=1)
    assert np.all(log.T_b[:40] == 0.0) and log.T_b.max() > 500.0  # free-rolling stretch, then braking
    assert np.allclose(np.diff(log.t), 0.01)
    from fricenv.logs import write_log

    write_log(tmp_path / "log.csv", log, comments=log.comments)
    back = read_log(tmp_path / "log.csv")
    assert len(back) == len(log) and back.v is not None and back.a_x is not None


def test_report_mode_and_json_keys(tmp_path, capsys):
    """--report: the augmented sim is the report's verdict + params; the command's JSON has the keys."""
    from fricenv.cli import main

    report = {"plant": "quarter-car", "verdict": "brake_lag", "gap_before": 3.0, "gap_after": 0.2,
              "params": {"tau": 0.04}, "where": {}, "candidates": []}
    path = tmp_path / "report.json"
    path.write_text(json.dumps(report))
    out = tmp_path / "gap.json"
    rc = main(["gap", "policy", "rule-abs", "--road", "dry", "--seeds", "2", "--report", str(path),
               "--effect", "brake_lag", "--param", "tau=0.04", "--json", str(out)])
    assert rc == 0
    res = json.loads(out.read_text())
    for key in ("policy", "road", "effects", "verdict", "distance_nominal_m", "distance_real_m",
                "distance_augmented_m", "prediction_error_before", "prediction_error_after", "ratio"):
        assert key in res
    assert res["ratio"]["real"] == pytest.approx(res["distance_real_m"] / res["limit_distance_m"])
    assert res["verdict"] == "brake_lag" and res["effects"] == [{"effect": "brake_lag", "params": {"tau": 0.04}}]
    assert abs(res["prediction_error_after"]) < abs(res["prediction_error_before"])
    assert "augmented" in capsys.readouterr().out


def test_report_none_verdict_keeps_nominal():
    assert effects_from_report({"verdict": "unexplained", "params": {}}) == ("unexplained", [])
    with pytest.raises(ValueError, match="valid"):
        effects_from_report({"verdict": "warp_drive", "params": {}})


def test_unknown_controller_lists_valid(capsys):
    with pytest.raises(UnknownPolicyError, match="rule-abs.*slip-pi|slip-pi.*rule-abs"):
        resolve_policy("fuzzy-abs")
    from fricenv.cli import main

    assert main(["gap", "policy", "fuzzy-abs", "--effect", "brake_lag", "--param", "tau=0.04"]) == 2
    err = capsys.readouterr().err
    assert "fuzzy-abs" in err and "rule-abs" in err and "oracle-slip" in err


def test_retune_rejects_untunable_and_needs_a_real_side():
    with pytest.raises(ValueError, match="retune"):
        policy_gap("locked", "dry", LAG, report={"verdict": "none", "params": {}}, seeds=1, retune=True)
    with pytest.raises(ValueError, match="effects"):
        policy_gap("rule-abs", "dry", (), seeds=1)


@pytest.mark.slow
def test_full_flow_diagnoses_the_closed_loop_log():
    """Stand-in closed-loop log -> diagnose -> augmented sim: the verdict is the stand-in's effect and the
    prediction error shrinks."""
    res = policy_gap("rule-abs", "dry", LAG, seeds=5)
    assert res["verdict"] == "brake_lag"
    assert res["augmented_effects"][0]["params"]["tau"] == pytest.approx(0.04, rel=0.15)
    assert abs(res["prediction_error_after"]) < abs(res["prediction_error_before"])


def test_retune_picks_in_the_corrected_sim_and_measures_on_the_real_side():
    """The retune choice is the corrected simulator's best value, and the real-side gain is measured, not assumed."""
    res = policy_gap("rule-abs", "dry", LAG, report={"verdict": "brake_lag", "params": {"tau": 0.04}}, seeds=1,
                     retune=True)
    rt = res["retune"]
    best = min(rt["grid"], key=lambda r: r["augmented"])
    assert rt["best_augmented"] == best["value"]
    assert rt["real_best_augmented_m"] == best["real"]
    assert rt["real_gain_m"] == pytest.approx(res["distance_real_m"] - best["real"])
    default = next(r for r in rt["grid"] if r["value"] == rt["default"])
    assert default["real"] == pytest.approx(res["distance_real_m"])  # the default's row is the un-tuned run
