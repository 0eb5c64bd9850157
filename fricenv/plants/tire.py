"""Tire-road friction: the Magic Formula and the road presets.

This module is the single home of the Magic Formula (Sui & Johansen, eq. (2)) and of the slip; every other module
imports them. They are plain arithmetic over the ``np`` namespace, so numba compiles the same functions for the fast
paths (:mod:`fricenv.plants.compiled`) and the estimators build their CasADi models from them
(:mod:`fricenv.plants.namespace`).

    mu(lambda) = theta * sin(C * atan(B*lambda - E*(B*lambda - atan(B*lambda))))

The formula is odd in the slip, so a negative (traction) slip gives a negative friction coefficient, i.e. a force
that pushes the vehicle forward. Slip conventions are in :func:`longitudinal_slip`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy.optimize import minimize_scalar

from fricenv.errors import InvalidInputError

__all__ = [
    "DRY",
    "ICE",
    "ROADS",
    "SNOW",
    "WET",
    "MagicFormula",
    "UnknownRoadError",
    "ecu_slip",
    "get_road",
    "longitudinal_slip",
    "magic_formula",
    "magic_formula_and_dslip",
    "magic_formula_dslip",
    "slip_and_partials",
]

# Below this speed [m/s] the slip denominator is held, so slip stays finite as the vehicle comes to rest.
SLIP_SPEED_FLOOR = 0.1


class UnknownRoadError(InvalidInputError):
    """A road name that is not one of the presets."""


def magic_formula(slip, B, C, E, theta):
    """Friction coefficient of the Magic Formula, eq. (2) of Sui & Johansen; broadcasts over arrays.

    :param slip: longitudinal slip [-], positive when braking, negative in traction.
    :param B: stiffness factor [-].
    :param C: shape factor [-].
    :param E: curvature factor [-].
    :param theta: road condition coefficient (peak factor) [-].
    :return: friction coefficient mu [-].
    """
    bs = B * slip
    return theta * np.sin(C * np.arctan(bs - E * (bs - np.arctan(bs))))


def magic_formula_dslip(slip, B, C, E, theta):
    """Derivative d mu / d slip of :func:`magic_formula` (closed form, used by Jacobians)."""
    return magic_formula_and_dslip(slip, B, C, E, theta)[1]


def magic_formula_and_dslip(slip, B, C, E, theta):
    """``(mu, d mu / d slip)`` of :func:`magic_formula`, sharing the arctangents (the integrators need both)."""
    bs = B * slip
    inner = bs - E * (bs - np.arctan(bs))
    # d inner / d slip = B * (1 - E + E / (1 + bs^2))
    dinner = B * (1.0 - E + E / (1.0 + bs * bs))
    angle = C * np.arctan(inner)
    return theta * np.sin(angle), theta * np.cos(angle) * C * dinner / (1.0 + inner * inner)


def longitudinal_slip(v, omega, r, speed_floor: float = SLIP_SPEED_FLOOR):
    """Signed longitudinal slip for braking and traction.

    Braking (``v >= omega r``) uses eq. (3) of Sui & Johansen, ``(v - omega r) / v``, in [0, 1]. Traction
    (``omega r > v``) uses the definition of Li, Du & Li, ``(omega r - v) / (omega r)``, returned with a negative
    sign so that one odd Magic Formula covers both. Both share the denominator ``max(v, omega r)``, held above
    ``speed_floor`` so that slip stays finite at standstill.

    :param v: vehicle speed [m/s].
    :param omega: wheel angular speed [rad/s].
    :param r: wheel radius [m].
    :param speed_floor: smallest denominator [m/s].
    :return: slip in [-1, 1] (clipped to 1 if the wheel turns backwards).
    """
    wr = omega * r
    return (v - wr) / np.maximum(np.maximum(v, wr), speed_floor)


def ecu_slip(omega, v_ref, r, speed_floor: float = SLIP_SPEED_FLOOR):
    """Braking slip as an ABS ECU estimates it: ``1 - omega r / max(v_ref, speed_floor)``, from a (measured or
    filtered) wheel speed and the ECU's reference speed in place of the unknown vehicle speed.

    :param omega: wheel speed [rad/s].
    :param v_ref: the ECU's reference (estimated vehicle) speed [m/s].
    :param r: wheel radius [m].
    :param speed_floor: smallest reference speed in the denominator [m/s].
    :return: slip estimate [-] (floats or arrays).
    """
    return 1.0 - omega * r / np.maximum(v_ref, speed_floor)


def slip_and_partials(v, omega, r, speed_floor: float = SLIP_SPEED_FLOOR):
    """:func:`longitudinal_slip` with its partial derivatives: ``(lambda, d lambda / d v, d lambda / d omega)``.

    braking: lambda = 1 - omega r / v      -> d/dv = omega r / v^2,   d/domega = -r / v
    traction: lambda = v / (omega r) - 1   -> d/dv = 1 / (omega r),   d/domega = -v r / (omega r)^2
    floored denominator: (v - omega r) / floor -> d/dv = 1 / floor,   d/domega = -r / floor
    """
    wr = omega * r
    denom = np.maximum(np.maximum(v, wr), speed_floor)
    floored = denom <= speed_floor
    braking = v >= wr
    dlam_dv = np.where(floored, 1.0, np.where(braking, wr / denom, 1.0)) / denom
    dlam_dw = np.where(floored | braking, -r, -v * r / denom) / denom
    return (v - wr) / denom, dlam_dv, dlam_dw


@dataclass(frozen=True)
class MagicFormula:
    """Magic Formula parameters of one tire-road pair.

    ``peak_slip`` and ``mu_max`` are found numerically on slip in (0, 1]; for a curve that rises all the way (the
    paper's snow, C < 1), the peak is at slip 1.
    """

    B: float  # stiffness factor [-]
    C: float  # shape factor [-]
    E: float  # curvature factor [-]
    theta: float  # road condition coefficient [-]
    name: str = field(default="custom", compare=False)

    def mu(self, slip):
        """Friction coefficient at ``slip`` [-]."""
        return magic_formula(slip, self.B, self.C, self.E, self.theta)

    def dmu(self, slip):
        """Slope d mu / d slip at ``slip``."""
        return magic_formula_dslip(slip, self.B, self.C, self.E, self.theta)

    @cached_property
    def _peak(self) -> tuple[float, float]:
        # Coarse grid first: the curve may have a local maximum and a higher value at slip 1.
        grid = np.linspace(1e-4, 1.0, 2001)
        mu = self.mu(grid)
        i = int(np.argmax(mu))
        if i == len(grid) - 1:
            return 1.0, float(mu[-1])
        lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
        res = minimize_scalar(lambda s: -self.mu(s), bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-10})
        return float(res.x), float(-res.fun)

    @property
    def peak_slip(self) -> float:
        """Slip lambda* at which mu is largest on (0, 1] [-]."""
        return self._peak[0]

    @property
    def mu_max(self) -> float:
        """Largest friction coefficient on (0, 1] [-]."""
        return self._peak[1]

    @property
    def mu_locked(self) -> float:
        """Sliding friction of a locked wheel, mu(1) [-]."""
        return float(self.mu(1.0))

    def as_array(self) -> np.ndarray:
        """(B, C, E, theta) as a float array."""
        return np.array([self.B, self.C, self.E, self.theta], dtype=float)


# Sui & Johansen, eq. (4) (after Matuško et al.).
DRY = MagicFormula(B=10.38, C=1.65, E=0.65663, theta=1.0, name="dry")
# Sui & Johansen, eq. (5). C < 1: mu keeps rising up to slip 1, so this curve has no interior peak.
SNOW = MagicFormula(B=14.395, C=0.9, E=-6.439, theta=0.3, name="snow")
# Wet asphalt and ice: the Pacejka "simplified Magic Formula" coefficient sets common in vehicle-dynamics tools
# (e.g. MathWorks' Tire-Road Interaction (Magic Formula) block documentation: wet B=12 C=2.3 D=0.82 E=1,
# ice B=4 C=2 D=0.1 E=1).
WET = MagicFormula(B=12.0, C=2.3, E=1.0, theta=0.82, name="wet")
ICE = MagicFormula(B=4.0, C=2.0, E=1.0, theta=0.1, name="ice")

ROADS: dict[str, MagicFormula] = {road.name: road for road in (DRY, WET, SNOW, ICE)}


def get_road(name: str) -> MagicFormula:
    """Road preset by name; raises :class:`UnknownRoadError` listing the valid names."""
    try:
        return ROADS[name]
    except KeyError:
        raise UnknownRoadError(f"unknown road {name!r}; valid roads: {', '.join(ROADS)}") from None
