"""The checks of what a report says on blind logs (validation/report_check.py) count what they say they count."""

from types import SimpleNamespace

import numpy as np
import pytest

from fricenv.plants.quarter_car import QuarterCarParams
from validation.report_check import (
    combo_summary,
    miss_kind,
    miss_kinds,
    power_summary,
    right_or_below_size,
    sensor_summary,
    size_ratio,
)

ROAD = {"B": 10.0, "C": 1.9, "E": 0.97, "theta": 1.0}


def _dg(detectable: dict) -> SimpleNamespace:
    return SimpleNamespace(where={"detectable": detectable}, data=SimpleNamespace(p=QuarterCarParams()))


def test_size_ratio_is_the_true_deviation_over_the_reported_size():
    dg = _dg({"brake_gain": {"gain": 0.05}, "mu_change": {"theta_after": 0.2}, "radius_error": {"r_eff": 0.004}})
    assert size_ratio("brake_gain", {"params": {"gain": 1.1}, "road": ROAD}, dg) == pytest.approx(2.0)
    # a friction change is off at the road's theta before it
    assert size_ratio("mu_change", {"params": {"t_change": 1.0, "theta_after": 0.9}, "road": ROAD},
                      dg) == pytest.approx(0.5)
    r = QuarterCarParams().r
    assert size_ratio("radius_error", {"params": {"r_eff": r - 0.002}, "road": ROAD}, dg) == pytest.approx(0.5)
    assert size_ratio("drag", {"params": {"c0": 100.0, "c2": 0.3}, "road": ROAD}, dg) is None


def test_power_summary_splits_at_the_reported_size_and_counts_none_below_it_as_right():
    rows = [{"right": True, "verdict": "brake_gain", "expected": "brake_gain", "size_ratio": 3.0},
            {"right": False, "verdict": "none", "expected": "brake_gain", "size_ratio": 1.5},
            {"right": False, "verdict": "none", "expected": "drag", "size_ratio": 0.4},
            {"right": False, "verdict": "brake_lag", "expected": "brake_delay", "size_ratio": 0.4},
            {"right": False, "verdict": "none", "expected": "radius_error", "size_ratio": None,
             "not_testable": ["radius_error"]}]
    assert [right_or_below_size(r) for r in rows] == [True, False, True, False, True]
    s = power_summary(rows)
    assert s["above"] == {"logs": 2, "right": 1}
    assert s["below"] == {"logs": 2, "right": 0}
    assert s["right_or_below_size"] == pytest.approx(3 / 5)


def test_sensor_summary_counts_flags_per_kind_of_log():
    def row(real, v, a_x, outliers):
        sensors = {"omega": {"filtered": False, "outliers": outliers}}
        if v is not None:
            sensors["v"] = {"filtered": v, "outliers": 0}
        if a_x is not None:
            sensors["a_x"] = {"filtered": a_x, "outliers": 0}
        return {"truth": {"real": {"rate_hz": 50.0} if real else None}, "sensors": sensors}

    rows = [row(True, True, True, 3), row(True, False, None, 2), row(True, None, True, 3), row(False, False, False, 0),
            row(False, None, True, 1), {"verdict": "error", "truth": {"real": None}}]
    s = sensor_summary(rows)
    assert s["real"]["v"] == {"logs": 2, "flagged_filtered": 1}
    assert s["real"]["a_x"] == {"logs": 2, "flagged_filtered": 2}
    assert s["real"]["omega_outliers"] == {"logs": 3, "set_aside": 8}
    assert s["clean"]["v"] == {"logs": 1, "flagged_filtered": 0}
    assert s["clean"]["a_x"] == {"logs": 2, "flagged_filtered": 1}
    assert s["clean"]["omega_outliers"] == {"logs": 2, "set_aside": 1}


def test_a_wrong_verdict_is_classed_by_the_first_reason_that_applies():
    base = {"right": False, "expected": "brake_delay", "verdict": "brake_lag", "detectable": True,
            "confounded": [], "not_testable": []}
    rows = [dict(base, right=True),
            dict(base, detectable=False, confounded=[["brake_delay", "brake_lag"]]),
            dict(base, confounded=[["brake_delay", "brake_lag"]]),
            dict(base, confounded=[["brake_lag", "brake_delay", "drag"]]),
            dict(base, verdict="none", not_testable=["brake_delay"]),
            dict(base, confounded=[["brake_gain", "brake_lag"]]),
            dict(base, all_named=False),
            {"right": False, "expected": "unexplained", "verdict": "none"},
            dict(base, verdict="unexplained", true_explains=False),
            dict(base, verdict="none", true_explains=False)]  # the true model's share decides only `unexplained`
    assert [miss_kind(r) for r in rows] == [None, "below the oracle", "confounded", "confounded", "not testable",
                                            "other", None, None, "true model leaves the gap", "other"]
    assert miss_kinds(rows) == {"below the oracle": 1, "true model leaves the gap": 1, "confounded": 2,
                                "not testable": 1, "other": 2}


