"""The Rosenbrock (ROS2) substep of the quarter car, eq. (1): written once, in plain math.

One L-stable two-stage Rosenbrock step (ROS2, Verwer et al. 1999, ``gamma = 1 + 1/sqrt(2)``) with the exact
Jacobian ``A`` of eq. (1),

    (I - gamma h A) k1 = f(x)
    (I - gamma h A) k2 = f(x + h k1) - 2 k1
    x+ = x + h (3/2 k1 + 1/2 k2)

(the 2x2 systems solved by Cramer's rule), followed by the lock event (``omega >= 0``: a wheel that would turn
backwards locks where omega crosses zero and slides at ``mu(1)`` for the rest of the substep) and ``v >= 0``.
:func:`ros2_substep` is plain arithmetic over the ``np`` namespace with the Magic Formula and the slip of
:mod:`fricenv.plants.tire`, so the same function runs on numpy arrays (:func:`fricenv.plants.quarter_car.step`, the
batched reference) and compiled by numba on floats (:mod:`fricenv.plants.compiled`, the env's and the gap tool's
fast paths). It is tested against a dense solve of the same stages and, through ``quarter_car.step``, against
scipy's Radau.
"""

from __future__ import annotations

import numpy as np

from fricenv.plants.tire import longitudinal_slip, magic_formula, magic_formula_and_dslip, slip_and_partials

__all__ = ["INVARIANT_TOL", "LOCK_TINY", "REFINE_MIN_STEP", "REFINE_PARTS", "ROS2_GAMMA", "braking_invariant_broken",
           "ros2_substep"]

# gamma = 1 + 1/sqrt(2) makes the method L-stable and of order 2.
ROS2_GAMMA = 1.0 + 1.0 / 2.0**0.5
LOCK_TINY = 1e-300  # guard of the lock-crossing interpolation
INVARIANT_TOL = 1e-9  # relative tolerance of the invariant check (rounding at free rolling)
REFINE_PARTS = 8  # a substep that breaks the braking invariant is redone in this many parts ...
REFINE_MIN_STEP = 5e-4  # ... recursively, while the step is longer than this [s] (one level from 2 ms: deeper
# levels cost up to 512 steps per substep in stiff fits and changed no tested result)


def braking_invariant_broken(v0, w0, v1, w1, Tb, r):
    """Where a step from (v0, w0) to (v1, w1) broke the braking invariant of eq. (1).

    With ``T_b >= 0`` and a wheel no faster than the car (``omega r <= v``), the tire force is >= 0 all along:
    the wheel cannot overtake the car and the car cannot speed up. A linearly implicit step can break this when
    it linearises across the friction peak while the slip dynamics are much faster than the step (low speed,
    brake released past the peak): it overshoots to traction slip and pushes the car forward.
    """
    tol = INVARIANT_TOL * (1.0 + v0)
    return (Tb >= 0.0) & (w0 * r <= v0) & ((w1 * r > v1 + tol) | (v1 > v0 + tol))


def ros2_substep(v, w, Tb, B, C, E, theta, mu1, h, r, m, J, Fz):
    """One ROS2 substep of eq. (1) with the lock event and ``v >= 0``, on floats or arrays alike.

    :param v: vehicle speed [m/s].
    :param w: wheel speed [rad/s].
    :param Tb: brake torque [N m] (negative drives), held over the substep.
    :param B: Magic Formula stiffness factor; :param C: shape factor; :param E: curvature factor;
    :param theta: peak factor.
    :param mu1: ``mu(1)`` of that road, the sliding friction of a locked wheel [-].
    :param h: substep [s].
    :param r: wheel radius [m]; :param m: quarter-car mass [kg]; :param J: wheel inertia [kg m^2];
    :param Fz: tire load [N].
    :return: (v, omega, broken) after the substep; ``broken`` where :func:`braking_invariant_broken` holds (the
        caller redoes those substeps in finer parts).
    """
    hg = h * ROS2_GAMMA
    # f(x) and the Jacobian from the tire force and its partials (eq. (1)-(3))
    lam, dlam_dv, dlam_dw = slip_and_partials(v, w, r)
    mu, dmu = magic_formula_and_dslip(lam, B, C, E, theta)
    Fx, dF_dv, dF_dw = Fz * mu, Fz * dmu * dlam_dv, Fz * dmu * dlam_dw
    m11, m12 = 1.0 - hg * (-dF_dv / m), -hg * (-dF_dw / m)  # I - gamma h A
    m21, m22 = -hg * (r * dF_dv / J), 1.0 - hg * (r * dF_dw / J)
    det = m11 * m22 - m12 * m21
    b1, b2 = -Fx / m, (r * Fx - Tb) / J
    k1v, k1w = (m22 * b1 - m12 * b2) / det, (m11 * b2 - m21 * b1) / det
    # f(x + h k1), omega clipped at 0
    v2 = v + h * k1v
    F2 = Fz * magic_formula(longitudinal_slip(v2, np.maximum(w + h * k1w, 0.0), r), B, C, E, theta)
    b1, b2 = -F2 / m - 2.0 * k1v, (r * F2 - Tb) / J - 2.0 * k1w
    k2v, k2w = (m22 * b1 - m12 * b2) / det, (m11 * b2 - m21 * b1) / det
    v_new = v + h * (1.5 * k1v + 0.5 * k2v)
    w_new = w + h * (1.5 * k1w + 0.5 * k2w)
    # Lock event: lock where omega crosses zero, slide at mu(1) for the rest of the substep.
    crossing = w_new < 0.0
    frac = np.where(crossing, w / np.maximum(w - w_new, LOCK_TINY), 1.0)
    v_new = np.where(crossing, v + frac * (v_new - v) - (1.0 - frac) * h * Fz * mu1 / m, v_new)
    w_new = np.maximum(w_new, 0.0)
    v_new = np.maximum(v_new, 0.0)
    return v_new, w_new, braking_invariant_broken(v, w, v_new, w_new, Tb, r)
