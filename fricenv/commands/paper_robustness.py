"""The estimators under the effect grid: rms speed, slip and friction error per plant cell, and health shares.

Every env estimator (``ekf``, ``mhe``, ``ekf-rls``, ``ekf-full``, ``mhe-full``, ``ekf-ax``, ``mhe-ax``) runs over
the same stops: the gap tool's stand-in with its ``abs`` and ``open-loop`` drivers on dry, wet and snow,
``--seeds`` seeds (0..n-1; each draws the initial speed on 20-32 m/s, the free roll, the driver and the noise), on
the nominal plant and on every cell of the effect grid (each library effect at its low and high size; radius and
friction change relative to the road, the change at mid-stop). Errors count from 0.5 s after the brake is first
applied: rms speed, slip and friction-in-use error (rms over the stops of a cell), the worst speed error over the
whole stop, the share of samples with each health value (ok, not_excited, solver_failed, invalid_input,
outlier, reinitialised, ...), and the stops that miss the target (``agents.robustness.meets_target``). Every estimator's model has the nominal vehicle parameters, as the env builds it;
with ``--told-radius`` a radius-error cell's estimators are given that cell's rolling radius, as a calibration (the
gap tool's ``radius_error`` verdict) would give it.

Writes into ``--out``: ``robustness.txt`` (the rms speed error table, estimator x cell), ``robustness.json`` (the
matrix, every stop's row and the run's settings) and ``robustness.png`` (the heatmap); prints the tables of rms
speed error, worst speed error and outlier share. Stops run in ``--workers`` processes or, with ``--ray
auto|ADDRESS``, as Ray tasks (one CPU each; 'auto' joins a running instance or starts a local one, shut down after).
"""

from __future__ import annotations

import argparse

DEFAULT_SEEDS = 3


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``fricenv paper robustness``."""
    from agents.robustness import ESTIMATORS

    parser.add_argument("--out", default="runs/paper_robustness", metavar="DIR",
                        help="output directory (default %(default)s)")
    parser.add_argument("--seeds", type=int, default=DEFAULT_SEEDS,
                        help="stops per (driver, road, cell): seeds 0..n-1 (default %(default)s)")
    parser.add_argument("--estimators", nargs="+", default=None, metavar="EST",
                        help="env estimators (default: " + " ".join(ESTIMATORS) + ")")
    parser.add_argument("--effects", nargs="+", default=None, metavar="EFFECT",
                        help="grid effects to run (default: all); the nominal plant always runs")
    parser.add_argument("--told-radius", action="store_true",
                        help="give the estimators a radius_error cell's rolling radius, as a calibration would "
                             "(default: every estimator uses the nominal radius on every cell)")
    parser.add_argument("--workers", type=int, default=2, help="worker processes (default %(default)s)")
    parser.add_argument("--ray", metavar="auto|ADDRESS", default=None,
                        help="run the stops as Ray tasks: 'auto' (a running instance, else a local one) or a "
                             "cluster address; --workers is then not used")


def _check(args) -> tuple:
    """Validate the options before any work; the estimators and cells."""
    from agents.robustness import ESTIMATORS
    from fricenv.effects.grid import EFFECT_GRID, grid_cells
    from fricenv.errors import InvalidInputError

    if args.seeds < 1:
        raise InvalidInputError("--seeds must be >= 1")
    if args.workers < 1:
        raise InvalidInputError("--workers must be >= 1")
    estimators = tuple(args.estimators or ESTIMATORS)
    bad = [e for e in estimators if e not in ESTIMATORS]
    if bad:
        raise InvalidInputError(f"--estimators: unknown {', '.join(bad)}; valid: {', '.join(ESTIMATORS)}")
    effects = tuple(args.effects or EFFECT_GRID)
    bad = [e for e in effects if e not in EFFECT_GRID]
    if bad:
        raise InvalidInputError(f"--effects: unknown {', '.join(bad)}; valid: {', '.join(EFFECT_GRID)}")
    return estimators, grid_cells(effects)


def run(args) -> int:
    """Run the study, print the tables, write table, JSON and heatmap."""
    import sys
    import time

    from agents.robustness import (
        DRIVERS,
        MAX_ERROR,
        MAX_FLAGS,
        RMS_FACTOR,
        RMS_MARGIN,
        ROADS,
        study,
        summarize,
    )
    from agents.robustness_report import format_matrix, write_matrix

    estimators, cells = _check(args)
    seeds = list(range(args.seeds))
    n_stops = len(cells) * len(DRIVERS) * len(ROADS) * len(seeds)
    engine = f"Ray {args.ray}" if args.ray else f"{args.workers} worker(s)"
    print(f"{n_stops} stops ({len(cells)} plant cells x {len(DRIVERS)} drivers x {len(ROADS)} roads x "
          f"{len(seeds)} seeds), {len(estimators)} estimators each, on {engine}", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    rows = study(estimators, cells, seeds=seeds, workers=args.workers, ray=args.ray, told_radius=args.told_radius)
    wall = time.perf_counter() - t0
    matrix = summarize(rows)
    for m in matrix:
        m["outlier"] = m["health"].get("outlier", 0.0)
    for key, what in (("v_rms", "rms speed error [m/s]"), ("v_worst", "worst speed error [m/s]"),
                      ("slip_rms", "rms slip error [-]"), ("mu_rms", "rms friction error [-]"),
                      ("outlier", "share of samples flagged outlier [-]")):
        span = "whole stop" if key in ("v_worst", "outlier") else "after the first 0.5 s of braking"
        print(f"{what}, {span} ({', '.join(DRIVERS)}; {', '.join(ROADS)}; {len(seeds)} seeds)")
        print(format_matrix(matrix, "estimator", key, "{:.3f}" if key in ("slip_rms", "outlier") else "{:.2f}"))
        print()
    print(f"stops missing the target (rms within {RMS_FACTOR:g}x the same stop's nominal error + {RMS_MARGIN:g} m/s, "
          f"never {MAX_ERROR:g} m/s off, flags on at most {MAX_FLAGS:.0%} of the samples), of "
          f"{len(DRIVERS) * len(ROADS) * len(seeds)} per cell")
    print(format_matrix([m for m in matrix if m["cell"] != "nominal"], "estimator", "missed", "{:.0f}"))
    print()
    print(f"wall time {wall:.1f} s ({engine})")
    written = write_matrix(args.out, matrix, "estimator", "v_rms",
                           f"estimators under the effect grid: rms speed error [m/s] after 0.5 s of braking "
                           f"({len(seeds)} seeds)", "rms speed error [m/s]",
                           extra={"rows": rows, "seeds": seeds, "drivers": list(DRIVERS), "roads": list(ROADS),
                                  "told_radius": args.told_radius, "wall_time_s": wall, "engine": engine})
    for kind, path in written.items():
        print(f"wrote {kind}: {path}")
    return 0
