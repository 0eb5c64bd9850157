"""Quarter-car braking plant (Sui & Johansen, Section II), batched over a leading dimension.

State ``x = (v, omega)``: vehicle speed [m/s] and wheel angular speed [rad/s], arrays of shape ``(n,)``.
Road parameters ``road = (B, C, E, theta)`` come as an array of shape ``(n, 4)`` (or ``(4,)``, broadcast), so
each quarter car of a batch can be on its own road, and a road can change between two steps.

Dynamics, eq. (1):

    m v'     = -F_x                                   (1a)
    J omega' =  r F_x - T_b sign(omega)               (1b)
    F_x      =  F_z mu(lambda)                        (2)

``T_b > 0`` brakes; ``T_b < 0`` is a drive torque, with the traction slip of Li, Du & Li
(:func:`fricenv.plants.tire.longitudinal_slip`). Wheel lock: ``omega >= 0`` always; at ``omega = 0`` the brake
holds the wheel like static friction, i.e. the wheel stays locked while ``T_b >= r F_x``.

The wheel equation is stiff at low speed: the slip time constant is about
``v / (F_z mu'(lambda) (r^2/J + 1/m))``, 0.3 ms at 2 m/s on dry asphalt. :func:`step` therefore uses an
L-stable Rosenbrock method (ROS2, Verwer et al. 1999) with an exact Jacobian, which stays accurate and stable for
substeps far longer than that time constant. It is checked against scipy's Radau in the tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fricenv.plants import sui_johansen as sj
from fricenv.plants.tire import (
    MagicFormula,
    longitudinal_slip,
    magic_formula,
    magic_formula_and_dslip,
    slip_and_partials,
)

__all__ = [
    "PAPER_PARAMS",
    "ROS2_GAMMA",
    "QuarterCarParams",
    "braking_invariant_broken",
    "derivatives",
    "jacobian",
    "physical_limit_distance",
    "refine_where_unphysical",
    "road_array",
    "slip",
    "slip_form_derivatives",
    "step",
    "tire_force",
]

# ROS2 constant: gamma = 1 + 1/sqrt(2) makes the method L-stable and of order 2.
ROS2_GAMMA = 1.0 + 1.0 / np.sqrt(2.0)
_ROS2_GAMMA = ROS2_GAMMA  # old private name
REFINE_PARTS = 8  # a substep that breaks the braking invariant is redone in this many parts ...
REFINE_MIN_STEP = 5e-4  # ... recursively, while the step is longer than this [s] (one level from 2 ms: deeper
# levels cost up to 512 steps per substep in stiff fits and changed no tested result)
INVARIANT_TOL = 1e-9  # relative tolerance of the invariant check (rounding at free rolling)


@dataclass(frozen=True)
class QuarterCarParams:
    """Quarter-car parameters, Table I of Sui & Johansen."""

    m: float = sj.MASS  # quarter vehicle mass [kg]
    J: float = sj.INERTIA  # wheel moment of inertia [kg m^2]
    r: float = sj.RADIUS  # wheel radius [m]
    Fz: float = sj.LOAD  # vertical tire load [N]
    g: float = sj.GRAVITY  # gravity [m/s^2]

    def __post_init__(self):
        for name in ("m", "J", "r", "Fz", "g"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"QuarterCarParams.{name} must be finite and > 0, got {value!r}")


PAPER_PARAMS = QuarterCarParams()


def road_array(road: MagicFormula | np.ndarray, n: int | None = None) -> np.ndarray:
    """Road parameters as an ``(n, 4)`` (or ``(4,)``) array of (B, C, E, theta)."""
    arr = road.as_array() if isinstance(road, MagicFormula) else np.asarray(road, dtype=float)
    if arr.shape[-1] != 4:
        raise ValueError(f"road array must end in 4 entries (B, C, E, theta), got shape {arr.shape}")
    if n is not None and arr.ndim == 1:
        arr = np.broadcast_to(arr, (n, 4)).copy()
    return arr


def slip(v, omega, p: QuarterCarParams = PAPER_PARAMS):
    """Signed slip of the quarter car (positive braking), see :func:`~fricenv.plants.tire.longitudinal_slip`."""
    return longitudinal_slip(v, omega, p.r)


def tire_force(v, omega, road, p: QuarterCarParams = PAPER_PARAMS):
    """Longitudinal tire force F_x = F_z mu(lambda) [N], eq. (2); positive when braking."""
    road = np.asarray(road, dtype=float)
    return p.Fz * magic_formula(slip(v, omega, p), road[..., 0], road[..., 1], road[..., 2], road[..., 3])


def _force_and_partials(v, omega, road, p: QuarterCarParams):
    """F_x and its partial derivatives with respect to v and omega."""
    lam, dlam_dv, dlam_dw = slip_and_partials(v, omega, p.r)
    mu, dmu = magic_formula_and_dslip(lam, road[..., 0], road[..., 1], road[..., 2], road[..., 3])
    return p.Fz * mu, p.Fz * dmu * dlam_dv, p.Fz * dmu * dlam_dw


def derivatives(v, omega, Tb, road, p: QuarterCarParams = PAPER_PARAMS):
    """Right-hand side of eq. (1) for ``omega > 0``: returns (v', omega').

    The lock constraint (``omega >= 0`` with a static brake) is applied by :func:`step`, not here, so that this
    function stays smooth for Jacobians and for reference integrators.
    """
    Fx = tire_force(v, omega, road, p)
    return -Fx / p.m, (p.r * Fx - Tb) / p.J


def jacobian(v, omega, road, p: QuarterCarParams = PAPER_PARAMS):
    """Jacobian of :func:`derivatives` with respect to (v, omega): returns (a11, a12, a21, a22)."""
    road = np.asarray(road, dtype=float)
    _, dF_dv, dF_dw = _force_and_partials(v, omega, road, p)
    return _jacobian_from(dF_dv, dF_dw, p)


def _jacobian_from(dF_dv, dF_dw, p: QuarterCarParams):
    """Jacobian of eq. (1) from the tire force's partials: (a11, a12, a21, a22)."""
    return -dF_dv / p.m, -dF_dw / p.m, p.r * dF_dv / p.J, p.r * dF_dw / p.J


