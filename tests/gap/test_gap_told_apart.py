"""The report says whether the log tells the verdict's effect from the best other significant candidate
(``where["told_apart"]``): a stand-in log whose effect is clear reads apart; one where a brake delay and a lag give
the same data (8 ms on snow under ABS, where the torque moves the wheel slowly) reads not apart, and the summary
line says so. The verdict itself is the same either way."""

from fricenv.effects.quarter_car import make_effect
from fricenv.gap.quarter_car.diagnose import DiagnoseConfig, diagnose
from fricenv.gap.quarter_car.report import summary_line
from fricenv.gap.quarter_car.simulate import simulate_log
from fricenv.plants.tire import SNOW, MagicFormula

CFG = DiagnoseConfig(jobs=2)
ROAD = MagicFormula(B=11.0, C=1.9, E=0.8, theta=0.9, name="custom")


def test_a_lag_that_the_log_shows_is_told_apart_from_a_delay():
    log, _ = simulate_log([make_effect("brake_lag", tau=0.008)], ROAD, "abs", seed=1, duration=4.0)
    dg = diagnose(log, cfg=CFG)
    ta = dg.where["told_apart"]
    assert dg.verdict == "brake_lag" and ta["effect"] == "brake_lag" and ta["from"] == "brake_delay"
    assert ta["apart"] and ta["z_paired"] > CFG.sig_z
    assert "not told apart" not in summary_line(dg)


def test_a_delay_that_a_lag_reads_as_well_is_reported_not_told_apart():
    log, _ = simulate_log([make_effect("brake_delay", delay=0.008)], SNOW, "abs", seed=1, duration=4.0)
    dg = diagnose(log, cfg=CFG)
    ta = dg.where["told_apart"]
    assert dg.verdict == "brake_delay" and ta["from"] == "brake_lag"
    assert not ta["apart"] and ta["z_paired"] < CFG.sig_z
    assert 0.0 < ta["params"]["tau"] < 0.03  # the lag that reads the same data
    assert "not told apart from brake_lag" in summary_line(dg)
