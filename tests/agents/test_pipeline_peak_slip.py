"""The pipeline's slip reference is the estimator's peak slip when it reports one (the EKF/RLS shape fit)."""

from __future__ import annotations

import numpy as np
import pytest

from agents.controllers import SLIP_REF_MAX, slip_reference
from agents.pipeline import SAFE_SLIP_REF, STALE_STEPS, EstimatedPeakSource, assumed_shape
from estimators.base import Health
from fricenv.plants.tire import DRY, MagicFormula

VALUES = {"v_hat": np.array([20.0]), "wheel_speed": np.array([60.0])}  # wheel surface speed 18 m/s (r = 0.3)


@pytest.mark.parametrize("peak, expected", [(0.088, 0.088), (0.389, 0.389), (1.0, SLIP_REF_MAX)])
def test_reported_peak_slip_is_the_reference_capped(peak, expected):
    from agents.pipeline import DITHER_STEPS

    src = EstimatedPeakSource(lambda: ({"peak_slip": peak}, int(Health.OK)), assumed_shape("ekf-rls"), 0.3)
    lam = np.array([src(VALUES)[1][0] for _ in range(DITHER_STEPS)])  # one period of the dither
    assert lam.mean() == pytest.approx(expected, abs=1e-12) and not src.fallback


def test_without_peak_slip_the_assumed_shape_sets_the_reference_and_staleness_falls_back():
    health = {"value": int(Health.OK)}
    src = EstimatedPeakSource(lambda: ({"peak_slip": float("nan")}, health["value"]), assumed_shape("ekf-rls"), 0.3)
    _, lam = src(VALUES)
    dry_shape = MagicFormula(DRY.B, DRY.C, DRY.E, 1.0)
    assert lam[0] == pytest.approx(slip_reference(dry_shape)[0], abs=1e-3)  # NaN: the assumed (dry) shape's peak
    health["value"] = int(Health.SOLVER_FAILED)
    for _ in range(STALE_STEPS):
        _, lam = src(VALUES)
    assert src.fallback and lam[0] == SAFE_SLIP_REF


def test_ekf_rls_estimate_carries_peak_slip():
    from estimators.registry import make_estimator

    est = make_estimator("ekf-rls")
    assert "peak_slip" in est.names
    assert est.reset(v0=20.0).values["peak_slip"] == pytest.approx(DRY.peak_slip, abs=1e-8)  # the prior: dry


def test_reported_peak_slip_is_dithered_around_its_value_and_the_assumed_shape_is_not():
    from agents.pipeline import DITHER_AMPLITUDE, DITHER_STEPS

    src = EstimatedPeakSource(lambda: ({"peak_slip": 0.088}, int(Health.OK)), assumed_shape("ekf-rls"), 0.3)
    refs = np.array([src(VALUES)[1][0] for _ in range(DITHER_STEPS)])
    assert refs.mean() == pytest.approx(0.088, abs=1e-12)  # a full period of the sine averages out
    assert refs.max() <= 0.088 * (1 + DITHER_AMPLITUDE) + 1e-12
    assert refs.max() >= 0.088 * (1 + 0.99 * DITHER_AMPLITUDE)
    plain = EstimatedPeakSource(lambda: ({}, int(Health.OK)), assumed_shape("ekf-rls"), 0.3)
    assert len({plain(VALUES)[1][0] for _ in range(DITHER_STEPS)}) == 1  # no shape fit to excite: no dither
