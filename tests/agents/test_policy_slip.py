"""Where a policy brakes under an effect (validation.policy_slip): its ratio is the evaluation's, its slip the
plant's, its slip estimate the observation's."""

import numpy as np
import pytest

from agents.evaluation import Scenario, parse_policy, run_episode
from fricenv.effects.grid import grid_effect
from validation.policy_slip import main, measure


def test_the_ratio_is_the_evaluations_and_a_weak_brake_shows_in_the_slip():
    effects = (grid_effect("brake_gain", "low", "dry", 20.0),)
    m = measure("pipeline:ekf-rls", "brake_gain:low", "dry", 20.0, 0)
    expected = run_episode(parse_policy("pipeline:ekf-rls"), Scenario("dry", 20.0, effects, "brake_gain:low"), 0)
    assert m["ratio"] == pytest.approx(expected["ratio"], rel=1e-12)
    assert abs(m["slip_hat"] - m["slip"]) < 0.05 and m["slip_ref"] == pytest.approx(0.191, abs=0.005)
    nominal = measure("pipeline:ekf-rls", "nominal", "dry", 20.0, 0)
    assert m["torque"] > nominal["torque"]  # the slip loop commands more from a weaker brake
    assert np.isnan(measure("rule-abs", "nominal", "dry", 20.0, 0)["slip_hat"])  # no estimator, no estimate


def test_a_cell_off_the_grid_is_refused(capsys):
    with pytest.raises(SystemExit):
        main(["--policy", "rule-abs", "--cells", "brake_gain:medium"])
    assert "cell 'brake_gain:medium'" in capsys.readouterr().err
