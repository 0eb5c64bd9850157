"""Straight-line two-axle vehicle with the Dugoff tire (Li, Du & Li, eqs. (1)-(2), Table I), batched.

With the steer angle delta_f = 0 and no lateral disturbance, eq. (1) keeps v_y = 0 and the yaw rate at 0, and
reduces to the longitudinal and wheel dynamics (one wheel per axle, as in the paper's single-track model):

    m v_x'      = F_xf + F_xr                    (1, first row, delta_f = 0, v_y r = 0)
    I_w omega_f' = -F_xf R_w + T_f               (1, fourth row)
    I_w omega_r' = -F_xr R_w + T_r               (1, fifth row)

``T > 0`` drives, ``T < 0`` brakes; forces are positive forward. Axle loads are static,
``F_zf = m g L_r / (L_f + L_r)``, ``F_zr = m g L_f / (L_f + L_r)``.

Dugoff tire, eq. (2), with slip angle alpha = 0 and the slip of eq. (3), S = (omega R - v)/max(v, omega R)
(positive in traction):

    lambda_D = mu F_z (1 - eps_r u |S|) (1 - |S|) / (2 C_s |S|),  f = lambda_D (2 - lambda_D) if lambda_D < 1 else 1
    F_x = C_s S / (1 - |S|) f(lambda_D)

(the paper writes S for braking slip; the magnitude |S| with the sign of S covers traction and braking alike).

Integration: classic RK4 with ``substeps`` per call. The wheel equation is stiff at low speed (time constant
``I_w v / (R_w^2 C_s)``, 3.4 ms at 10 m/s), so the default 1 ms substeps keep RK4 inside its stability region
down to about 2 m/s; checked against scipy's Radau in the tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fricenv.plants import li_du_li as ldl
from fricenv.plants.tire import longitudinal_slip

__all__ = ["TABLE_I", "TwoAxleParams", "axle_loads", "derivatives", "dugoff_force", "slip", "step"]

SLIP_MIN = 1e-9  # |S| below this: the Dugoff force is C_s S (f = 1)
SLIP_MAX = 0.999  # |S| is clipped here so that 1 - |S| > 0


@dataclass(frozen=True)
class TwoAxleParams:
    """Table I of Li, Du & Li."""

    m: float = ldl.MASS  # vehicle mass [kg]
    L_f: float = ldl.L_F  # CG to front axle [m]
    L_r: float = ldl.L_R  # CG to rear axle [m]
    C_s: float = ldl.TIRE_STIFFNESS  # longitudinal tire stiffness [N/unit slip]
    I_z: float = ldl.YAW_INERTIA  # yaw inertia [kg m^2] (unused in straight line)
    R_w: float = ldl.WHEEL_RADIUS  # wheel radius [m]
    I_w: float = ldl.WHEEL_INERTIA  # wheel inertia [kg m^2]
    mu: float = ldl.ROAD_MU  # road friction coefficient [-]
    eps_r: float = ldl.DUGOFF_EPS_R  # Dugoff velocity reduction factor [s/m]
    C_alpha: float = ldl.CORNERING_STIFFNESS  # cornering stiffness [N/rad] (unused in straight line)
    g: float = 9.81  # gravity [m/s^2]

    def __post_init__(self):
        for name in ("m", "L_f", "L_r", "C_s", "R_w", "I_w", "g"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"TwoAxleParams.{name} must be finite and > 0, got {value!r}")
        if not (np.isfinite(self.mu) and self.mu >= 0):
            raise ValueError(f"TwoAxleParams.mu must be finite and >= 0, got {self.mu!r}")


TABLE_I = TwoAxleParams()


def axle_loads(p: TwoAxleParams = TABLE_I) -> tuple[float, float]:
    """Static (F_zf, F_zr) [N]."""
    L = p.L_f + p.L_r
    return p.m * p.g * p.L_r / L, p.m * p.g * p.L_f / L


def slip(v, omega, p: TwoAxleParams = TABLE_I):
    """Eq. (3): S = (omega R - v) / max(v, omega R), positive in traction: :func:`fricenv.plants.tire.
    longitudinal_slip` with Li, Du & Li's sign."""
    return -longitudinal_slip(v, omega, p.R_w)


def dugoff_force(S, Fz, u, mu, p: TwoAxleParams = TABLE_I):
    """Dugoff longitudinal force, eq. (2) with alpha = 0 [N]; broadcasts.

    :param S: slip (positive traction) [-].
    :param Fz: vertical load [N].
    :param u: wheel-plane speed [m/s].
    :param mu: friction coefficient [-].
    :param p: vehicle parameters (C_s, eps_r).
    """
    a = np.clip(np.abs(S), SLIP_MIN, SLIP_MAX)
    lam = mu * Fz * (1.0 - p.eps_r * u * a) * (1.0 - a) / (2.0 * p.C_s * a)
    f = np.where(lam < 1.0, lam * (2.0 - lam), 1.0)
    return np.sign(S) * p.C_s * a / (1.0 - a) * f


def derivatives(v, wf, wr, Tf, Tr, p: TwoAxleParams = TABLE_I, mu=None):
    """Right-hand side of eq. (1) with delta_f = 0: (v', omega_f', omega_r').

    :param mu: friction coefficient override (array or scalar; default ``p.mu``).
    """
    mu = p.mu if mu is None else mu
    Fzf, Fzr = axle_loads(p)
    Ff = dugoff_force(slip(v, wf, p), Fzf, v, mu, p)
    Fr = dugoff_force(slip(v, wr, p), Fzr, v, mu, p)
    return (Ff + Fr) / p.m, (-Ff * p.R_w + Tf) / p.I_w, (-Fr * p.R_w + Tr) / p.I_w


def step(v, wf, wr, Tf, Tr, dt: float, p: TwoAxleParams = TABLE_I, substeps: int = 10, mu=None):
    """Advance by ``dt`` with torques held (zero-order hold); RK4 substeps; batched over a leading dimension.

    Wheel speeds are kept >= 0 (a locked wheel does not turn backwards) and the speed >= 0.

    :return: (v, omega_f, omega_r), new arrays.
    """
    if substeps < 1:
        raise ValueError(f"substeps must be >= 1, got {substeps}")
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a finite positive time step, got {dt!r}")
    h = dt / substeps
    x = [np.asarray(v, dtype=float), np.asarray(wf, dtype=float), np.asarray(wr, dtype=float)]

    def rhs(s):
        return derivatives(s[0], s[1], s[2], Tf, Tr, p, mu)

    for _ in range(substeps):
        k1 = rhs(x)
        k2 = rhs([xi + 0.5 * h * ki for xi, ki in zip(x, k1)])
        k3 = rhs([xi + 0.5 * h * ki for xi, ki in zip(x, k2)])
        k4 = rhs([xi + h * ki for xi, ki in zip(x, k3)])
        x = [np.maximum(xi + h / 6.0 * (a + 2 * b + 2 * c + d), 0.0) for xi, a, b, c, d in zip(x, k1, k2, k3, k4)]
    return x[0], x[1], x[2]
