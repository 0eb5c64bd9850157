"""The one policy-spec parser: controllers, estimator pipelines and trained run directories; clear errors."""

from __future__ import annotations

import json

import pytest

from agents.controllers import CONTROLLERS
from agents.evaluation import parse_policy
from agents.policy_spec import PolicySpec, PolicySpecError, parse_policy_spec
from fricenv.envs.estimator_observation import ESTIMATOR_NAMES


def _run_dir(tmp_path, **meta):
    d = tmp_path / "run"
    d.mkdir()
    (d / "train.json").write_text(json.dumps(meta))
    return d


def test_controllers_and_the_observation_they_need():
    for name in CONTROLLERS:
        spec = parse_policy_spec(name)
        assert (spec.label, spec.kind, spec.source, spec.estimator) == (name, "controller", name, "none")
        assert spec.observation == ("oracle" if name in ("oracle-slip", "slip-pi") else "default")


def test_pipelines_take_every_observation_estimator_but_none():
    for est in ESTIMATOR_NAMES[1:]:
        spec = parse_policy_spec(f"pipeline:{est}")
        assert (spec.label, spec.kind, spec.estimator) == (f"est+slip-pi[{est}]", "pipeline", est)
    with pytest.raises(PolicySpecError, match="unknown pipeline estimator 'none'; valid: ekf, mhe, ekf-rls"):
        parse_policy_spec("pipeline:none")


def test_a_trained_run_is_read_from_its_metadata(tmp_path):
    d = _run_dir(tmp_path, env="braking", estimator="ekf-rls", algo="sac",
                 env_kwargs={"observation": "oracle", "road": "wet"})
    spec = parse_policy_spec(str(d))
    assert spec == PolicySpec("sac[ekf-rls]", "trained", str(d), estimator="ekf-rls", observation="oracle",
                              algo="sac", env_kwargs={"observation": "oracle", "road": "wet"})
    assert parse_policy(str(d)) == spec  # agents.evaluation parses with the same parser


def test_wrong_specs_are_rejected_with_the_valid_forms(tmp_path):
    with pytest.raises(PolicySpecError) as err:
        parse_policy_spec("fuzzy-abs")
    assert isinstance(err.value, ValueError)
    for form in (*CONTROLLERS, "pipeline:<estimator>", "train.json"):
        assert form in str(err.value)
    payload = _run_dir(tmp_path, env="payload", estimator="rls")
    with pytest.raises(PolicySpecError, match="is a payload policy; only braking policies"):
        parse_policy_spec(str(payload))
    (payload / "train.json").write_text("{not json")
    with pytest.raises(PolicySpecError, match="unreadable training metadata"):
        parse_policy_spec(str(payload))
    with pytest.raises(PolicySpecError, match="a policy spec is a string"):
        parse_policy_spec(3)
