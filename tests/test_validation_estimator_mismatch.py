"""The estimator mismatch study on the independent simulator's stops (validation.estimator_mismatch --source
independent): the grid cell reaches that simulator's plant, and a driver of the other source is refused."""

import numpy as np
import pytest

from validation.estimator_mismatch import _independent_logs, measure, verdicts


def test_the_independent_source_puts_the_grid_cell_on_its_plant_under_the_same_command():
    """The pedal press is open-loop: a 1.25 brake gain and the grid's high drag stop the car sooner under the very
    command the nominal stop logs (5 s of nominal braking do not reach the stop speed on this draw)."""
    (_, nom, v_nom), (_, gain, v_gain), (_, drag, v_drag) = _independent_logs("pedal", "dry", 0, "high",
                                                                               ["brake_gain", "drag"])
    assert len(v_gain) < len(v_nom) and len(v_drag) < len(v_nom)
    assert np.array_equal(gain.T_b, nom.T_b[:len(gain.T_b)]) and np.array_equal(drag.T_b, nom.T_b[:len(drag.T_b)])


def test_the_independent_source_measures_every_estimator_against_its_own_nominal_run():
    rows = measure(["ekf-rls"], ["bosch-abs"], ["dry"], [0], "high", ["brake_gain"], source="independent")
    nominal, gain = (r for r in rows)
    assert (nominal.effect, gain.effect) == ("nominal", "brake_gain")
    # the EKF/RLS keeps the nominal stop's speed to a tenth of a m/s, and a 1.25 brake gain moves its error
    assert nominal.rms < 0.1, nominal.rms
    assert gain.rms != pytest.approx(nominal.rms, abs=1e-6)
    assert all(v["rms_bound"] == pytest.approx(2.0 * nominal.rms + 0.1) for v in verdicts(rows))


def test_a_driver_of_the_other_source_is_refused():
    with pytest.raises(ValueError, match="not of the independent source; its drivers: pedal, bosch-abs, sine"):
        measure(["ekf-rls"], ["abs"], ["dry"], [0], source="independent")