def slip_form_derivatives(v, lam, Tb, road, p: QuarterCarParams = PAPER_PARAMS):
    """Wheel-slip dynamics, eq. (6), valid for braking (v > 0, omega >= 0): returns (v', lambda').

        v'      = -F_z mu(lambda) / m                                              (6a)
        lambda' = -(1/v) ((1 - lambda)/m + r^2/J) F_z mu(lambda) + (1/v)(r/J) T_b   (6b)
    """
    road = np.asarray(road, dtype=float)
    Fx = p.Fz * magic_formula(lam, road[..., 0], road[..., 1], road[..., 2], road[..., 3])
    vdot = -Fx / p.m
    lamdot = (-((1.0 - lam) / p.m + p.r**2 / p.J) * Fx + p.r / p.J * Tb) / v
    return vdot, lamdot


def _ros2_matrix(a11, a12, a21, a22, h_gamma):
    """``I - h gamma A`` for batched 2x2 A, with its determinant: (m11, m12, m21, m22, det)."""
    m11, m12 = 1.0 - h_gamma * a11, -h_gamma * a12
    m21, m22 = -h_gamma * a21, 1.0 - h_gamma * a22
    return m11, m12, m21, m22, m11 * m22 - m12 * m21


def _solve_w(m, b1, b2):
    """Solve ``M k = b`` for the batched 2x2 ``m`` of :func:`_ros2_matrix`, by Cramer's rule (no inverse formed)."""
    m11, m12, m21, m22, det = m
    return (m22 * b1 - m12 * b2) / det, (m11 * b2 - m21 * b1) / det


def step(v, omega, Tb, road, dt: float, p: QuarterCarParams = PAPER_PARAMS, substeps: int = 1):
    """Advance the batch by ``dt`` seconds under a brake torque held constant (zero-order hold).

    Each of the ``substeps`` physics steps is one ROS2 step:

        (I - gamma h A) k1 = f(x)
        (I - gamma h A) k2 = f(x + h k1) - 2 k1
        x+ = x + h (3/2 k1 + 1/2 k2)

    followed by the lock constraint ``omega >= 0`` (the static brake holds a wheel that would turn backwards) and
    ``v >= 0`` (the car does not reverse under braking).

    :param v: vehicle speed [m/s], shape (n,).
    :param omega: wheel speed [rad/s], shape (n,).
    :param Tb: brake torque [N m] (negative drives), shape (n,) or scalar.
    :param road: (B, C, E, theta), shape (n, 4) or (4,).
    :param dt: time to advance [s].
    :param p: quarter-car parameters.
    :param substeps: number of equal physics steps in ``dt``.
    :return: (v, omega) after ``dt``, new arrays.
    """
    if substeps < 1:
        raise ValueError(f"substeps must be >= 1, got {substeps}")
    road = np.asarray(road, dtype=float)
    h = dt / substeps
    hg = h * ROS2_GAMMA
    v = np.asarray(v, dtype=float)
    omega = np.asarray(omega, dtype=float)
    for _ in range(substeps):
        # f(x) from the force the Jacobian needs anyway: eq. (1)
        Fx, dF_dv, dF_dw = _force_and_partials(v, omega, road, p)
        m = _ros2_matrix(*_jacobian_from(dF_dv, dF_dw, p), hg)
        k1v, k1w = _solve_w(m, -Fx / p.m, (p.r * Fx - Tb) / p.J)
        f2v, f2w = derivatives(v + h * k1v, np.maximum(omega + h * k1w, 0.0), Tb, road, p)
        k2v, k2w = _solve_w(m, f2v - 2.0 * k1v, f2w - 2.0 * k1w)
        v_new = v + h * (1.5 * k1v + 0.5 * k2v)
        w_new = omega + h * (1.5 * k1w + 0.5 * k2w)
        v_new, w_new = _lock_event(v, omega, v_new, w_new, road, h, p)
        v, omega = refine_where_unphysical(v, omega, v_new, w_new, Tb, road, h, p)
    return v, omega


