"""`fricenv bench gap` times the compiled and the numpy window simulators in the same run and reports their ratio
(the timings themselves are replaced here: a test must not assert on time)."""

import argparse
import json

import pytest

from fricenv import bench_targets
from fricenv.gap.quarter_car.diagnose import DiagnoseConfig


def test_bench_gap_reports_both_paths_and_their_ratio(monkeypatch, tmp_path):
    calls = []

    def fake_seconds(log, compiled):
        calls.append((log.v is not None, compiled))
        wall = (2.0 if compiled else 9.0) if log.v is not None else (3.0 if compiled else 6.0)
        return wall, 1.5 * wall  # CPU seconds of the process and its workers

    monkeypatch.setattr(bench_targets, "_diagnose_seconds", fake_seconds)
    monkeypatch.setattr(bench_targets, "_speed_reconstruction_ms", lambda log: (1.0, 4.0))
    monkeypatch.setattr(bench_targets, "_gap_log", lambda seed, all_channels: argparse.Namespace(
        v=[0.0] if all_channels else None))
    out = bench_targets.bench_gap(argparse.Namespace(repeats=2, seed=0))
    assert sorted(calls) == sorted([(True, True), (True, False), (False, True), (False, False)] * 2)
    assert out["gap_diagnose_seconds"] == {"all_channels": 2.0, "required_only": 3.0}
    assert out["gap_diagnose_seconds_numpy"] == {"all_channels": 9.0, "required_only": 6.0}
    assert out["gap_speedup"] == {"all_channels": pytest.approx(4.5), "required_only": pytest.approx(2.0)}
    assert out["gap_diagnose_cpu_seconds"] == {"all_channels": 3.0, "required_only": 4.5}
    assert out["gap_diagnose_cpu_seconds_numpy"] == {"all_channels": 13.5, "required_only": 9.0}
    json.dumps(out)  # --json writes it


def test_the_numpy_path_is_a_config_switch_that_reaches_the_windows():
    from fricenv.gap.quarter_car.simulate import simulate_log
    from fricenv.gap.quarter_car.windows import prepare
    from fricenv.plants.quarter_car import PAPER_PARAMS
    from fricenv.plants.tire import WET

    log, _ = simulate_log([], WET, "open-loop", seed=1, duration=1.5)
    assert prepare(log, PAPER_PARAMS, DiagnoseConfig()).compiled
    assert not prepare(log, PAPER_PARAMS, DiagnoseConfig(compiled=False)).compiled


def test_the_cpu_seconds_count_the_worker_processes(monkeypatch):
    """A diagnosis whose CPU runs in a child process that has ended is counted (the pool's workers end with it)."""
    import multiprocessing

    def burn():
        t = bench_targets._cpu_seconds()
        while bench_targets._cpu_seconds() - t < 0.3:
            pass

    def diagnose_in_a_child(log, cfg):
        proc = multiprocessing.get_context("fork").Process(target=burn)
        proc.start()
        proc.join()
        assert cfg.jobs == bench_targets.GAP_JOBS

    monkeypatch.setattr("fricenv.gap.quarter_car.diagnose.diagnose", diagnose_in_a_child)
    cpu = bench_targets._diagnose_seconds(None, True)[1]
    assert cpu >= 0.3  # the child's 0.3 s, though this process only waited
