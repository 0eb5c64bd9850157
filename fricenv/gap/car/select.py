"""The effect set of a car: a forward selection over the library effects the car model holds, each step scored on
held-out windows (:func:`fricenv.gap.car.pooled.cross_fit`), and the verdict."""

from __future__ import annotations

import numpy as np

from fricenv import progress
from fricenv.gap.car.pooled import HeldOut, Problem, cross_fit

__all__ = ["forward_select", "gap", "paired_z", "verdict"]


def gap(mse: np.ndarray) -> float:
    """The model part of a held-out error in noise units, ``sqrt(max(mean MSE - 1, 0))``."""
    m = np.asarray(mse, dtype=float)
    m = m[np.isfinite(m)]
    return float(np.sqrt(max(np.mean(m) - 1.0, 0.0))) if m.size else float("nan")


def paired_z(before: np.ndarray, after: np.ndarray) -> float:
    """Paired z of the held-out improvement per window (mean over its standard error)."""
    d = np.asarray(before, dtype=float) - np.asarray(after, dtype=float)
    d = d[np.isfinite(d)]
    if d.size < 2:
        return 0.0
    se = np.std(d, ddof=1) / np.sqrt(d.size)
    return float(np.mean(d) / se) if se > 0 else (np.inf if np.mean(d) > 0 else 0.0)


def forward_select(pb: Problem, nominal: HeldOut, calibrations: tuple = ()) -> tuple[list, HeldOut, list]:
    """Add, while it helps on held-out windows (paired z above ``sig_z``), the candidate that lowers the held-out
    error most; at most ``max_effects``.

    :param calibrations: effects in the set from the start, fitted together, their held-out z reported only
        (measured outside the events, or a calibration the log's provenance predicts).
    :return: (the effects in the order added, their held-out errors, the steps tried).
    """
    chosen, cur, steps = [], nominal, []
    left = list(pb.cfg.candidates)
    cal = [e for e in calibrations if e in left]
    if cal:  # together: one calibration alone can move the model away from the data the others correct
        with progress.task("fit the car's calibrations", total=1) as advance:
            h = cross_fit(pb, cal)
            advance()
        steps.append({"added": "+".join(cal), "gap": gap(h.all()), "z_paired": paired_z(cur.all(), h.all()),
                      "tried": {"+".join(cal): gap(h.all())}, "accepted": True, "calibration": True})
        chosen += cal
        left = [c for c in left if c not in cal]
        cur = h
    while left and len(chosen) < pb.cfg.max_effects:
        tried = {}
        with progress.task(f"fit the car with {len(chosen) + 1} effect(s)", total=len(left)) as advance:
            for c in left:
                tried[c] = cross_fit(pb, chosen + [c], cur)
                advance()
        best = min(tried, key=lambda c: np.nanmean(tried[c].all()))
        z = paired_z(cur.all(), tried[best].all())
        steps.append({"added": best, "gap": gap(tried[best].all()), "z_paired": z,
                      "tried": {c: gap(h.all()) for c, h in tried.items()}, "accepted": z > pb.cfg.sig_z})
        if z <= pb.cfg.sig_z:
            break
        chosen.append(best)
        left.remove(best)
        cur = tried[best]
    return chosen, cur, steps


def verdict(effects: list, gap_before: float, gap_after: float, ratio: float, gap_none: float) -> str:
    """The first effect when the set closes the gap (``gap_after <= ratio * gap_before``); ``none`` when the
    nominal model fits within noise; else ``unexplained``."""
    if gap_before <= gap_none:
        return "none"
    if effects and gap_after <= ratio * gap_before:
        return effects[0]
    return "unexplained"
