"""Each wheel's rolling radius from the session's free rolling: with neither brake nor drive torque a tire carries
no longitudinal force and rolls without slip, so ``r_eff = v / omega``. Measured as the median over the samples
with the brake and the drive off, a straight path and a speed well above the events' floor, where the wheel speed's
quantisation and the speed estimate's offsets weigh least.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fricenv.gap.car.events import DEFAULT_RULES, EventRules, applied
from fricenv.gap.car.session import Session

__all__ = ["FreeRolling", "free_rolling_radii"]

MIN_SPEED = 10.0  # free rolling counts above this speed [m/s]
MAX_YAW_RATE = 0.02  # straight: |yaw rate| below this [rad/s] (or the same curvature from the steering angle)
MIN_SAMPLES = 25  # fewest free-rolling samples for a radius [-]


@dataclass(frozen=True)
class FreeRolling:
    """Radii by corner [m], the samples they come from, and the spread (interquartile range / 1.349) per corner."""

    radii: dict
    samples: int
    spread: dict

    def z(self, nominal: dict) -> float:
        """The largest distance of a radius from its ``nominal`` (corner -> m) in standard errors of its median
        (``1.2533 spread / sqrt(samples)``)."""
        return max(abs(r - nominal[c]) / max(1.2533 * self.spread[c] / np.sqrt(self.samples), 1e-12)
                   for c, r in self.radii.items())

    def summary(self, nominal: dict | None = None) -> dict:
        out = {"samples": self.samples, "radius": dict(self.radii), "spread": dict(self.spread)}
        if nominal is not None:
            out["z_from_nominal"] = self.z(nominal)
        return out


def _straight(s: Session, wheelbase: float) -> np.ndarray:
    if s.yaw_rate is not None:
        return np.abs(np.nan_to_num(s.yaw_rate, nan=np.inf)) < MAX_YAW_RATE
    if s.steer is not None:  # yaw rate of a rolling car ~ v steer / L
        return np.abs(s.v * np.nan_to_num(s.steer, nan=np.inf) / wheelbase) < MAX_YAW_RATE
    return np.ones(len(s), dtype=bool)


def free_rolling_radii(s: Session, wheelbase: float, rules: EventRules = DEFAULT_RULES) -> FreeRolling | None:
    """The free-rolling radius of every logged wheel, or None with fewer than ``MIN_SAMPLES`` free-rolling samples
    (the brake applied and the drive as :func:`fricenv.gap.car.events.applied` reads them)."""
    v = np.nan_to_num(s.v)
    moving = v > rules.min_speed
    free = (v > MIN_SPEED) & ~applied(s.T_b, moving, rules.brake_share) & _straight(s, wheelbase)
    if s.throttle is not None:
        free &= ~applied(s.throttle, moving, rules.throttle_share)
    radii, spread = {}, {}
    for c, w in s.wheels.items():
        ok = free & np.isfinite(w) & (w > 0)
        if np.count_nonzero(ok) < MIN_SAMPLES:
            return None
        ratio = v[ok] / w[ok]
        radii[c] = float(np.median(ratio))
        q1, q3 = np.percentile(ratio, [25, 75])
        spread[c] = float((q3 - q1) / 1.349)
    return FreeRolling(radii=radii, samples=int(np.count_nonzero(free)), spread=spread)
