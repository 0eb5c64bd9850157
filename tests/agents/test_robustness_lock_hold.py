"""The EKF/RLS on the robustness matrix's stop where a lagging brake holds the wheel locked while the command falls:
the torque the brake still applies lies within the command's last 0.1 s, so rule (B4) of
:mod:`estimators.speed_reference` takes the locked wheel as the brake's lag, in the env's gate and in the paper's
(before the rule the paper's gate rejected it ten times in a row, and the env's restarted at its second sample
through (J3) of :mod:`estimators.jump`, whose own test is in tests/estimators/test_gate_jump.py)."""

from __future__ import annotations

import numpy as np

from agents.robustness import simulate_stop
from estimators.base import Health
from estimators.batched import make_batched
from estimators.registry import get_estimator
from fricenv.effects.grid import GridCell
from fricenv.plants import quarter_car as qc

P = qc.PAPER_PARAMS
DT = 0.01
BAD = (int(Health.OUTLIER), int(Health.REINITIALISED))


def _lagging_brake_stop():
    """The robustness matrix's ABS stop on dry with an 80 ms brake lag, seed 1: the brake holds the wheel
    locked at 2.62-2.72 s while the command falls from 1736 to 483 N m."""
    return simulate_stop(GridCell("brake_lag", "high"), "dry", "abs", 1)


def test_a_wheel_a_lagging_brake_holds_at_rest_is_not_flagged():
    stop = _lagging_brake_stop()
    held = (stop.t >= 2.615) & (stop.t <= 2.725)
    assert np.all(stop.slip[held] == 1.0)  # locked through the window
    assert stop.T_b[held][0] > 1.5 * stop.T_b[held][-1]  # while the command falls
    for braking_reference in (True, False):
        est = get_estimator("ekf-rls").make(P, DT, braking_reference=braking_reference)
        est.reset(v0=float(stop.omega[0]) * P.r)
        samples = zip(stop.omega, stop.a_x, stop.T_b)
        health = np.array([int(est.update((w, a), (T,)).health) for w, a, T in samples])
        assert not np.isin(health, BAD).any(), (braking_reference, np.flatnonzero(np.isin(health, BAD)))


def test_batched_gate_holds_the_wheel_at_rest_as_the_single_one():
    stop = _lagging_brake_stop()
    batched = make_batched("ekf-rls", 1, P, DT)
    batched.reset(v0=np.array([stop.omega[0] * P.r]))
    single = get_estimator("ekf-rls").make(P, DT)
    single.reset(v0=float(stop.omega[0]) * P.r)
    for w, a, T in zip(stop.omega, stop.a_x, stop.T_b):
        values, health = batched.update(np.array([w]), np.array([a]), np.array([T]))
        ref = single.update((w, a), (T,))
        assert health[0] == int(ref.health)
        for key in single.names:
            np.testing.assert_allclose(values[key][0], ref.values[key], rtol=1e-9, atol=1e-9)
