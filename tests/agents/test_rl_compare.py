"""`fricenv compare --train-seeds`: every row trained on each seed, the JSON rows and the training list."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from agents import evaluation
from agents.evaluation import COMPARE_KEYS, TRAINING_KEYS, _run_trainings, _training_jobs

ROOT = Path(__file__).resolve().parents[2]


def test_training_jobs_cover_every_row_and_seed(tmp_path):
    jobs = _training_jobs(tmp_path, ["none", "ekf-rls"], ["ppo-stack4", "recurrent-ppo"], "ppo", 1000, [0, 1, 2])
    assert len(jobs) == 12
    assert jobs["ppo-ekf-rls#s2"]["out"] == tmp_path / "ppo-ekf-rls-s2"
    assert (jobs["ppo-stack4#s1"]["frame_stack"], jobs["ppo-stack4#s1"]["estimator"]) == (4, "none")
    assert jobs["recurrent-ppo#s0"]["algo"] == "recurrent-ppo"
    assert {j["seed"] for j in jobs.values()} == {0, 1, 2}
    with pytest.raises(ValueError, match="memory baseline"):
        _training_jobs(tmp_path, ["none"], ["lstm"], "ppo", 1000, [0])


def test_the_longest_trainings_start_first_and_results_keep_the_jobs_order(tmp_path, monkeypatch):
    """The RecurrentPPO trainings (about 5x a PPO one per step) start first, so that none runs alone at the end of
    ``fricenv compare``; the metadata come back in the jobs' order."""
    jobs = list(_training_jobs(tmp_path, ["none", "ekf-rls"], ["recurrent-ppo"], "ppo", 1000, [0, 1]).values())
    started = []

    def fake_map(fn, tasks, jobs_, label, ray=None):
        started.extend(t[0]["out"].name for t in tasks)
        return [{"run": t[0]["out"].name} for t in tasks]

    monkeypatch.setattr(evaluation, "map_tasks", fake_map)
    metas = _run_trainings(jobs, 2)
    assert started[:2] == ["recurrent-ppo-s0", "recurrent-ppo-s1"]
    assert [m["run"] for m in metas] == [j["out"].name for j in jobs]


@pytest.mark.slow
def test_compare_json_has_one_row_per_train_seed(tmp_path):
    out = tmp_path / "cmp.json"
    res = subprocess.run([sys.executable, "-m", "fricenv", "compare", "--estimators", "ekf-rls", "--baselines",
                          "ppo-stack4", "--train-seeds", "0", "1", "--steps", "512", "--seeds", "1", "--workers",
                          "2", "--out", str(tmp_path / "runs"), "--json", str(out)], cwd=ROOT, capture_output=True,
                         text=True, timeout=1800, check=False)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.startswith("budget: 4 trainings")
    data = json.loads(out.read_text())
    trained = [r for r in data["rows"] if r["train_seed"] is not None]
    assert all(set(COMPARE_KEYS) <= set(r) for r in data["rows"])
    assert {(r["policy"], r["train_seed"]) for r in trained} == {
        ("ppo[ekf-rls]", 0), ("ppo[ekf-rls]", 1), ("ppo-stack4[none]", 0), ("ppo-stack4[none]", 1)}
    assert len(trained) == 4 * 12  # every scenario of the set for each trained policy and seed
    assert [set(TRAINING_KEYS) <= set(t) for t in data["training"]] == [True] * 4
    assert {(t["estimator"], t["train_seed"]) for t in data["training"]} == {("ekf-rls", 0), ("ekf-rls", 1),
                                                                              ("none", 0), ("none", 1)}
