"""Rule (B4) of the EKF/RLS's wheel-speed gate (estimators/speed_reference.py): a brake that has not followed its
command yet is no outlier and no friction jump.

Stops: the robustness study's open-loop stop on dry, seed 1 (agents/robustness.py), whose command steps by 500-1100
N m; before the rule, the first sample after each step was flagged OUTLIER and the second REINITIALISED (6 flags
with an 80 ms brake lag, 14 with a 60 ms brake delay).
"""

import numpy as np
import pytest

from agents.robustness import run_estimator, simulate_stop
from estimators.base import Health
from estimators.speed_reference import brake_lag_shift
from fricenv.effects.grid import GridCell
from fricenv.plants.quarter_car import PAPER_PARAMS

DT = 0.01


def test_shift_is_what_a_torque_of_the_span_explains():
    scale = DT / PAPER_PARAMS.J  # rad/s per N m over one sample
    # the command went from -300 to -1300 N m (braking harder): the wheel decelerates less than predicted, by up to
    # 1000 N m's worth of wheel speed
    assert brake_lag_shift(4.0, -1300.0, -1300.0, -300.0, np.inf, DT, PAPER_PARAMS.J) == pytest.approx(4.0)
    assert brake_lag_shift(25.0, -1300.0, -1300.0, -300.0, np.inf, DT, PAPER_PARAMS.J) == pytest.approx(1000 * scale)
    # ... but no torque of the span makes it decelerate more than the command does
    assert brake_lag_shift(-4.0, -1300.0, -1300.0, -300.0, np.inf, DT, PAPER_PARAMS.J) == 0.0
    # a released brake: the wheel may decelerate more than predicted, not less
    assert brake_lag_shift(-4.0, -300.0, -1300.0, -300.0, np.inf, DT, PAPER_PARAMS.J) == pytest.approx(-4.0)
    assert brake_lag_shift(4.0, -300.0, -1300.0, -300.0, np.inf, DT, PAPER_PARAMS.J) == 0.0
    # rule (B3)'s ceiling bounds how far the prediction may rise
    assert brake_lag_shift(4.0, -1300.0, -1300.0, -300.0, 1.5, DT, PAPER_PARAMS.J) == pytest.approx(1.5)
    # a command that held still explains nothing
    assert brake_lag_shift(4.0, -800.0, -800.0, -800.0, np.inf, DT, PAPER_PARAMS.J) == 0.0


@pytest.mark.parametrize("effect, most", [("brake_lag", 0), ("brake_delay", 5)])
def test_command_steps_under_a_slow_brake_are_not_flagged(effect, most):
    stop = simulate_stop(GridCell(effect, "high"), "dry", "open-loop", seed=1)
    assert np.ptp(stop.T_b) > 1000.0  # the stop has the steps the rule is about
    health = run_estimator("ekf-rls", [stop])[0]["health"]
    flags = int(np.sum((health == Health.OUTLIER) | (health == Health.REINITIALISED)))
    # measured: 0 with the 80 ms lag (6 before the rule), 4 with the 60 ms delay (14 before), in 500 samples
    assert flags <= most, flags
