"""Validate the EKF/RLS curve-shape fit on fresh noise seeds: per road, the share of samples after
settling whose estimated peak slip is the road's (within the test's tolerance), on the braking logs of
``tests/estimators/test_curve_shape.py``. The fit was tuned on noise seeds 1-20; report other seeds.

    python -m tests.shape_validation --seeds 300 310
"""

from __future__ import annotations

import argparse

import numpy as np

from fricenv.plants.tire import DRY, ICE, ROADS
from tests.estimators import test_curve_shape as T


def road_shares(name: str, seeds: range) -> list[float]:
    """Per seed, the share of samples after ``SETTLE`` on the road's peak (snow: keeping its friction)."""
    road, out = ROADS[name], []
    for s in seeds:
        log = T.braking_log(road, s)
        est = T.estimated_peak_slip(log)[log["t"] >= T.SETTLE]
        if name == "snow":
            out.append(float(np.mean(road.mu(est) >= T.SNOW_MU_FRACTION * road.mu_max)))
        else:
            out.append(float(np.mean(np.abs(est - road.peak_slip) <= T.SLIP_TOL)))
    return out


def jump_shares(before, after, seeds: range) -> list[float]:
    """Per seed, the share of samples on the new road's peak once the test's follow time after the jump is over."""
    out = []
    for s in seeds:
        log = T.braking_log(before, s, road_after=after)
        est = T.estimated_peak_slip(log)
        late = log["t"] >= T.JUMP_AT + (T.FOLLOW_TIME if after is ICE else T.DRY_AGAIN_TIME)
        out.append(float(np.mean(np.abs(est[late] - after.peak_slip) <= T.SLIP_TOL)))
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs=2, default=(300, 310), metavar=("FIRST", "STOP"),
                        help="noise seeds FIRST..STOP-1 (default 300 310; the fit was tuned on 1-20)")
    a = parser.parse_args(argv)
    seeds = range(*a.seeds)
    for name in ("dry", "wet", "snow", "ice"):
        shares = road_shares(name, seeds)
        need = T.WET_FRACTION if name == "wet" else 1.0
        print(f"{name:9s} placed on {sum(f >= need for f in shares)}/{len(shares)} seeds  "
              + " ".join(f"{f:.2f}" for f in shares))
    for before, after, label in ((DRY, ICE, "dry->ice"), (ICE, DRY, "ice->dry")):
        print(f"{label:9s} share on the new peak: " + " ".join(f"{f:.2f}" for f in jump_shares(before, after, seeds)))


if __name__ == "__main__":
    main()
