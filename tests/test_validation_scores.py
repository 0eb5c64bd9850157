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


def test_the_fourth_figure_counts_right_verdicts_on_shown_logs_told_apart():
    rows = [
        {"category": "none", "verdict": "none", "right": True},  # shown, nothing to tell apart from
        {"category": "brake_delay", "verdict": "brake_lag", "right": False, "detectable": True, "apart": False,
         "alternative": "brake_lag"},  # shown, not told apart: out of the fourth figure
        {"category": "brake_lag", "verdict": "brake_lag", "right": True, "detectable": True, "apart": False,
         "alternative": "brake_delay"},
        {"category": "drag", "verdict": "none", "right": False, "detectable": True, "apart": True,
         "alternative": "brake_gain"},
        {"category": "drag", "verdict": "none", "right": False, "detectable": False},  # not shown
    ]
    q = quarter_car_numbers(rows)
    assert (q["shown"], q["right_on_shown"], q["apart"], q["right_on_apart"]) == (4, 2, 2, 1)
    assert q["alternatives"] == {"brake_delay->brake_lag": 1, "brake_lag->brake_delay": 1}
    assert "apart" not in quarter_car_numbers(rows[:1] + rows[-1:])  # a suite without the oracle: three numbers


def test_the_tools_own_told_apart_test_splits_the_effect_verdicts():
    apart = {"apart": True}
    rows = [
        {"category": "drag", "verdict": "drag", "right": True, "detectable": True, "told_apart": apart},
        {"category": "drag", "verdict": "brake_gain", "right": False, "detectable": True, "told_apart": apart},
        {"category": "brake_lag", "verdict": "brake_delay", "right": False, "detectable": False,
         "told_apart": {"apart": False}},
        {"category": "none", "verdict": "none", "right": True, "told_apart": None},  # no effect named: not counted
    ]
    q = quarter_car_numbers(rows)
    assert q["tool_told_apart"] == {"apart": {"verdicts": 2, "right": 1}, "not_apart": {"verdicts": 1, "right": 0}}


def test_noise_levels_compare_the_level_the_tool_used_with_the_sources_by_logger_rate():
    import pytest

    from validation.scores import noise_levels

    def row(ratio, rate=None):
        truth = {"real": {"rate_hz": rate}} if rate else {}
        return {"sensors": {"omega": {"noise_std": 0.4 * ratio}}, "true_noise": {"omega": 0.4}, "truth": truth}

    rows = [row(0.5, 97.0), row(0.6, 90.0), row(1.0, 40.0), row(0.9), {"sensors": {"omega": {}}}]
    levels = noise_levels(rows)["omega"]
    assert levels["all"]["logs"] == 4 and levels["all"]["median"] == pytest.approx(0.75)
    assert levels["85 Hz and above"] == pytest.approx({"logs": 2, "median": 0.55, "min": 0.5, "max": 0.6})
    assert levels["below 50 Hz"]["logs"] == 1 and "50-85 Hz" not in levels


def test_pool_adds_a_line_over_every_files_logs(tmp_path, capsys):
    import json

    from validation.scores import main

    files = []
    for i, rows in enumerate(([{"category": "none", "verdict": "none", "right": True}],
                              [{"category": "drag", "verdict": "brake_gain", "right": False, "detectable": True}])):
        files.append(tmp_path / f"r{i}.json")
        files[-1].write_text(json.dumps({"logs": rows}))
    assert main(["--pool", *map(str, files)]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("2 files pooled: data show the answer on 2/2") and "right on those 1/2" in last
    assert "wrong named effects 1/2" in last