def braking_invariant_broken(v0, w0, v1, w1, Tb, r: float):
    """Where a step from (v0, w0) to (v1, w1) broke the braking invariant of eq. (1).

    With ``T_b >= 0`` and a wheel no faster than the car (``omega r <= v``), the tire force is >= 0 all along:
    the wheel cannot overtake the car and the car cannot speed up. A linearly implicit step can break this when
    it linearises across the friction peak while the slip dynamics are much faster than the step (low speed,
    brake released past the peak): it overshoots to traction slip and pushes the car forward.
    """
    tol = INVARIANT_TOL * (1.0 + v0)
    return (Tb >= 0.0) & (w0 * r <= v0) & ((w1 * r > v1 + tol) | (v1 > v0 + tol))


def refine_where_unphysical(v0, w0, v1, w1, Tb, road, h: float, p: QuarterCarParams = PAPER_PARAMS):
    """Redo, in :data:`REFINE_PARTS` shorter steps, every car whose step broke :func:`braking_invariant_broken`.

    The check is a few array operations; the refinement (recursive, down to :data:`REFINE_MIN_STEP`) runs only
    for the rare cars that need it, so the common step costs nothing more.
    """
    if h <= REFINE_MIN_STEP:
        return v1, w1
    bad = braking_invariant_broken(v0, w0, v1, w1, Tb, p.r)
    if not bad.any():
        return v1, w1
    v0, w0 = np.asarray(v0, dtype=float), np.asarray(w0, dtype=float)
    Tb = np.broadcast_to(np.asarray(Tb, dtype=float), v0.shape)
    road = np.asarray(road, dtype=float)
    v_fine, w_fine = step(v0[bad], w0[bad], Tb[bad], road[bad] if road.ndim == 2 else road, h, p, REFINE_PARTS)
    v1, w1 = np.array(v1, dtype=float), np.array(w1, dtype=float)
    v1[bad], w1[bad] = v_fine, w_fine
    return v1, w1


def _lock_event(v, omega, v_new, w_new, road, h, p: QuarterCarParams):
    """Apply the lock constraint to a substep from (v, omega) to (v_new, w_new).

    A wheel that would turn backwards locks where omega crosses zero (located by linear interpolation); for the
    rest of the substep the car slides at mu(1). Without locating the crossing, the lock-up transient costs a
    first-order error that dominates the stopping-distance error at 2 ms substeps.
    """
    crossing = w_new < 0.0
    if crossing.any():
        frac = np.where(crossing, omega / np.maximum(omega - w_new, 1e-300), 1.0)
        v_lock = v + frac * (v_new - v)
        mu_slide = magic_formula(1.0, road[..., 0], road[..., 1], road[..., 2], road[..., 3])
        v_new = np.where(crossing, v_lock - (1.0 - frac) * h * p.Fz * mu_slide / p.m, v_new)
        w_new = np.maximum(w_new, 0.0)
    return np.maximum(v_new, 0.0), w_new


def physical_limit_distance(v0, v_stop, mu_max, p: QuarterCarParams = PAPER_PARAMS):
    """Distance [m] to brake from ``v0`` to ``v_stop`` at the road's peak friction held the whole way.

    ``(v0^2 - v_stop^2) / (2 g mu_max)``: the figure every ABS result is divided by (DESIGN.md).
    """
    return (np.square(v0) - np.square(v_stop)) / (2.0 * p.g * mu_max)
