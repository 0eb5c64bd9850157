"""The drift test's parameter shift (fricenv.gap.quarter_car.drift.parameter_shift) on real-like exports of the
independent simulator: a brake fade that a constant brake gain fits within the noise, and a true brake gain."""

from __future__ import annotations

import warnings

import pytest

from fricenv.commands.gap_convert import convert
from fricenv.gap.quarter_car.diagnose import DiagnoseConfig, diagnose_file
from fricenv.gap.quarter_car.drift import SHIFT_SHARE, shift_limit
from validation.independent_model import Effect, Road
from validation.independent_sim import IndependentCase, write_real_log

CFG = DiagnoseConfig(jobs=1)


def _diagnosed(tmp_path, case: IndependentCase):
    csv_path, map_path, _ = write_real_log(tmp_path / "export", case)
    path = tmp_path / "log.contract.csv"
    convert(csv_path, map_path, "quarter-car", path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return diagnose_file(path, cfg=CFG)


def test_the_shift_limit_is_student_t_with_eight_degrees_of_freedom_shared_over_the_parameters():
    assert shift_limit(1, 0.01) == pytest.approx(3.3554, abs=1e-3)  # t_{0.995, 8}
    assert shift_limit(2, 0.01) == pytest.approx(3.8325, abs=1e-3)  # t_{0.9975, 8}


def test_a_brake_fade_whose_constant_gain_fits_within_the_noise_is_unexplained(tmp_path):
    """A brake fade under ABS on a dry road, exported at 38 Hz with the logger's IMU filter. A constant brake gain
    (0.94) leaves no robust gap, so the held-out test cannot tell a drift; refitted on the early and the late half,
    the gain falls from 0.96 to 0.92: ten standard errors of the jackknife, and 0.7 of the gain's distance from 1. It
    read `brake_gain` without this test."""
    fade = {"fade_per_kelvin": 0.0005915391216973759, "heat_capacity": 600.0, "cooling": 30.0}
    case = IndependentCase("out_of_library", (Effect("brake_fade", fade),),
                           Road(8.884876810311908, 1.65, 0.65663, 1.0533790217363301, "dry"), "bosch-abs",
                           25.772077506768895, 0.39286178071459377, ("v", "a_x"), 0.030394664854531794,
                           0.12037808372215893, 1778499576, real={"rate_hz": 37.92067517609655})
    dg = _diagnosed(tmp_path, case)
    drift = dg.where["drift_test"]
    assert drift["model"] == "brake_gain"
    assert drift["robust_gap"] <= CFG.gap_within_noise  # the held-out test has nothing to halve
    gain = drift["shift"]["gain"]
    assert gain["t"] > drift["shift_limit"] and gain["share"] >= SHIFT_SHARE
    assert gain["early"] > gain["late"] + 0.02
    assert drift["drifts"] and dg.verdict == "unexplained" and dg.effects == []


def test_a_constant_brake_gain_does_not_shift(tmp_path):
    """A brake gain of 0.85 under pedal braking on a dry road, exported at 60 Hz: its early and late estimates
    agree within the jackknife's standard errors, and it is named."""
    case = IndependentCase("brake_gain", (Effect("brake_gain", {"gain": 0.8476278014943393}),),
                           Road(11.660285138549906, 1.65, 0.65663, 1.0715517760747355, "dry"), "pedal",
                           18.65231923038787, 0.4581219903238752, ("v", "a_x"), 0.04341854881482057,
                           0.10041807869976804, 1501337517, real={"rate_hz": 60.43794570848066})
    dg = _diagnosed(tmp_path, case)
    drift = dg.where["drift_test"]
    assert abs(drift["shift"]["gain"]["t"]) < drift["shift_limit"] and not drift["drifts"]
    assert dg.verdict == "brake_gain"
    assert dg.params["gain"] == pytest.approx(0.8476, rel=0.03)


def test_a_significant_shift_smaller_than_half_the_effect_is_no_drift(tmp_path):
    """A radius error (0.356 m) on ice under the sine driver, exported at 88 Hz: the radius is read 0.357 m on the
    early half and 0.363 m on the late one, about five standard errors of the jackknife but only 0.38 of the
    radius error's size. A bias that small in a precise parameter is no drift: the radius error is named."""
    case = IndependentCase("radius_error", (Effect("radius_error", {"r_eff": 0.3560164541605212}),),
                           Road(4.414774473922794, 2.0, 1.0, 0.09944504711120548, "ice"), "sine",
                           25.898115562350345, 0.46403165036402355, ("v", "a_x"), 0.03501949828600592,
                           0.11151842467719286, 1718132609, real={"rate_hz": 88.10043500020328})
    dg = _diagnosed(tmp_path, case)
    drift = dg.where["drift_test"]
    radius = drift["shift"]["r_eff"]
    assert abs(radius["t"]) > drift["shift_limit"] and radius["share"] < SHIFT_SHARE
    assert not drift["drifts"] and dg.verdict == "radius_error"

def test_a_drift_level_outside_zero_to_one_is_rejected():
    from fricenv.gap.quarter_car.diagnose import diagnose
    from fricenv.gap.quarter_car.simulate import simulate_log
    from fricenv.plants.tire import ROADS

    log, _ = simulate_log([], ROADS["dry"], "abs", seed=1, duration=1.0)
    with pytest.raises(ValueError, match=r"drift_alpha must lie in \(0, 1\), got 0.0"):
        diagnose(log, cfg=DiagnoseConfig(drift_alpha=0.0))
