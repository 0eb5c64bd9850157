"""The three numbers of a suite (validation.scores, validation.payload_suite.score_rows) count what they say."""

from validation.payload_suite import score_rows
from validation.scores import quarter_car_numbers


def test_quarter_car_numbers_count_shown_right_and_wrongly_named_logs():
    rows = [
        {"category": "none", "verdict": "brake_lag", "right": False},  # shown by definition, wrong, names a wrong effect
        {"category": "drag", "verdict": "none", "right": False, "detectable": False},  # not shown
        {"category": "drag", "verdict": "drag", "right": True, "detectable": True},
        {"category": "out_of_library", "verdict": "unexplained", "right": True},  # no oracle ran: counts as shown
        {"category": "drag", "verdict": "drag", "right": True, "truth_effects": ["drag", "brake_gain"],
         "shown": ["drag", "brake_gain"], "all_named": False, "named": ["drag", "radius_error"]},
    ]
    q = quarter_car_numbers(rows)
    assert (q["n"], q["shown"], q["right_on_shown"], q["wrong_named"]) == (5, 4, 2, 2)


def test_payload_score_rows():
    rows = [
        {"category": "none", "verdict": "none", "right": True, "shown": True, "wrong_named": False},
        {"category": "vision_delay", "verdict": "vision_delay", "right": True, "shown": True, "wrong_named": False,
         "delay_ok": True},
        {"category": "calibration_drift", "verdict": "vision_delay", "right": False, "shown": False,
         "wrong_named": True},
    ]
    s = score_rows(rows)
    assert s["shown_share"] == 2 / 3 and s["right_on_shown"] == 1.0 and s["wrong_named_share"] == 1 / 3
    assert s["nominal_none"] == (1, 1) and s["delay_within_tol"] == (1, 1)


def test_an_effect_log_without_the_oracle_is_refused():
    """A `fricenv gap validate` result has no oracle: counting its effect logs as shown would flatter the suite."""
    import pytest

    with pytest.raises(ValueError, match="stand_in_suite"):
        quarter_car_numbers([{"category": "drag", "verdict": "drag", "right": True}])
