"""``fricenv tune`` (agents.tuning): the seed split, argument errors, determinism, resume on a shared storage,
parallel workers (processes and Ray), and one real tiny trial whose file ``fricenv train --hyperparams`` reads."""

from __future__ import annotations

import dataclasses
import json

import pytest

from agents.evaluation import DEFAULT_SEEDS
from agents.hyperparams import load_hyperparams
from agents.training import DEFAULT_CONFIGS, SEED_STRIDE, PPOConfig, SACConfig
from agents.tuning import (
    HYPERPARAMS_FILE,
    TRIALS_FILE,
    TUNING_EVAL_SEEDS,
    TUNING_TRAIN_SEEDS,
    TuneSettings,
    TuningError,
    committed_params,
    config_from_params,
    run_study,
    sample_config,
)
from fricenv.cli import main
from tests.gap.test_ray_fleet import local_ray  # noqa: F401 - the fixture: a local 2-CPU Ray instance

pytest.importorskip("optuna", reason="optuna is a dependency of fricenv (pyproject.toml)")


def stub_objective(trial, settings: TuneSettings) -> float:
    """A cheap deterministic objective over the real search space (no training)."""
    _, cfg = sample_config(trial, settings.algos)
    trial.report(cfg.learning_rate, 0)
    return 100.0 * cfg.learning_rate + getattr(cfg, "vf_coef", 0.0)


def _params(result) -> list[dict]:
    return [t["params"] for t in json.loads(result.trials_path.read_text())["trials"]]


def test_seed_split_is_disjoint_from_the_evaluation_seeds():
    cfg = TuneSettings(out="x")
    max_envs = 64  # more sub-envs than any sampled or committed configuration
    train_env_seeds = {s * SEED_STRIDE + i for s in cfg.train_seeds for i in range(max_envs)}
    compare_env_seeds = {s * SEED_STRIDE + i for s in (0, 1, 2) for i in range(max_envs)}
    evaluation = set(range(max(DEFAULT_SEEDS, 10_000)))  # evaluate/compare reset seeds 0..N-1, N up to 10000
    tuning_eval = set(cfg.eval_seeds)
    assert tuning_eval.isdisjoint(evaluation) and tuning_eval.isdisjoint(train_env_seeds)
    assert train_env_seeds.isdisjoint(compare_env_seeds) and train_env_seeds.isdisjoint(evaluation)
    assert set(cfg.train_seeds).isdisjoint({0, 1, 2})


@pytest.mark.parametrize("change, message", [
    ({"eval_seeds": (2, 900_000)}, "tuning evaluation seeds must be >= 900000"),
    ({"train_seeds": (0,)}, "tuning training seeds must be in [100, 899]"),
    ({"algos": ("tqc",)}, "unknown algorithm(s) ['tqc']; valid: ppo, sac"),
    ({"n_trials": 0}, "n_trials must be a positive integer"),
    ({"steps": 2, "n_evals": 3}, "steps (2) must be at least n_evals (3)"),
    ({"workers": 2}, "several workers or --ray need a shared --storage"),
    ({"ray": "auto"}, "several workers or --ray need a shared --storage"),
    ({"estimator": "kalman"}, "estimator:"),
])
def test_bad_settings_are_one_line_errors(change, message):
    with pytest.raises(TuningError) as err:
        dataclasses.replace(TuneSettings(out="x"), **change).check()
    assert message in str(err.value) and "\n" not in str(err.value)


def test_cli_bad_arguments_are_one_line_exit_2(tmp_path, capsys):
    out = str(tmp_path / "o")
    for argv, expected in [(["tune", "--out", out, "--workers", "2"], "need a shared --storage"),
                           (["tune", "--out", out, "--eval-seeds", "1"], "must be >= 900000"),
                           (["tune", "--out", out, "--storage", "nosuchdb://x/y", "--trials", "1"],
                            "cannot open Optuna storage")]:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("fricenv tune: error:") and expected in err and "\n" not in err, err
    assert not (tmp_path / "o" / HYPERPARAMS_FILE).exists()


def test_new_study_runs_the_committed_configuration_first(tmp_path):
    result = run_study(TuneSettings(out=str(tmp_path / "o"), n_trials=3, algos=("ppo", "sac")), stub_objective)
    trials = json.loads(result.trials_path.read_text())["trials"]
    assert [t["params"] for t in trials[:2]] == [committed_params(a, ("ppo", "sac")) for a in ("ppo", "sac")]
    assert config_from_params(trials[0]["params"], ("ppo", "sac")) == ("ppo", DEFAULT_CONFIGS[("braking", "ppo")])
    assert trials[1]["user_attrs"]["baseline"] == "agents/hyperparams/braking.json"
    assert "baseline" not in trials[2]["user_attrs"]
    plain = run_study(TuneSettings(out=str(tmp_path / "p"), n_trials=1, baseline=False), stub_objective)
    assert _params(plain)[0] != committed_params("ppo", ("ppo",))