@pytest.mark.slow
def test_the_oracle_of_several_effects_shows_a_large_one_and_not_a_negligible_one():
    """A brake gain of 0.8 on a log that also holds a drag of 0.1 N (nothing a log could show) is shown; the drag is
    not: the brake gain alone, fitted with the road, predicts the log as well as the true model."""
    import warnings

    from fricenv.effects.quarter_car import make_effect
    from fricenv.gap.quarter_car.config import DiagnoseConfig
    from fricenv.gap.quarter_car.diagnose import diagnose
    from fricenv.gap.quarter_car.simulate import AX_NOISE_STD, OMEGA_NOISE_VAR, V_NOISE_STD, simulate_log
    from fricenv.plants.tire import MagicFormula
    from validation.report_check import shown_effects

    road = MagicFormula(B=11.0, C=1.9, E=0.8, theta=0.9, name="custom")
    effects = {"brake_gain": {"gain": 0.8}, "drag": {"c0": 0.1, "c2": 0.0}}
    log, _ = simulate_log([make_effect(k, **v) for k, v in effects.items()], road, "open-loop", seed=5, duration=4.0)
    cfg = DiagnoseConfig(jobs=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        dg = diagnose(log, cfg=cfg)
        noise = {"omega": float(np.sqrt(OMEGA_NOISE_VAR)), "v": V_NOISE_STD, "a_x": AX_NOISE_STD}
        shown = shown_effects(effects, {"B": 11.0, "C": 1.9, "E": 0.8, "theta": 0.9}, dg, cfg, noise)
    assert shown == {"brake_gain": True, "drag": False}


def test_combo_summary_counts_the_logs_where_what_is_shown_is_named():
    rows = [{"truth_effects": ["a", "b"], "shown": ["a", "b"], "named": ["a", "b"], "all_named": True},
            {"truth_effects": ["a", "b"], "shown": ["a", "b"], "named": ["a"], "all_named": False},
            {"truth_effects": ["a", "b"], "shown": ["a"], "named": ["a", "c"], "all_named": False},
            {"truth_effects": ["a", "b"], "shown": [], "named": ["none"], "all_named": False},
            {"verdict": "error"}]
    s = combo_summary(rows)
    assert s == {"logs": 4, "every_shown": 2, "every_shown_all_named": 1, "some_shown": 3, "shown_named": 2}


@pytest.mark.slow
def test_the_noise_free_truth_shows_a_strong_brake_fade_and_not_a_nominal_log(tmp_path):
    """The oracle of an out-of-library log: on a pedal log whose brake fades by 40 % over the stop the noise-free
    truth beats the calibrated nominal model by far; on the same log without the fade (the nominal model's own
    class) it does not, since the nominal model then predicts within the noise."""
    import dataclasses
    import warnings

    from fricenv.gap.quarter_car.diagnose import DiagnoseConfig, diagnose_file
    from validation import independent_sim as ind
    from validation.report_check import truth_shown

    cfg = DiagnoseConfig(jobs=1)
    base = ind.draw_independent_case("none", np.random.default_rng(4), driver="pedal")
    base = dataclasses.replace(base, columns=("v", "a_x"))
    temp_rise = 0.5 * ind.VEHICLE.m * base.v0**2 / ind.FADE_HEAT_CAPACITY  # all kinetic energy into the brake
    fade = ind.Effect("brake_fade", {"fade_per_kelvin": 0.4 / temp_rise, "heat_capacity": ind.FADE_HEAT_CAPACITY,
                                     "cooling": ind.FADE_HEAT_CAPACITY / ind.FADE_COOLING_TIME})
    shown = {}
    for name, case in (("fade", dataclasses.replace(base, category="out_of_library", effects=(fade,))), ("none", base)):
        path = tmp_path / f"{name}.csv"
        ind.write_independent_log(path, case)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            dg = diagnose_file(path, cfg=cfg)
        shown[name] = truth_shown(ind.simulate_case(case), dg, cfg, ind.case_noise(case))
    assert shown == {"fade": True, "none": False}
