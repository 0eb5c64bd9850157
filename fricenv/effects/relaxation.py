"""Quarter car with tire relaxation: the extended 3-state right-hand side and its Rosenbrock step.

The ``relaxation_length`` effect changes the tire force law (the force depends on a third state, the transient
slip), which cannot be expressed through :func:`fricenv.plants.quarter_car.step`: those elements of
:class:`fricenv.effects.quarter_car.EffectSimulator` are integrated by :func:`relaxation_step`, the plant's ROS2
scheme on :func:`relaxation_derivatives`, with the Magic Formula of :mod:`fricenv.plants.tire`. It is checked
against ``scipy.integrate.solve_ivp`` (Radau) in the tests.
"""

from __future__ import annotations

import numpy as np

from fricenv.effects.library import drag_force
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import longitudinal_slip, magic_formula, magic_formula_dslip, slip_and_partials

__all__ = ["RELAX_GAMMA", "relaxation_derivatives", "relaxation_step"]

# Rosenbrock gamma of the relaxation plant's steps: 1/2 (linearly implicit trapezoidal rule, A-stable, second
# order) leaves the oscillatory mode of the transient slip and the wheel (about 25 Hz on dry asphalt at
# sigma = 0.3 m) undamped, as it is; the plant's L-stable 1 + 1/sqrt(2) damps that mode numerically at 2 ms steps,
# which a fit then reads as a relaxation length about 10 % too long.
RELAX_GAMMA = 0.5


def relaxation_derivatives(v, omega, lam_t, Tb, road, r, sigma, c0, c2, p: qc.QuarterCarParams = qc.PAPER_PARAMS):
    """Extended quarter car with tire relaxation (eq. (1) with a transient slip): returns (v', omega', lambda_t').

        m v'               = -F_z mu(lambda_t) - F_d(v)
        J omega'           =  r F_z mu(lambda_t) - T_b
        (sigma/v) lambda_t' = lambda(v, omega) - lambda_t

    :param v: vehicle speed [m/s]; :param omega: wheel speed [rad/s]; :param lam_t: transient slip [-].
    :param Tb: applied brake torque [N m]; :param road: (n, 4) Magic Formula parameters.
    :param r: rolling radius [m]; :param sigma: relaxation length [m] (> 0); :param c0: drag [N];
    :param c2: air drag coefficient [N s^2/m^2]; :param p: quarter-car parameters (m, J, F_z).
    """
    road = np.asarray(road, dtype=float)
    F = p.Fz * magic_formula(lam_t, road[..., 0], road[..., 1], road[..., 2], road[..., 3])
    drag = drag_force(v, c0, c2)
    lam = longitudinal_slip(v, omega, r)
    return -(F + drag) / p.m, (r * F - Tb) / p.J, v * (lam - lam_t) / sigma


def _solve_relax(m, b: np.ndarray) -> np.ndarray:
    """Solve ``M k = b`` (b: (n, 3)) for the sparse ``M = [[m00, 0, m02], [0, 1, m12], [m20, m21, m22]]`` of
    :func:`relaxation_step` by elimination onto the transient slip (no inverse formed; ``m00 >= 1``)."""
    m00, m02, m12, m20, m21, m22 = m
    b0, b1, b2 = b[:, 0], b[:, 1], b[:, 2]
    k2 = (b2 - m20 * b0 / m00 - m21 * b1) / (m22 - m20 * m02 / m00 - m21 * m12)
    return np.stack([(b0 - m02 * k2) / m00, b1 - m12 * k2, k2], axis=1)


def relaxation_step(v, omega, lam_t, Tb, road, h: float, r, sigma, c0, c2,
                    p: qc.QuarterCarParams = qc.PAPER_PARAMS, gamma: float = RELAX_GAMMA):
    """One two-stage Rosenbrock step of :func:`relaxation_derivatives` (exact 3x3 Jacobian; the plant's ROS2
    scheme with ``gamma``, see :data:`RELAX_GAMMA`), then ``omega >= 0``, ``v >= 0``.

    :param h: step [s]; other parameters as in :func:`relaxation_derivatives` (arrays of shape (n,)).
    :param gamma: Rosenbrock gamma (second order for any value; 1 + 1/sqrt(2) is the L-stable ROS2).
    :return: (v, omega, lambda_t) after ``h``.
    """
    road = np.asarray(road, dtype=float)
    B, C, E, th = road[..., 0], road[..., 1], road[..., 2], road[..., 3]
    fz_dmu = p.Fz * magic_formula_dslip(lam_t, B, C, E, th)
    lam, dlam_dv, dlam_dw = slip_and_partials(v, omega, r)
    hg = h * gamma
    # I - h gamma A; the Jacobian A has zeros at (0, 1), (1, 0), (1, 1), so M is sparse the same way
    m00 = 1.0 - hg * np.where(v > 0.0, -2.0 * c2 * v / p.m, 0.0)
    m02 = hg * fz_dmu / p.m
    m12 = -hg * r * fz_dmu / p.J
    m20 = -hg * ((lam - lam_t) / sigma + v / sigma * dlam_dv)
    m21 = -hg * v / sigma * dlam_dw
    m22 = 1.0 + hg * v / sigma
    m = (m00, m02, m12, m20, m21, m22)

    def f(x):
        return np.stack(relaxation_derivatives(x[:, 0], np.maximum(x[:, 1], 0.0), x[:, 2], Tb, road, r, sigma,
                                               c0, c2, p), axis=1)

    x = np.stack([v, omega, lam_t], axis=1)
    k1 = _solve_relax(m, f(x))
    k2 = _solve_relax(m, f(x + h * k1) - 2.0 * k1)
    x = x + h * (1.5 * k1 + 0.5 * k2)
    return np.maximum(x[:, 0], 0.0), np.maximum(x[:, 1], 0.0), np.clip(x[:, 2], -1.0, 1.0)
