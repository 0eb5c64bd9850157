"""Which wheel-speed outliers does the diagnosis set aside? Matched by time on blind logs.

A real-like export (:mod:`tests.real_artifacts`) writes isolated outliers into the wheel speed and records where;
the diagnosis reads the export through its map, resamples it onto its grid and, preparing it, sets aside what its
sensor step (:func:`fricenv.gap.signals.sensors.condition_channel`) flags. An outlier counts as found when a flag lies within one grid
sample of its time stamp; a flag with no outlier there is false. Clean logs (no outliers written) give false flags
only. The check stops at the log's preparation: nothing is fitted.

Measurement command::

    python -m tests.outlier_check --n 60 --seed 3010 [--clean] [--jobs 2] [--json PATH]
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Sequence

import numpy as np

from tests import independent_sim as sim
from tests.measure_cli import measurement_parser, pool_map
from tests.real_artifacts import write_export

__all__ = ["check_case", "main", "measure"]

MATCH_SAMPLES = 1  # a flag this many grid samples from an outlier's time stamp finds it [-]


def _omega_flags(path: str) -> tuple[np.ndarray, float]:
    """The grid indices the diagnosis' log preparation (:func:`fricenv.gap.quarter_car.windows.prepare`) sets aside in a
    contract log's wheel speed (logged there, missing from its measurements), and the grid step [s]."""
    from fricenv.gap.quarter_car.config import DEFAULT_CONFIG
    from fricenv.gap.quarter_car.diagnose import read_log
    from fricenv.gap.quarter_car.windows import prepare
    from fricenv.plants.quarter_car import PAPER_PARAMS

    log = read_log(path)
    d = prepare(log, PAPER_PARAMS, DEFAULT_CONFIG)
    return np.flatnonzero(np.isfinite(log.omega) & ~np.isfinite(d.meas["omega"])), float(log.dt)


def check_case(case: sim.IndependentCase) -> dict:
    """One log: outliers written, found, and false flags (the written times are the export's, from its start)."""
    from fricenv.commands.gap_convert import convert

    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "log.csv")
        if case.real is None:
            sim.write_independent_log(path, case)
            written = np.zeros(0)
        else:
            export = sim.real_export(case)
            csv_path, map_path = write_export(os.path.join(tmp, "export"), export)
            convert(csv_path, map_path, "quarter-car", path)
            s = np.asarray(export.truth["instants"], dtype=float)
            written = s[np.asarray(export.truth["outlier_rows"], dtype=int)] - s[0]
        flags, dt = _omega_flags(path)
    at = np.round(written / dt).astype(int)
    found = int(sum(np.any(np.abs(flags - i) <= MATCH_SAMPLES) for i in at))
    false = int(sum(not np.any(np.abs(at - f) <= MATCH_SAMPLES) for f in flags))
    rate = None if case.real is None else float(case.real["rate_hz"])
    return {"written": int(at.size), "found": found, "false": false, "rate_hz": rate}


def measure(n: int, seed: int, jobs: int = 1, real: bool = True) -> dict:
    """``n`` draws of :func:`tests.independent_sim.draw_cases` (real-like or clean), each checked."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    rows = pool_map(check_case, sim.draw_cases(n, seed, real), jobs)
    out = {k: int(sum(r[k] for r in rows)) for k in ("written", "found", "false")}
    out["logs_missing_any"] = int(sum(r["found"] < r["written"] for r in rows))
    return {**out, "n": n, "seed": seed, "real": real, "logs": rows}


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: ``python -m tests.outlier_check --n 60 --seed 3010 [--clean]``."""
    ap = measurement_parser("Match the wheel-speed outliers the diagnosis sets aside to those written.", 60, 7)
    ap.add_argument("--clean", action="store_true", help="clean logs (no outliers written): false flags only")
    args = ap.parse_args(argv)
    from fricenv.utils import write_json
    from tests import outlier_check as mod  # noqa: PLW0406 -- by its import name, for the worker processes

    s = mod.measure(args.n, args.seed, args.jobs, not args.clean)
    print(f"wheel-speed outliers written {s['written']}, set aside {s['found']}, false flags {s['false']}; "
          f"logs with an outlier left in: {s['logs_missing_any']} of {args.n}")
    if args.json:
        write_json(args.json, s)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
