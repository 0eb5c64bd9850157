"""One sample of the speed recursion of :mod:`fricenv.gap.signals.speed`, as plain math: the force balance with drag
and the transient slip's lag. The numpy path calls these functions and :mod:`fricenv.gap.signals.speed_kernel`
compiles them, so the recursion is written once."""

from __future__ import annotations

import numpy as np

__all__ = ["IMPLICIT", "slip_lag_decay", "speed_update"]

IMPLICIT = 0.5  # weight of the step's end in the linearly implicit step (1/2: trapezoidal, second order) [-]


def speed_update(v, mu, dmu_dv, c0, c2, Fz, m, dt, implicit):
    """One linearly implicit step of the force balance with drag, ``m v' = -(F_z mu + c0 + c2 v^2)``, kept >= 0
    (plain math: the compiled recursion is built from it).

    :param v: speed [m/s]; :param mu: friction coefficient; :param dmu_dv: its slope in v [s/m] (0: no feedback).
    :param c0: constant resistance [N]; :param c2: quadratic drag coefficient [N s^2/m^2].
    :param Fz: tire load [N]; :param m: mass [kg]; :param dt: step [s].
    :param implicit: weight of the step's end (:data:`IMPLICIT`).
    """
    f = -(Fz * mu + c0 + c2 * v * v) / m
    dfdv = -(Fz * dmu_dv + 2.0 * c2 * v) / m
    return np.maximum(v + dt * f / (1.0 - implicit * dt * np.minimum(dfdv, 0.0)), 0.0)


def slip_lag_decay(v, dt_over_sigma):
    """Factor by which the transient slip's lag behind the slip decays over one sample, ``exp(-v dt / sigma)``
    (first-order relaxation, ``(sigma / v) lambda_t' = lambda - lambda_t``, with the speed held over the sample)."""
    return np.exp(-np.maximum(v, 0.0) * dt_over_sigma)
