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
from fricenv.plants.tire import longitudinal_slip, magic_formula, magic_formula_and_dslip, slip_and_partials

__all__ = ["RELAX_GAMMA", "relaxation_derivatives", "relaxation_rhs", "relaxation_step", "relaxation_step_elementwise"]

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
    return relaxation_rhs(v, omega, lam_t, Tb, road[..., 0], road[..., 1], road[..., 2], road[..., 3], r, sigma, c0,
                          c2, p.m, p.J, p.Fz)


def relaxation_rhs(v, omega, lam_t, Tb, B, C, E, th, r, sigma, c0, c2, m: float, J: float, Fz: float):
    """:func:`relaxation_derivatives` elementwise, on arrays or floats alike (numba compiles it for the window
    kernels, :mod:`fricenv.effects.kernels`): the road as (B, C, E, theta), the plant as (m, J, F_z)."""
    F = Fz * magic_formula(lam_t, B, C, E, th)
    drag = drag_force(v, c0, c2)
    lam = longitudinal_slip(v, omega, r)
    return -(F + drag) / m, (r * F - Tb) / J, v * (lam - lam_t) / sigma


def relaxation_step(v, omega, lam_t, Tb, road, h: float, r, sigma, c0, c2,
                    p: qc.QuarterCarParams = qc.PAPER_PARAMS, gamma: float = RELAX_GAMMA):
    """One two-stage Rosenbrock step of :func:`relaxation_derivatives` (exact 3x3 Jacobian; the plant's ROS2
    scheme with ``gamma``, see :data:`RELAX_GAMMA`), then ``omega >= 0``, ``v >= 0``.

    :param h: step [s]; other parameters as in :func:`relaxation_derivatives` (arrays of shape (n,)).
    :param gamma: Rosenbrock gamma (second order for any value; 1 + 1/sqrt(2) is the L-stable ROS2).
    :return: (v, omega, lambda_t) after ``h``.
    """
    road = np.asarray(road, dtype=float)
    return relaxation_step_elementwise(v, omega, lam_t, Tb, road[..., 0], road[..., 1], road[..., 2], road[..., 3],
                                       h, r, sigma, c0, c2, p.m, p.J, p.Fz, gamma)


def relaxation_step_elementwise(v, omega, lam_t, Tb, B, C, E, th, h: float, r, sigma, c0, c2, m: float, J: float,
                                Fz: float, gamma: float):
    """:func:`relaxation_step` elementwise, on arrays or floats alike (numba compiles it for the window kernels):
    the one form of the step. Parameters as in :func:`relaxation_rhs`."""
    fz_dmu = Fz * magic_formula_and_dslip(lam_t, B, C, E, th)[1]
    lam, dlam_dv, dlam_dw = slip_and_partials(v, omega, r)
    hg = h * gamma
    # I - h gamma A; the Jacobian A has zeros at (0, 1), (1, 0), (1, 1), so M is sparse the same way:
    # M = [[m00, 0, m02], [0, 1, m12], [m20, m21, m22]], solved by elimination onto the transient slip (m00 >= 1)
    m00 = 1.0 - hg * np.where(v > 0.0, -2.0 * c2 * v / m, 0.0)
    m02 = hg * fz_dmu / m
    m12 = -hg * r * fz_dmu / J
    m20 = -hg * ((lam - lam_t) / sigma + v / sigma * dlam_dv)
    m21 = -hg * v / sigma * dlam_dw
    m22 = 1.0 + hg * v / sigma
    schur = m22 - m20 * m02 / m00 - m21 * m12
    b0, b1, b2 = relaxation_rhs(v, np.maximum(omega, 0.0), lam_t, Tb, B, C, E, th, r, sigma, c0, c2, m, J, Fz)
    k12 = (b2 - m20 * b0 / m00 - m21 * b1) / schur
    k10, k11 = (b0 - m02 * k12) / m00, b1 - m12 * k12
    b0, b1, b2 = relaxation_rhs(v + h * k10, np.maximum(omega + h * k11, 0.0), lam_t + h * k12, Tb, B, C, E, th, r,
                                sigma, c0, c2, m, J, Fz)
    b0, b1, b2 = b0 - 2.0 * k10, b1 - 2.0 * k11, b2 - 2.0 * k12
    k22 = (b2 - m20 * b0 / m00 - m21 * b1) / schur
    k20, k21 = (b0 - m02 * k22) / m00, b1 - m12 * k22
    v_new = v + h * (1.5 * k10 + 0.5 * k20)
    w_new = omega + h * (1.5 * k11 + 0.5 * k21)
    lt_new = lam_t + h * (1.5 * k12 + 0.5 * k22)
    return np.maximum(v_new, 0.0), np.maximum(w_new, 0.0), np.minimum(np.maximum(lt_new, -1.0), 1.0)
