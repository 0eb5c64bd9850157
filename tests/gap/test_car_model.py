"""The car model's pieces against closed forms: the actuator's lag and delay, the body's deceleration from four
braked wheels, a window's start speed."""

import numpy as np
import pytest

from fricenv.gap.car.model import EventData, _actuator, nominal_params, predict_event, window_residuals
from fricenv.gap.car.session import CarParams

CAR = CarParams(790.0, 1.248, 1.7328, wheel_inertia=1.0)


def test_lag_is_a_sampled_first_order_response():
    dt, tau = 0.04, 0.1
    T = np.r_[0.0, np.ones(30)]
    y = _actuator(T, dt, tau, 0.0)
    k = np.arange(1, 31)
    assert y == pytest.approx(np.r_[0.0, 1.0 - np.exp(-(k - 1) * dt / tau)], abs=1e-12)


def test_delay_shifts_a_ramp():
    T = np.arange(20.0)
    assert _actuator(T, 0.04, 0.0, 0.08)[5:] == pytest.approx(T[5:] - 2.0)


def _event(v, T, wheels, dt=0.04, H=10):
    return EventData(v=v, T=T, pre=0, wheels=wheels, a_x=None, dt=dt, starts=np.arange(0, len(v) - H + 1, H),
                     horizon=H, block=np.zeros(len(v) // H, int), t0=0.0)


def test_deceleration_sums_four_wheels_and_drag():
    n = 20
    e = _event(np.full(n, 15.0), np.full(n, 200.0), {"fl": np.zeros(n)})
    x = nominal_params(0.33, CAR) | {"gain": 1.5, "c0": 300.0, "c2": 2.0}
    a, slip = predict_event(e, x, 30.0, CAR, "fl")
    b = CAR.front_share
    torque = 1.5 * 200.0 * (2.0 + 2.0 * (1 - b) / b)
    m_eff = 790.0 + 4 * 1.0 / 0.33 ** 2
    assert a == pytest.approx(np.full(n, -(torque / 0.33 + 300.0 + 2.0 * 225.0) / m_eff))
    assert slip["fl"] == pytest.approx(np.full(n, 1.5 * 200.0 / 0.33 / (CAR.static_load("fl") * 30.0)))


def test_a_window_starts_from_its_best_speed():
    """Data made by the model itself, shifted by a constant speed per window: the start speed absorbs it."""
    n, dt = 30, 0.04
    x = nominal_params(0.33, CAR)
    e = _event(np.zeros(n), np.linspace(0, 300, n), {"fl": np.zeros(n)})
    e.v = np.full(n, 20.0)  # no drag in the nominal car: the deceleration does not depend on v
    a, slip = predict_event(e, x, 30.0, CAR, "fl")
    v = 20.0 + np.r_[0.0, np.cumsum(0.5 * (a[1:] + a[:-1]) * dt)]
    e.v = v + np.repeat([0.3, -0.2, 0.1], 10)
    e.wheels = {"fl": e.v * (1 - slip["fl"]) / 0.33}
    r, counts = window_residuals(e, x, 30.0, CAR, "fl", {"v": 0.01, "omega_fl": 0.1})
    assert np.max(np.abs(r)) < 1e-6 and (counts == 20).all()