def test_same_seed_same_parameters(tmp_path):
    runs = [run_study(TuneSettings(out=str(tmp_path / f"r{i}"), n_trials=3, seed=seed), stub_objective)
            for i, seed in enumerate((5, 5, 6))]
    assert _params(runs[0]) == _params(runs[1])
    assert _params(runs[0]) != _params(runs[2])
    assert len({json.dumps(p, sort_keys=True) for p in _params(runs[0])}) == 3  # three different draws


@pytest.mark.parametrize("storage", ["journal", "sqlite"])
def test_resume_adds_trials_and_new_draws(tmp_path, storage):
    url = str(tmp_path / "study.log") if storage == "journal" else f"sqlite:///{tmp_path / 'study.db'}"
    cfg = TuneSettings(out=str(tmp_path / "out"), n_trials=2, storage=url, algos=("ppo", "sac"))
    first = run_study(cfg, stub_objective)
    second = run_study(cfg, stub_objective)
    assert (first.n_trials, first.n_new, second.n_trials, second.n_new) == (2, 2, 4, 2)
    trials = json.loads(second.trials_path.read_text())["trials"]
    assert [t["number"] for t in trials] == [0, 1, 2, 3] and {t["state"] for t in trials} == {"COMPLETE"}
    assert trials[2]["params"] not in (trials[0]["params"], trials[1]["params"])  # a resume does not repeat draws
    best = min(trials, key=lambda t: t["value"])
    assert second.best["number"] == best["number"]
    written = load_hyperparams(second.hyperparams_path, {"ppo": PPOConfig, "sac": SACConfig})
    algo, cfg_best = config_from_params(best["params"], cfg.algos)
    assert written[algo] == cfg_best
    assert written[algo].learning_rate == pytest.approx(best["params"][f"{algo}_learning_rate"], rel=1e-12)


def test_process_pool_workers_share_the_study(tmp_path):
    cfg = TuneSettings(out=str(tmp_path / "out"), n_trials=5, storage=str(tmp_path / "study.log"), workers=2)
    result = run_study(cfg, stub_objective)
    trials = json.loads(result.trials_path.read_text())["trials"]
    assert result.n_trials == 5 and sorted(t["number"] for t in trials) == [0, 1, 2, 3, 4]
    assert len({json.dumps(t["params"], sort_keys=True) for t in trials}) == 5  # the workers draw apart


@pytest.mark.xdist_group("ray")
@pytest.mark.slow  # Ray workers start and compile in a fresh environment: 80-100 s
def test_ray_workers_share_the_study(tmp_path, local_ray):  # noqa: F811 - pytest fixture
    cfg = TuneSettings(out=str(tmp_path / "out"), n_trials=4, storage=str(tmp_path / "study.log"), workers=2,
                       ray="auto")
    result = run_study(cfg, stub_objective)
    assert local_ray.is_initialized()  # the test's instance was joined and left to the test
    trials = json.loads(result.trials_path.read_text())["trials"]
    assert result.n_trials == 4 and {t["state"] for t in trials} == {"COMPLETE"}
    assert result.best["value"] == min(t["value"] for t in trials)


@pytest.mark.slow
def test_real_tiny_trial_is_read_by_fricenv_train(tmp_path, capsys):
    """One real trial (PPO, no estimator, one training rollout, one evaluation episode per scenario), then
    ``fricenv train --hyperparams`` trains with exactly the tuned configuration."""
    assert main(["-q", "tune", "--out", str(tmp_path / "tune"), "--trials", "1", "--steps", "2048", "--evals", "1",
                 "--estimator", "none", "--eval-seeds", str(TUNING_EVAL_SEEDS[0])]) == 0
    trials = json.loads((tmp_path / "tune" / TRIALS_FILE).read_text())
    (trial,) = trials["trials"]
    assert trial["state"] == "COMPLETE" and trial["user_attrs"]["steps"] >= 2048
    attrs = trial["user_attrs"]
    assert attrs["ratio_worst"] >= attrs["ratio_mean"]
    assert trial["value"] == pytest.approx(attrs["ratio_mean"] + 0.5 * (attrs["ratio_worst"] - 1.0)
                                           + 0.1 * attrs["locks"] / 5, rel=1e-12)
    assert trial["user_attrs"]["ratio_mean"] > 0.99  # no policy stops shorter than the physical limit
    assert trials["seeds"]["tuning_train_seeds"] == list(TUNING_TRAIN_SEEDS)
    hp = tmp_path / "tune" / HYPERPARAMS_FILE
    assert main(["-q", "train", "--hyperparams", str(hp), "--steps", "64", "--out", str(tmp_path / "run"),
                 "--no-progress"]) == 0
    meta = json.loads((tmp_path / "run" / "train.json").read_text())
    _, tuned = config_from_params(trial["params"], ("ppo",))
    assert meta["config"] == json.loads(json.dumps(dataclasses.asdict(tuned)))
