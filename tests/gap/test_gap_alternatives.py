"""A named effect that an untested one imitates on the log's channels comes with that effect's equivalent size."""

import dataclasses
import os

import numpy as np
import pytest

from fricenv.gap.quarter_car.alternatives import alternatives
from fricenv.gap.quarter_car.diagnose import diagnose
from fricenv.gap.quarter_car.report import _testability_lines
from fricenv.logs import read_log
from fricenv.plants.quarter_car import PAPER_PARAMS
from validation.independent_model import ROADS, VEHICLE, Effect
from validation.independent_sim import draw_independent_case, write_independent_log

GAIN = [{"effect": "brake_gain", "params": {"gain": 0.81}}]


def test_a_brake_gain_comes_with_the_radius_that_gives_its_data_when_the_radius_is_untested():
    (alt,) = alternatives(GAIN, {"radius_error": "neither v nor a_x logged"}, PAPER_PARAMS)
    assert alt["effect"] == "radius_error" and alt["instead_of"] == "brake_gain"
    assert alt["params"]["r_eff"] == pytest.approx(PAPER_PARAMS.r / 0.9)  # (A2): g = (r / r_e)^2


def test_no_alternative_when_the_radius_was_tested_or_no_gain_is_named():
    assert alternatives(GAIN, {}, PAPER_PARAMS) == []
    assert alternatives([{"effect": "drag", "params": {"c0": 100.0, "c2": 0.3}}],
                        {"radius_error": "neither v nor a_x logged"}, PAPER_PARAMS) == []


def test_an_omega_only_radius_error_is_named_a_brake_gain_with_its_radius_as_the_alternative(tmp_path):
    """A radius 6 % large on an independent simulator's ABS stop, logged without v and a_x: the tool cannot test
    the radius there and names the brake gain that gives the same data; the alternative it reports is the true
    radius up to the wheel-inertia term (within 1.5 %)."""
    r_true = VEHICLE.r * 1.06
    case = draw_independent_case("radius_error", np.random.default_rng(202), driver="bosch-abs", road=ROADS["wet"],
                                 effects=(Effect("radius_error", {"r_eff": r_true}),))
    path = os.path.join(tmp_path, "log.csv")
    write_independent_log(path, dataclasses.replace(case, columns=()))
    dg = diagnose(read_log(path))  # the independent vehicle is the paper's (m, J, r, F_z)
    assert dg.verdict == "brake_gain"
    (alt,) = dg.where["alternatives"]
    assert alt["effect"] == "radius_error"
    assert alt["params"]["r_eff"] == pytest.approx(r_true, rel=0.015)
    assert any("`radius_error` (r_eff = " in line for line in _testability_lines(dg.where))
