"""SB3 training (a few hundred steps), save/load, evaluation determinism and outputs, CLI verbs."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from agents.evaluation import (
    ROW_KEYS,
    SCENARIOS,
    Scenario,
    evaluate,
    parse_policy,
    run_episode,
    summarize_policies,
    write_outputs,
)
from agents.training import PPOConfig, SACConfig, ScenarioMix, load_policy, train
from fricenv.envs.factory import make_braking

pytestmark = pytest.mark.filterwarnings("ignore:tensorboard is not installed")

TINY_PPO = PPOConfig(n_envs=2, n_steps=128, batch_size=64, n_epochs=2)


@pytest.fixture(scope="module")
def ppo_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("ppo-ekf-rls")
    result = train(out, estimator="ekf-rls", algo="ppo", steps=256, seed=3, config=TINY_PPO, progress_bar=False,
                   checkpoint_every=128)
    return out, result


def test_ppo_trains_saves_and_loads_back(ppo_run):
    out, result = ppo_run
    assert result.steps == 256
    for name in ("model.zip", "vecnormalize.pkl", "train.json"):
        assert (out / name).is_file()
    assert list((out / "checkpoints").glob("ppo_*_steps.zip"))
    meta = json.loads((out / "train.json").read_text())
    assert meta["estimator"] == "ekf-rls" and meta["algo"] == "ppo" and meta["steps"] == 256
    assert meta["config"]["n_envs"] == 2 and meta["torch_threads"] == 1
    policy = load_policy(out)
    env = make_braking("ekf-rls", road="dry")
    obs, _ = env.reset(seed=0)
    a1, a2 = policy.act(obs), policy.act(obs)
    assert a1.shape == (1,) and env.action_space.contains(a1)
    np.testing.assert_array_equal(a1, a2)  # deterministic
    # the loaded normalisation is the trained one, frozen
    assert policy.vecnormalize.training is False
    assert policy.vecnormalize.obs_rms.count > 1


def test_sac_trains_saves_and_loads_back(tmp_path):
    cfg = SACConfig(n_envs=1, learning_starts=50, batch_size=32, buffer_size=1000, net_arch=(32, 32))
    result = train(tmp_path, estimator="oracle", algo="sac", steps=120, seed=0, config=cfg, progress_bar=False,
                   checkpoint_every=0)
    assert result.steps == 120
    policy = load_policy(tmp_path)
    obs, _ = make_braking("oracle").reset(seed=0)
    assert policy.act(obs).shape == (1,)


def test_train_rejects_bad_options(tmp_path):
    with pytest.raises(ValueError, match="ppo, sac"):
        train(tmp_path, algo="a2c", steps=10)
    with pytest.raises(ValueError, match="ekf-rls"):
        train(tmp_path, estimator="ukf", steps=10)
    with pytest.raises(TypeError, match="SACConfig"):
        train(tmp_path, algo="sac", steps=10, config=TINY_PPO)
    with pytest.raises(ValueError, match="not a training run"):
        load_policy(tmp_path)


def test_scenario_mix_draws_presets_and_changes():
    env = ScenarioMix(make_braking("none"), change_probability=0.5)
    roads = set()
    _, info = env.reset(seed=0)
    roads.add(info["road"])
    v0s = []
    for _ in range(40):
        _, info = env.reset()
        roads.add(info["road"])
        v0s.append(env.unwrapped.sim.v0[0])
    assert any("->" in r for r in roads) and any("->" not in r for r in roads)
    assert 15.0 <= min(v0s) < max(v0s) <= 32.0
    with pytest.raises(ValueError, match="change_probability"):
        ScenarioMix(make_braking("none"), change_probability=1.5)


def test_scenario_set_covers_roads_speeds_and_transitions():
    names = {s.name for s in SCENARIOS}
    for road in ("dry", "wet", "snow", "ice", "dry->ice", "ice->dry"):
        for v0 in (20, 30):
            assert f"{road}@{v0}" in names


def test_evaluation_is_deterministic_for_a_fixed_seed(ppo_run):
    out, _ = ppo_run
    scen = [Scenario("dry->ice", 20.0)]
    policies = ["rule-abs", "pipeline:ekf-rls", str(out)]
    a = evaluate(policies, scenarios=scen, seeds=[4], workers=1, progress=False)
    b = evaluate(policies, scenarios=scen, seeds=[4], workers=1, progress=False)
    assert a == b
    assert [r["policy"] for r in a] == ["rule-abs", "est+slip-pi[ekf-rls]", "ppo[ekf-rls]"]
    c = evaluate(["rule-abs"], scenarios=scen, seeds=[5], workers=1, progress=False)
    assert c[0]["ratio_mean"] != a[0]["ratio_mean"]  # another seed, other noise


def test_run_episode_figures_match_the_env():
    spec = parse_policy("oracle-slip")
    res = run_episode(spec, Scenario("dry", 20.0), seed=0)
    assert res["stopped"] and not res["lock"]
    assert 1.0 < res["ratio"] < 1.02  # oracle slip controller: ~1.006 on dry
    assert res["slip_err"] < 0.05


def test_outputs_and_summary(tmp_path):
    rows = evaluate(["rule-abs", "locked"], scenarios=[Scenario("dry", 20.0)], seeds=2, workers=1, progress=False)
    written = write_outputs(rows, tmp_path / "out", tmp_path / "rows.json")
    data = json.loads((tmp_path / "rows.json").read_text())
    assert set(data) == {"rows"}
    for r in data["rows"]:
        assert {"policy", "estimator", "scenario", "ratio_mean", "ratio_std", "locks"} <= set(r)
    with open(written["csv"]) as fh:
        assert next(csv.reader(fh)) == list(ROW_KEYS)
    assert written["png"].read_bytes()[:4] == b"\x89PNG"
    by = {r["policy"]: r for r in rows}
    assert by["locked"]["locks"] == 2 and by["rule-abs"]["locks"] == 0
    assert by["locked"]["ratio_mean"] > by["rule-abs"]["ratio_mean"]
    summary = {s["policy"]: s for s in summarize_policies(rows)}
    assert summary["locked"]["ratio_worst"] == pytest.approx(by["locked"]["ratio_mean"])


def test_parse_policy_errors():
    with pytest.raises(ValueError, match="pipeline:<estimator>"):
        parse_policy("fuzzy-abs")
    with pytest.raises(ValueError, match="ekf-rls"):
        parse_policy("pipeline:none")


def test_cli_train_and_evaluate(tmp_path, capsys):
    from fricenv.cli import main

    run = tmp_path / "run"
    assert main(["train", "--estimator", "oracle", "--steps", "64", "--out", str(run), "--no-progress",
                 "--json", str(tmp_path / "train.json")]) == 0
    assert json.loads((tmp_path / "train.json").read_text())["steps"] >= 64
    assert main(["evaluate", "--policy", "rule-abs", "--seeds", "1", "--workers", "1", "--out",
                 str(tmp_path / "eval"), "--json", str(tmp_path / "eval.json")]) == 0
    rows = json.loads((tmp_path / "eval.json").read_text())["rows"]
    assert len(rows) == len(SCENARIOS)
    assert "ratio" in capsys.readouterr().out


@pytest.mark.parametrize("estimator, obs_dim", [("none", 12), ("rls", 22)])
def test_payload_excitation_policy_trains_with_and_without_S_hat(tmp_path, estimator, obs_dim):
    from fricenv.envs.factory import make_payload

    result = train(tmp_path, env="payload", estimator=estimator, steps=128, seed=0, config=TINY_PPO,
                   progress_bar=False, checkpoint_every=0)
    assert result.meta["env"] == "payload" and result.meta["estimator"] == estimator
    policy = load_policy(tmp_path)
    assert policy.model.observation_space.shape == (obs_dim,)
    obs, _ = make_payload(estimator).reset(seed=0)
    assert policy.act(obs).shape == (3,)
    with pytest.raises(ValueError, match="rls"):
        train(tmp_path, env="payload", estimator="ekf", steps=10)


@pytest.mark.slow
def test_ppo_with_ekf_rls_estimates_brakes_near_the_limit(tmp_path):
    """PPO + EKF/RLS with the committed hyperparameters (log torque map, lock-onset penalty), 500k steps on
    training seed 0: dry and ice at 20 m/s over evaluation seeds 0 and 1, each within 5 % of the physical limit and
    no wheel lock (part of the policies' target; wet and the friction jumps are not asserted here).

    Takes about 5 min on a loaded 2-core machine; with a linear torque map and no onset penalty it locks the
    wheel on ice in both episodes.
    """
    train(tmp_path, estimator="ekf-rls", steps=500_000, seed=0, progress_bar=False, checkpoint_every=0)
    rows = evaluate([str(tmp_path)], scenarios=[Scenario("dry", 20.0), Scenario("ice", 20.0)], seeds=2,
                    workers=1, progress=False)
    for r in rows:
        assert r["ratio_mean"] <= 1.05 and r["locks"] == 0, r


def test_two_runs_of_one_algorithm_get_distinct_rows(ppo_run, tmp_path):
    import shutil

    out, _ = ppo_run
    other = tmp_path / "second-run"
    shutil.copytree(out, other)
    rows = evaluate([str(out), str(other)], scenarios=[Scenario("dry", 20.0)], seeds=1, workers=1, progress=False)
    assert [r["policy"] for r in rows] == [f"ppo[ekf-rls]@{out.name}", "ppo[ekf-rls]@second-run"]
    assert rows[0]["ratio_mean"] == rows[1]["ratio_mean"]  # same policy, same seed
    with pytest.raises(ValueError, match="distinct"):
        evaluate(["rule-abs", "rule-abs"], scenarios=[Scenario("dry", 20.0)], seeds=1, workers=1, progress=False)


def test_the_train_commands_choices_are_the_librarys():
    """The command names its choices without importing the library (start-up time); they must not drift."""
    from agents.commands.train import BRAKING_ESTIMATORS, VEC_CHOICES
    from agents.training import VEC_KINDS
    from fricenv.envs.estimator_observation import ESTIMATOR_NAMES

    assert BRAKING_ESTIMATORS == ESTIMATOR_NAMES
    assert tuple(VEC_CHOICES) == tuple(VEC_KINDS)
