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


# ---------------------------------------------------------------- the same test for an effect added to a set
DRAG = {"c0": 150.0, "c2": 0.5}


def _set_fit(effects: list[str], x_effects: list[float], d):
    return score("+".join(effects), effects, param_names(effects), np.r_[DRY, x_effects], d, 0.0)


def test_an_addition_that_only_moves_the_sets_parameters_adds_nothing_of_its_own():
    """A drag log. The set is drag at a c0 well off its value; the joint model is drag at its true values plus a
    brake gain of exactly 1. The joint model beats the set by far, yet with its gain switched off it is the same
    model: the addition's own share is 0, so the forward selection must not name the brake gain."""
    from fricenv.gap.quarter_car.stats import paired_z

    d = _data([make_effect("drag", **DRAG)])
    off_set = _set_fit(["drag"], [60.0, DRAG["c2"]], d)
    joint = _set_fit(["drag", "brake_gain"], [DRAG["c0"], DRAG["c2"], 1.0], d)
    assert paired_z(off_set, joint, d) > CFG.sig_z  # what the test over the set alone would accept
    switched_off = candidates.without_effects(joint, d, keep=["drag"])
    assert np.array_equal(switched_off.window_mse, _set_fit(["drag"], [DRAG["c0"], DRAG["c2"]], d).window_mse)
    assert paired_z(switched_off, joint, d) == pytest.approx(0.0, abs=1e-9)


def test_a_true_second_effect_keeps_its_own_share():
    """Drag and a brake gain of 0.8 in the log: the joint model at the true values beats itself with the gain
    switched off by far."""
    from fricenv.gap.quarter_car.stats import paired_z

    d = _data([make_effect("drag", **DRAG), make_effect("brake_gain", gain=0.8)])
    joint = _set_fit(["drag", "brake_gain"], [DRAG["c0"], DRAG["c2"], 0.8], d)
    assert paired_z(candidates.without_effects(joint, d, keep=["drag"]), joint, d) > CFG.sig_z


def test_the_forward_selection_does_not_add_an_effect_that_adds_nothing(monkeypatch):
    """The first test's models through the forward selection (its joint fit stubbed by the constructed joint
    model): the step records the addition's test over the set and its own share, and the set stays drag."""
    from fricenv.gap.quarter_car import selection
    from fricenv.gap.quarter_car.context import FitContext

    d = _data([make_effect("drag", **DRAG)])
    off_set = _set_fit(["drag"], [60.0, DRAG["c2"]], d)
    joint = _set_fit(["drag", "brake_gain"], [DRAG["c0"], DRAG["c2"], 1.0], d)
    gain = _gain_fit(DRY, 1.0, d)
    monkeypatch.setattr(selection, "_extend", lambda ctx, nominal, current, extra, known: [joint for _ in extra])
    ctx = FitContext(d, (d,), CFG, 1)
    whole, steps = selection.forward_select(ctx, off_set, off_set, [off_set, gain])
    assert whole is off_set
    assert len(steps) == 1 and steps[0]["effect"] == "brake_gain" and not steps[0]["added"]
    assert steps[0]["z_over_set"] > CFG.sig_z and steps[0]["z_own"] == pytest.approx(0.0, abs=1e-9)
