"""The reported peak slip when the shape fit cannot tell shapes apart (:mod:`estimators.curve_shape`, (S5)): the
slip that keeps most friction on the worst plausible shape, where the safest bank peak would lose more than
``MINIMAX_GAIN`` (dry vs wet: a policy braking at dry's 0.19 on wet never shows the fit wet's early peak)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

from estimators.curve_shape import DEFAULT_BANK, MINIMAX_GAIN, MINIMAX_STEP, ShapeFit, ShapeFitParams
from fricenv.plants.tire import DRY, ROADS

NAMES = DEFAULT_BANK.names
BIT = {name: 1 << j for j, name in enumerate(NAMES)}


def _g(road, s: float) -> float:
    return float(road.mu(s)) / road.mu_max


def test_one_plausible_shape_reports_its_own_peak():
    for j, name in enumerate(NAMES):
        assert DEFAULT_BANK.minimax_slip[1 << j] == DEFAULT_BANK.peak_slip[j]
    assert DEFAULT_BANK.minimax_slip[0] == DEFAULT_BANK.peak_slip[0]  # no data: the prior (dry)


def test_dry_or_wet_reports_the_crossing_of_the_two_curves():
    """Between the two peaks the worst of two unimodal curves is largest where they cross (Magic Formula, solved
    with brentq): 0.128, where both keep 97.4 % of their peak, against 91.9 % of wet's at dry's peak slip."""
    wet = ROADS["wet"]
    cross = brentq(lambda s: _g(DRY, s) - _g(wet, s), wet.peak_slip, DRY.peak_slip)
    reported = DEFAULT_BANK.minimax_slip[BIT["dry"] | BIT["wet"]]
    assert reported == pytest.approx(cross, abs=MINIMAX_STEP)
    kept = min(_g(DRY, reported), _g(wet, reported))
    assert kept >= 0.97 and kept > _g(wet, DRY.peak_slip) + MINIMAX_GAIN


def test_close_shapes_keep_the_safest_bank_peak():
    """Dry or snow: dry's peak keeps 98.8 % of snow's friction, the best slip 99.2 %: under MINIMAX_GAIN, so the
    fit reports dry's peak as before (S4); dry or ice likewise reports ice's."""
    assert DEFAULT_BANK.minimax_slip[BIT["dry"] | BIT["snow"]] == DEFAULT_BANK.peak_slip[0]
    assert DEFAULT_BANK.minimax_slip[BIT["dry"] | BIT["ice"]] == DEFAULT_BANK.peak_slip[3]


def test_fit_outputs_the_slip_of_its_plausible_set():
    """With every shape plausible (an infinite ambiguity margin) the output is the table's entry for all of them;
    with exact wet data and the default margin only wet is plausible and its peak is reported."""
    wet = ROADS["wet"]
    wide, default = ShapeFit(1, params=ShapeFitParams(ambiguity=1e12)), ShapeFit(1)
    for s in np.linspace(0.03, 0.4, 100):
        for fit in (wide, default):
            fit.update(np.array([s]), np.array([wet.mu(s)]), np.array([20.0]), np.array([True]))
    assert wide.plausible()[0] == 2 ** len(NAMES) - 1
    assert wide.outputs()[0][0] == DEFAULT_BANK.minimax_slip[-1]
    assert default.plausible()[0] == BIT["wet"] and default.outputs()[0][0] == pytest.approx(wet.peak_slip, abs=1e-9)
