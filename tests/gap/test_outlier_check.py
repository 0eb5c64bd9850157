"""The outlier check (tests/outlier_check.py) on a short low-rate export: every written outlier set aside."""

import dataclasses

import pytest

from tests.outlier_check import check_case, measure
from validation import independent_sim as sim


def test_a_28_hz_export_has_its_three_wheel_speed_outliers_set_aside():
    # case 24 of tuning seed 3010: 139 samples at 28 Hz, where 2 % of the samples (2.8) once hid all 3 outliers
    case = sim.draw_cases(60, 3010, real=True)[24]
    assert 27.0 < case.real["rate_hz"] < 29.0
    row = check_case(case)
    assert row["written"] == 3
    assert row["found"] == 3
    assert row["false"] == 0


def test_a_clean_log_has_no_outlier_written_and_none_flagged():
    case = dataclasses.replace(sim.draw_cases(60, 3010, real=True)[24], real=None)
    assert check_case(case) == {"written": 0, "found": 0, "false": 0, "rate_hz": None}


def test_measure_rejects_an_empty_draw():
    with pytest.raises(ValueError, match="n must be >= 1"):
        measure(0, 1)
