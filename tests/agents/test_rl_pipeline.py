"""The estimator + slip-controller pipeline stops on every road and both friction jumps, without a lock."""

from __future__ import annotations

import pytest

from agents.evaluation import SCENARIOS, parse_policy, run_episode

PIPELINE_RATIO_MAX = 1.3  # the bound for the classical pipeline


@pytest.mark.slow
@pytest.mark.parametrize("scenario", SCENARIOS, ids=lambda s: s.name)
def test_ekf_rls_pipeline_stops_without_lock(scenario):
    res = run_episode(parse_policy("pipeline:ekf-rls"), scenario, seed=0)
    assert res["stopped"], scenario.name
    assert not res["lock"], scenario.name
    assert res["ratio"] <= PIPELINE_RATIO_MAX, (scenario.name, res["ratio"])


def test_stale_or_implausible_estimate_falls_back_to_the_safe_reference():
    import numpy as np

    from agents.pipeline import BELOW_STEPS, SAFE_SLIP_REF, STALE_STEPS, EstimatedPeakSource
    from estimators.base import Health
    from fricenv.plants.tire import ROADS

    assert all(SAFE_SLIP_REF < road.peak_slip for road in ROADS.values())  # stable side of every preset road
    health = {"value": int(Health.OK)}
    src = EstimatedPeakSource(lambda: ({}, health["value"]), wheel_radius=0.3)
    values = {"v_hat": np.array([20.0]), "wheel_speed": np.array([60.0])}  # wheel surface speed 18 m/s
    v, lam = src(values)
    assert not src.fallback and v[0] == 20.0 and lam[0] > SAFE_SLIP_REF
    health["value"] = int(Health.SOLVER_FAILED)
    for _ in range(STALE_STEPS - 1):
        src(values)
    assert not src.fallback  # held reference while fewer than STALE_STEPS updates failed
    v, lam = src(values)
    assert src.fallback and lam[0] == SAFE_SLIP_REF  # stale: the safe reference
    health["value"] = int(Health.OK)
    src(values)
    assert not src.fallback  # usable again
    low = {"v_hat": np.array([10.0]), "wheel_speed": np.array([60.0])}  # v_hat 8 m/s below the wheel
    for _ in range(BELOW_STEPS - 1):
        src(low)
    assert not src.fallback  # a short disagreement (a wheel-speed spike) is tolerated
    v, lam = src(low)
    assert src.fallback and v[0] == 18.0 and lam[0] == SAFE_SLIP_REF
    v, lam = src({"v_hat": np.array([np.nan]), "wheel_speed": np.array([60.0])})
    assert src.fallback and v[0] == 18.0
