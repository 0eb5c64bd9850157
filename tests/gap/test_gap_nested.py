"""The nested test: a candidate counts only for what its effect adds to its own road (candidates.test_against)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from fricenv.effects.quarter_car import make_effect
from fricenv.gap.quarter_car import candidates
from fricenv.gap.quarter_car.config import DiagnoseConfig
from fricenv.gap.quarter_car.fitting import fit_nominal, refine_noise, score
from fricenv.gap.quarter_car.params import param_names
from fricenv.gap.quarter_car.simulate import AX_NOISE_STD, OMEGA_NOISE_VAR, V_NOISE_STD, simulate_log
from fricenv.gap.quarter_car.verdict import significant
from fricenv.gap.quarter_car.windows import prepare
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import ROADS

CFG = DiagnoseConfig(jobs=1)
DRY = ROADS["dry"].as_array()
# a road that brakes like the dry one below the peak and differs beyond it: what an over-fitted nominal road is
OFF_PEAK = DRY * np.array([1.25, 0.9, 1.0, 0.97])


def _data(effects: list):
    log, _ = simulate_log(effects, ROADS["dry"], driver="open-loop", seed=11)
    d = prepare(log, qc.PAPER_PARAMS, CFG)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        refine_noise(fit_nominal(d, CFG), d)
    return d


def _gain_fit(road: np.ndarray, gain: float, d):
    return score("brake_gain", ["brake_gain"], param_names(["brake_gain"]), np.r_[road, gain], d, 0.0)


def test_a_better_road_with_its_effect_switched_off_is_not_an_effect():
    """A nominal log: the calibrated nominal road is off the peak, and a brake-gain candidate at the true road
    with a gain of exactly 1 beats it by far. The effect adds nothing to its own road, so it is not significant
    (without the nested test it would be)."""
    d = _data([])
    nominal = score("nominal", [], param_names([]), OFF_PEAK, d, 0.0)
    cand = _gain_fit(DRY, 1.0, d)
    candidates.test_against(nominal, cand, d)
    assert cand.z_paired > CFG.sig_z  # the road alone beats the nominal model ...
    assert cand.z_without == pytest.approx(0.0, abs=1e-9)  # ... and the gain adds nothing to it
    assert not significant(cand, nominal, CFG)
    at_own_road = score("nominal", [], param_names([]), DRY, d, 0.0)
    assert np.array_equal(candidates.without_effects(cand, d).window_mse, at_own_road.window_mse)


def test_an_effect_that_closes_the_gap_passes_both_tests():
    """A brake gain of 0.8 in the log: the fitted gain beats the nominal model and its own road without it."""
    d = _data([make_effect("brake_gain", gain=0.8)])
    nominal = score("nominal", [], param_names([]), OFF_PEAK, d, 0.0)
    cand = _gain_fit(DRY, 0.8, d)
    candidates.test_against(nominal, cand, d)
    assert cand.z_without > CFG.sig_z
    assert significant(cand, nominal, CFG)
    candidates.test_against(nominal, nominal, d)
    assert nominal.z_without is None  # the nominal model has no effect to switch off


@pytest.mark.slow
def test_the_oracle_applies_the_same_rule():
    """The oracle is the diagnosis' significance rule (nested test included) and its explains rule applied to the
    true model. On a log with a brake gain of 0.8 the true model passes both. On a nominal log whose calibrated
    nominal road is off the peak, the true road with the gain at its off value beats that road by far, yet adds
    nothing over itself, so it is not detectable (it would be by the paired test against the nominal model alone)."""
    from types import SimpleNamespace

    from fricenv.gap.quarter_car.diagnose import diagnose
    from validation.quarter_car_oracle import true_model_oracle

    noise = {"omega": float(np.sqrt(OMEGA_NOISE_VAR)), "v": V_NOISE_STD, "a_x": AX_NOISE_STD}  # what the stand-in drew

    road = dict(zip("BCE", DRY[:3]), theta=DRY[3])
    log, _ = simulate_log([make_effect("brake_gain", gain=0.8)], ROADS["dry"], driver="open-loop", seed=11)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        dg = diagnose(log, cfg=CFG)
    judged = true_model_oracle({"brake_gain": {"gain": 0.8}}, road, dg, CFG, noise)
    assert (judged["detectable"], judged["true_explains"]) == (True, True)

    d = _data([])
    off_peak = SimpleNamespace(data=d, nominal=score("nominal", [], param_names([]), OFF_PEAK, d, 0.0))
    at_road = _gain_fit(DRY, 1.0, d)
    candidates.test_against(off_peak.nominal, at_road, d)
    assert at_road.z_paired > CFG.sig_z  # what the paired test against the nominal model alone would accept
    assert true_model_oracle({"brake_gain": {"gain": 1.0}}, road, off_peak, CFG, noise)["detectable"] is False
