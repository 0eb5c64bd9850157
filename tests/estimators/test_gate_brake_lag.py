"""Rule (B4) of the EKF/RLS's wheel-speed gate (estimators/speed_reference.py): the part of a wheel-speed innovation
that a torque within the command's last 0.1 s explains (the stops it was measured on: tests/agents/
test_robustness_brake_lag.py)."""

import numpy as np
import pytest

from estimators.speed_reference import brake_lag_shift
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
