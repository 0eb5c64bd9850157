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
L-stable Rosenbrock method (ROS2, Verwer et al. 1999) with an exact Jacobian
(:func:`fricenv.plants.rosenbrock.ros2_substep`), which stays accurate and stable for substeps far longer than that
time constant. It is checked against scipy's Radau in the tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fricenv.plants import sui_johansen as sj
from fricenv.plants.rosenbrock import (
    REFINE_MIN_STEP,
    REFINE_PARTS,
    ROS2_GAMMA,
    braking_invariant_broken,
    ros2_substep,
)
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
    "slip_ode",
    "slip_ode_given_accel",
    "step",
    "tire_force",
]



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
    """Wheel-slip dynamics, eq. (6), valid for braking (v > 0, omega >= 0): returns (v', lambda') of
    :func:`slip_ode` for a road array."""
    road = np.asarray(road, dtype=float)
    return slip_ode(v, lam, Tb, road[..., 0], road[..., 1], road[..., 2], road[..., 3], p.r, p.m, p.J, p.Fz)


def slip_ode(v, lam, Tb, B, C, E, theta, r, m, J, Fz):
    """Wheel-slip dynamics, eq. (6), in plain math (the estimators' CasADi model is built from it):

        v'      = -F_z mu(lambda) / m                                              (6a)
        lambda' = -(1/v) ((1 - lambda)/m + r^2/J) F_z mu(lambda) + (1/v)(r/J) T_b   (6b)

    :return: (v', lambda').
    """
    Fx = Fz * magic_formula(lam, B, C, E, theta)
    vdot = -Fx / m
    lamdot = (-((1.0 - lam) / m + r**2 / J) * Fx + r / J * Tb) / v
    return vdot, lamdot


def slip_ode_given_accel(vdot, v, lam, Tb, B, C, E, theta, r, J, Fz):
    """The slip of eq. (6b) when the car's acceleration ``v'`` is given (a measured ``a_x``) rather than eq. (6a):
    ``lambda = 1 - r omega / v`` differentiated, with the wheel of eq. (1b),

        lambda' = ((1 - lambda) v' - r omega') / v,    J omega' = r F_z mu(lambda) - T_b

    With ``v' = -F_z mu(lambda) / m`` it is eq. (6b) (tested). In plain math, as :func:`slip_ode`.

    :return: lambda'.
    """
    r_omega_dot = r * (r * Fz * magic_formula(lam, B, C, E, theta) - Tb) / J
    return ((1.0 - lam) * vdot - r_omega_dot) / v


def step(v, omega, Tb, road, dt: float, p: QuarterCarParams = PAPER_PARAMS, substeps: int = 1):
    """Advance the batch by ``dt`` seconds under a brake torque held constant (zero-order hold).

    Each of the ``substeps`` physics steps is one ROS2 step (:func:`fricenv.plants.rosenbrock.ros2_substep`):

        (I - gamma h A) k1 = f(x)
        (I - gamma h A) k2 = f(x + h k1) - 2 k1
        x+ = x + h (3/2 k1 + 1/2 k2)

    followed by the lock constraint ``omega >= 0`` (the static brake holds a wheel that would turn backwards) and
    ``v >= 0`` (the car does not reverse under braking); a substep that breaks the braking invariant is redone in
    finer parts (:func:`refine_where_unphysical`).

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
    v = np.asarray(v, dtype=float)
    omega = np.asarray(omega, dtype=float)
    B, C, E, theta = road[..., 0], road[..., 1], road[..., 2], road[..., 3]
    mu1 = magic_formula(1.0, B, C, E, theta)
    for _ in range(substeps):
        v_new, w_new, _ = ros2_substep(v, omega, Tb, B, C, E, theta, mu1, h, p.r, p.m, p.J, p.Fz)
        v, omega = refine_where_unphysical(v, omega, v_new, w_new, Tb, road, h, p)
    return v, omega


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


def physical_limit_distance(v0, v_stop, mu_max, p: QuarterCarParams = PAPER_PARAMS):
    """Distance [m] to brake from ``v0`` to ``v_stop`` at the road's peak friction held the whole way.

    ``(v0^2 - v_stop^2) / (2 g mu_max)``: the figure every ABS result is divided by (docs/contracts.md).
    """
    return (np.square(v0) - np.square(v_stop)) / (2.0 * p.g * mu_max)
