"""`fricenv demo` and `fricenv bench env`: output files and schemas."""

import json

import pytest

from fricenv.cli import main


def test_demo_writes_table_json_and_png(tmp_path, capsys):
    out_json = tmp_path / "demo.json"
    assert main(["demo", "--quick", "--roads", "dry", "wet", "--out", str(tmp_path / "demo"), "--json",
                 str(out_json)]) == 0
    data = json.loads(out_json.read_text())
    rows = data["results"]
    assert {(r["road"], r["controller"]) for r in rows} == {
        (road, c) for road in ("dry", "wet") for c in ("oracle-slip", "slip-pi", "rule-abs", "locked")}
    for r in rows:
        assert set(r) == {"road", "controller", "distance_m", "limit_m", "ratio", "locked"}
        assert r["ratio"] == pytest.approx(r["distance_m"] / r["limit_m"], rel=1e-9)
        assert isinstance(r["locked"], bool)
    assert all(r["limit_m"] == pytest.approx(20.18, abs=0.01) for r in rows if r["road"] == "dry")
    assert (tmp_path / "demo" / "demo_dry.png").stat().st_size > 10_000
    printed = capsys.readouterr().out
    assert "rule-abs" in printed and "limit [m]" in printed


def test_the_corrected_simulator_part_puts_the_reported_effect_into_the_plant(tmp_path):
    """A report naming the true effect gives the same stopping distances as the plant with that effect; the nominal
    plant stops shorter (a brake lag delays every pressure rise)."""
    from fricenv.commands import demo_story as story

    name, params = story.HIDDEN_EFFECT
    report = tmp_path / "report.json"
    report.write_text(json.dumps({"verdict": name, "params": params, "effects": [{"effect": name, "params": params}]}))
    rows, _ = story.corrected_simulator(str(report), seed=0)
    by = {(r["plant"], r["controller"]): r["distance_m"] for r in rows}
    for ctl in story.CORRECTED_CONTROLLERS:
        assert by[("corrected", ctl)] == pytest.approx(by[("true effect", ctl)], rel=1e-9)
        assert by[("nominal", ctl)] < by[("true effect", ctl)] - 1.0
    assert "true effect [m]" in story.format_corrected_table(rows)


@pytest.mark.slow
def test_the_whole_demo_diagnoses_the_hidden_effect_and_links_every_part(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--json", str(tmp_path / "demo.json")]) == 0
    data = json.loads((tmp_path / "demo.json").read_text())
    name, _ = __import__("fricenv.commands.demo_story", fromlist=["x"]).HIDDEN_EFFECT
    assert data["diagnosis"]["effects"][0]["effect"] == name
    assert data["diagnosis"]["gap_after"] < 0.5 * data["diagnosis"]["gap_before"]
    assert {r["policy"] for r in data["estimators_in_the_loop"]} == {"slip-pi", "est+slip-pi[ekf-rls]",
                                                                      "est+slip-pi[mhe]"}
    index = (out / "index.md").read_text()
    for link in ("demo_dry.png", "estimators_in_the_loop.png", "corrected_simulator.png", "diagnosis/report.md"):
        assert link in index and (out / link).is_file()


def test_demo_rejects_unknown_road(tmp_path, capsys):
    assert main(["demo", "--roads", "gravel", "--out", str(tmp_path / "demo")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown road 'gravel'; valid: dry, wet" in err
    assert not (tmp_path / "demo").exists()


def test_bench_env_writes_medians_and_ratio(tmp_path):
    out_json = tmp_path / "bench.json"
    assert main(["bench", "env", "--repeats", "1", "--steps", "50", "--json", str(out_json)]) == 0
    data = json.loads(out_json.read_text())
    assert data["single_steps_per_s"] > 0 and data["pendulum_steps_per_s"] > 0
    assert data["single_vs_pendulum"] == pytest.approx(data["single_steps_per_s"] / data["pendulum_steps_per_s"])


def test_bench_all_leaves_out_the_slow_gap_target(monkeypatch):
    from fricenv.commands import bench

    called = []
    stubs = {name: (lambda args, name=name: called.append(name) or {}) for name in bench.TARGETS}
    monkeypatch.setattr(bench, "TARGETS", stubs)
    assert main(["bench", "--repeats", "1"]) == 0
    assert "gap" not in called
    assert {"env", "vector", "estimators", "ppo"} <= set(called)
    called.clear()
    assert main(["bench", "gap", "--repeats", "1"]) == 0
    assert called == ["gap"]


@pytest.mark.slow
def test_bench_gap_writes_diagnosis_seconds_and_speed_reconstruction(tmp_path):
    out_json = tmp_path / "bench.json"
    assert main(["bench", "gap", "--repeats", "1", "--json", str(out_json)]) == 0
    data = json.loads(out_json.read_text())
    assert set(data["gap_diagnose_seconds"]) == {"all_channels", "required_only"}
    assert all(s > 0 for s in data["gap_diagnose_seconds"].values())
    assert set(data["gap_diagnose_seconds_numpy"]) == {"all_channels", "required_only"}
    assert data["gap_speedup"]["all_channels"] == pytest.approx(
        data["gap_diagnose_seconds_numpy"]["all_channels"] / data["gap_diagnose_seconds"]["all_channels"])
    ms = data["speed_reconstruction_ms"]
    assert ms["newton"] > 0 and ms["ratio"] == pytest.approx(ms["sequential"] / ms["newton"])
