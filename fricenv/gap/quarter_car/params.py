"""Named parameter vectors of the quarter-car fits: the road ``(B, C, E, theta)`` first, then each effect's
parameters in registry order; ranges, finite-difference steps and scales per name (the effects' from the registry).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fricenv.effects import registry

__all__ = ["ROAD", "ROAD_BOUNDS", "ROAD_NAMES", "effect_param", "fd_steps", "param_bounds", "param_names",
           "road_of", "x_scales"]

ROAD_NAMES = ("B", "C", "E", "theta")
ROAD = slice(0, len(ROAD_NAMES))  # the road's part of a parameter vector
# Road parameter bounds for the fit: wide enough for every preset and for unknown roads. B and theta: wide.
# C and E: the physically plausible range of longitudinal Magic Formula shapes (the presets span C 0.9-2.3,
# E -6.4-1). A wider range lets the nominal road take unphysical shapes that absorb an effect (a flat curve with
# E = -12 hides a rolling-radius error on ice).
ROAD_BOUNDS = {"B": (2.0, 40.0), "C": (0.8, 2.8), "E": (-8.0, 1.0), "theta": (0.03, 1.6)}
# Finite-difference steps of the fit Jacobian and trust-region scales of the road parameters (absolute).
ROAD_FD_STEP = {"B": 0.05, "C": 0.005, "E": 0.02, "theta": 0.002}
ROAD_X_SCALE = {"B": 1.0, "C": 0.1, "E": 0.5, "theta": 0.05}


def param_names(effects: Sequence[str]) -> tuple[str, ...]:
    """The names of the parameter vector of the road plus ``effects``."""
    names = list(ROAD_NAMES)
    for e in effects:
        names += list(registry.get(e).param_names)
    return tuple(names)


def effect_param(name: str) -> registry.Param:
    """The registry's description of a library effect parameter."""
    for entry in registry.REGISTRY.values():
        if entry.in_library:
            for q in entry.params:
                if q.name == name:
                    return q
    raise KeyError(f"no library effect has a parameter {name!r}")


def road_of(x: np.ndarray) -> np.ndarray:
    """The road part ``(B, C, E, theta)`` of a parameter vector (or of each row of a matrix)."""
    return np.asarray(x)[..., ROAD]


def param_bounds(names: Sequence[str], train_starts: np.ndarray, t0: float, dt: float, horizon: int):
    """Lower and upper bounds of the parameters ``names``; a log time lies between the first and the last training
    window (at least one training window on either side).

    :param train_starts: start samples of the training windows.
    """
    lo, hi = [], []
    for n in names:
        if n in ROAD_BOUNDS:
            b = ROAD_BOUNDS[n]
        elif effect_param(n).log_time:
            b = (t0 + dt * (train_starts[0] + horizon), t0 + dt * train_starts[-1])
        else:
            b = effect_param(n).bounds
        lo.append(b[0])
        hi.append(b[1])
    return np.array(lo), np.array(hi)


def fd_steps(names: Sequence[str]) -> np.ndarray:
    return np.array([ROAD_FD_STEP[n] if n in ROAD_FD_STEP else effect_param(n).fd_step for n in names])


def x_scales(names: Sequence[str]) -> np.ndarray:
    return np.array([ROAD_X_SCALE[n] if n in ROAD_X_SCALE else effect_param(n).x_scale for n in names])
