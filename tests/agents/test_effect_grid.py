"""The effect grid (each library effect at two sizes) and evaluation scenarios on plants with effects."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agents.effect_scenarios import GRID_SCENARIOS, fixed_effect_scenarios, grid_scenarios, parse_effects_arg
from agents.evaluation import Scenario, evaluate
from agents.robustness_report import policy_matrix, write_matrix
from fricenv.effects.grid import (
    EFFECT_GRID,
    GridCell,
    cell_effects,
    grid_cells,
    grid_effect,
    grid_randomization,
)
from fricenv.envs.effect_spec import EffectSpecError
from fricenv.plants.quarter_car import PAPER_PARAMS
from fricenv.plants.tire import WET

TABLE = {  # effect: (low, high) as the grid's table states them; r and theta factors resolved below
    "brake_lag": ({"tau": 0.02}, {"tau": 0.08}),
    "brake_delay": ({"delay": 0.02}, {"delay": 0.06}),
    "brake_gain": ({"gain": 0.80}, {"gain": 1.25}),
    "radius_error": ({"r_eff": 0.97 * PAPER_PARAMS.r}, {"r_eff": 1.04 * PAPER_PARAMS.r}),
    "relaxation_length": ({"sigma": 0.3}, {"sigma": 0.6}),
    "drag": ({"c0": 60.0, "c2": 0.3}, {"c0": 150.0, "c2": 0.6}),
    "mu_change": ({"theta_after": 0.6 * 0.82}, {"theta_after": 1.3 * 0.82}),
}


def test_grid_cells_resolve_to_the_table_on_wet_at_20():
    assert list(EFFECT_GRID) == list(TABLE)
    mid_stop = 20.0 / (2 * WET.mu_max * 9.81)  # half of the stop at the road's peak friction
    for effect, sizes in TABLE.items():
        for size, expected in zip(("low", "high"), sizes):
            entry = grid_effect(effect, size, "wet", 20.0)
            assert entry["effect"] == effect
            want = dict(expected, t_change=mid_stop) if effect == "mu_change" else expected
            assert entry["params"] == pytest.approx(want, rel=1e-12)
    labels = [c.label for c in grid_cells()]
    assert labels[0] == "nominal" and len(labels) == 15 and "brake_gain:high" in labels
    assert cell_effects(GridCell("nominal"), "dry", 20.0) == []
    assert grid_effect("mu_change", "low", "dry->ice", 20.0)["params"]["theta_after"] == pytest.approx(0.6)
    with pytest.raises(ValueError, match="unknown grid effect 'fade'"):
        grid_effect("fade", "low", "dry", 20.0)


def test_randomization_spans_nominal_and_both_sizes_and_draws_both_sides():
    import gymnasium as gym

    import fricenv  # noqa: F401

    ranges = grid_randomization()
    assert "mu_change" not in ranges
    assert ranges["brake_gain"]["gain"] == (0.8, 1.25)  # two-sided: both sides of the nominal 1
    assert ranges["brake_lag"]["tau"] == (0.001, 0.08)  # one-sided: from (almost) the nominal plant to the high size
    assert ranges["radius_error"]["r_eff"] == pytest.approx((0.97 * PAPER_PARAMS.r, 1.04 * PAPER_PARAMS.r))
    env = gym.make("fricenv/Braking-v0", effects_randomization=ranges)
    gains = []
    for seed in range(12):
        env.reset(seed=seed)
        drawn = {e.name: e for e in env.unwrapped.sim.plant.effects[0]}
        assert set(drawn) == set(ranges)
        assert 0.001 <= drawn["brake_lag"].tau <= 0.08
        gains.append(drawn["brake_gain"].gain)
    assert min(gains) < 1.0 < max(gains) and all(0.8 <= g <= 1.25 for g in gains)


def test_effects_argument_forms(tmp_path):
    entries = [{"effect": "brake_lag", "params": {"tau": 0.04}}]
    assert parse_effects_arg(json.dumps(entries)) == entries
    listed = tmp_path / "effects.json"
    listed.write_text(json.dumps(entries))
    assert parse_effects_arg(str(listed)) == entries
    report = tmp_path / "report.json"
    report.write_text(json.dumps({"verdict": "drag", "params": {"c0": 80.0, "c2": 0.4}}))
    assert parse_effects_arg(str(report)) == [{"effect": "drag", "params": {"c0": 80.0, "c2": 0.4}}]
    for bad, msg in (("[{\"effect\": \"fade\"}]", "unknown effect 'fade'"), ("[1,", "not valid JSON"),
                     (str(tmp_path / "none.json"), "neither a JSON list")):
        with pytest.raises(EffectSpecError, match=f"^--effects: .*{msg}"):
            parse_effects_arg(bad)


def test_cli_rejects_bad_effects_in_one_line(capsys):
    from fricenv.cli import main

    assert main(["evaluate", "--policy", "rule-abs", "--effects", "[{\"effect\": \"brake_lag\"}]"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fricenv evaluate: error: --effects: effects[0]")


def test_rows_name_their_plant_and_the_effect_acts(tmp_path):
    delay = [{"effect": "brake_delay", "params": {"delay": 0.06}}]
    base = [Scenario("dry", 20.0)]
    rows = evaluate(["rule-abs"], scenarios=list(base) + fixed_effect_scenarios(base, delay), seeds=1, workers=1,
                    progress=False)
    nominal, delayed = rows
    assert nominal["cell"] == "nominal" and nominal["effects"] == []
    assert delayed["cell"] == "custom" and delayed["effects"] == delay
    assert delayed["ratio_mean"] != pytest.approx(nominal["ratio_mean"], abs=1e-3)  # the plant did change
    cells = grid_scenarios(GRID_SCENARIOS[:1], [GridCell("nominal"), GridCell("brake_gain", "high")])
    assert [(s.cell, list(s.effects)) for s in cells] == [
        ("nominal", []), ("brake_gain:high", [{"effect": "brake_gain", "params": {"gain": 1.25}}])]
    matrix = policy_matrix(rows)
    written = write_matrix(tmp_path, matrix, "policy", "ratio_mean", "t", "ratio")
    assert json.loads(written["json"].read_text())["matrix"][1]["cell"] == "custom"
    assert written["heatmap"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert np.isfinite([m["ratio_mean"] for m in matrix]).all()


def test_compare_takes_the_grid_and_checks_its_rows_before_training(capsys, tmp_path):
    from fricenv.cli import main

    assert main(["compare", "--effect-grid", "--estimators", "kalman", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("fricenv compare: error: unknown estimator 'kalman'")
    assert not any(tmp_path.iterdir())  # nothing trained
