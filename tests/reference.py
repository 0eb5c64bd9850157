"""Independent reference integrations for the plant tests (scipy Radau with event-switched lock)."""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import MagicFormula


def stopping_distance_radau(road: MagicFormula, torque, v0: float = 20.0, v_stop: float = 2.0,
                            p: qc.QuarterCarParams = qc.PAPER_PARAMS, t_max: float = 120.0):
    """Distance and time to slow from ``v0`` to ``v_stop`` under ``torque(t)``, a hybrid reference.

    The rolling mode is eq. (1) integrated by Radau at tight tolerance; when omega reaches 0 the wheel switches to
    the locked mode (omega = 0, sliding at mu(1)) until the tire torque exceeds the brake torque again.
    """
    R = road.as_array()
    t, x, locked = 0.0, np.array([v0, v0 / p.r, 0.0]), False

    def stop(t, y):
        return y[0] - v_stop

    stop.terminal, stop.direction = True, -1
    while t < t_max:
        if not locked:
            def rhs(t, y):
                return [*qc.derivatives(y[0], y[1], torque(t), R, p), y[0]]

            def switch(t, y):
                return y[1]

            def jac(t, y):  # only steers Radau's Newton iterations; the solution is set by rhs
                a11, a12, a21, a22 = qc.jacobian(y[0], y[1], R, p)
                return [[a11, a12, 0.0], [a21, a22, 0.0], [1.0, 0.0, 0.0]]

            switch.direction = -1
        else:
            f_slide = p.Fz * road.mu(1.0)

            def rhs(t, y, f_slide=f_slide):
                return [-f_slide / p.m, 0.0, y[0]]

            def switch(t, y, f_slide=f_slide):
                return p.r * f_slide - torque(t)

            def jac(t, y):
                return [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]

            switch.direction = 1
        switch.terminal = True
        sol = solve_ivp(rhs, (t, t_max), x, method="Radau", rtol=1e-9, atol=1e-9,
                        events=[stop, switch], max_step=0.002, jac=jac)
        t, x = sol.t[-1], sol.y[:, -1].copy()
        if sol.t_events[0].size:
            return float(x[2]), float(t)
        if sol.t_events[1].size:
            locked = not locked
            if locked:
                x[1] = 0.0
    raise RuntimeError("reference did not reach the stop speed")
