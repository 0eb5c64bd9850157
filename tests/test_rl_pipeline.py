"""The estimator + slip-controller pipeline stops on every road and both friction jumps, without a lock (issue 17)."""

from __future__ import annotations

import pytest

from agents.evaluation import SCENARIOS, parse_policy, run_episode

PIPELINE_RATIO_MAX = 1.3  # issue 17's bound for the classical pipeline


@pytest.mark.slow
@pytest.mark.parametrize("scenario", SCENARIOS, ids=lambda s: s.name)
def test_ekf_rls_pipeline_stops_without_lock(scenario):
    res = run_episode(parse_policy("pipeline:ekf-rls"), scenario, seed=0)
    assert res["stopped"], scenario.name
    assert not res["lock"], scenario.name
    assert res["ratio"] <= PIPELINE_RATIO_MAX, (scenario.name, res["ratio"])
