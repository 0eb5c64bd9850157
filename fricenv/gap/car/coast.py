"""The car's drag from its coasting (a coast-down): with neither brake nor drive, ``m v' = -(c0 + c2 v^2)`` (rolling
resistance, a closed throttle's engine braking, aerodynamic drag), fitted by non-negative least squares on the
slope of ``v`` over the session's coasting samples, as fast as the events and on a path as straight."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import nnls
from scipy.signal import savgol_filter

from fricenv.gap.car.events import DEFAULT_RULES, EventRules, applied, lateral_acceleration
from fricenv.gap.car.session import Session

__all__ = ["CoastDown", "coast_down"]

SAVGOL = (11, 2)  # the slope of v: window [samples], order
MIN_SAMPLES = 50  # fewest coasting samples for a drag [-]


@dataclass(frozen=True)
class CoastDown:
    """Drag coefficients (``c0`` [N], ``c2`` [N s^2/m^2]), the samples, and the drag force's z at the mean coasting
    speed (its estimate over its standard error, the residuals' correlation over the derivative window counted)."""

    c0: float
    c2: float
    samples: int
    z: float

    def summary(self) -> dict:
        return {"c0": self.c0, "c2": self.c2, "samples": self.samples, "z": self.z}


def coast_down(s: Session, mass: float, wheelbase: float, rules: EventRules = DEFAULT_RULES) -> CoastDown | None:
    """The coast-down drag, or None with fewer than ``MIN_SAMPLES`` coasting samples.

    :param mass: the mass the deceleration moves (with the wheels' rotation) [kg].
    """
    if len(s) < 4 * SAVGOL[0]:
        return None
    v = np.nan_to_num(s.v)
    moving = v > rules.min_speed
    coast = moving & ~applied(s.T_b, moving, rules.brake_share)
    if s.throttle is not None:
        coast &= ~applied(s.throttle, moving, rules.throttle_share)
    coast &= lateral_acceleration(s, wheelbase) <= rules.max_lateral
    # the derivative window must hold coasting samples only
    k = SAVGOL[0] // 2
    inner = np.convolve(coast.astype(float), np.ones(SAVGOL[0]), "same") >= SAVGOL[0] - 0.5
    ok = coast & inner
    ok[:k] = ok[-k:] = False
    n = int(np.count_nonzero(ok))
    if n < MIN_SAMPLES:
        return None
    dv = savgol_filter(v, SAVGOL[0], SAVGOL[1], deriv=1, delta=s.dt)
    A = np.c_[np.ones(n), v[ok] ** 2]
    coef, _ = nnls(A, -mass * dv[ok])
    resid = -mass * dv[ok] - A @ coef
    n_eff = max(n / SAVGOL[0], 2.0)
    vm = float(np.mean(v[ok]))
    g = np.array([1.0, vm ** 2])
    cov = np.linalg.pinv(A.T @ A) * float(np.sum(resid ** 2)) / max(n - 2, 1) * (n / n_eff)
    se = float(np.sqrt(max(g @ cov @ g, 1e-300)))
    return CoastDown(c0=float(coef[0]), c2=float(coef[1]), samples=n, z=float(g @ coef) / se)
