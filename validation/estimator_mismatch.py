"""The quarter-car estimators on plants with the effect grid's effects: do they keep the speed?

For each estimator (registry name), driver, road and seed, a simulator writes a stop on the nominal plant and one
per effect of :data:`fricenv.effects.grid.EFFECT_GRID` at the chosen size (``mu_change`` switches at the nominal
stop's mid time, :func:`fricenv.effects.grid.grid_effect`); the estimator runs on the logged wheel speed and
commanded torque (and ``a_x`` if it reads it). Figures per run: rms and largest speed error after ``SETTLE_TIME``
(of the log, which starts with a free roll), and the share of samples flagged ``OUTLIER`` or ``REINITIALISED``
(the logs hold no spike, so every flag is false), the first half second included.

Sources (``--source``):

- ``stand-in``: the gap tool's stand-in (:func:`fricenv.gap.quarter_car.simulate.simulate_log`), drivers ``abs``
  and ``open-loop``;
- ``independent``: :mod:`validation.independent_sim`, written apart from fricenv's plant and effects, with its own
  drivers (``pedal``, ``bosch-abs``, ``sine``), free roll, initial speed and ``a_x`` noise drawn from the seed; the
  same grid cell's parameters on its plant (its effect implementations and its RK4).

Targets: rms <= ``RMS_FACTOR`` x the same estimator's nominal rms (same source, road, driver, seed) +
``RMS_MARGIN``; largest error <= ``MAX_ERROR``; flags <= ``MAX_FLAGS``.

Command::

    python -m validation.estimator_mismatch [--source stand-in|independent] [--estimators ekf mhe ekf-rls]
        [--roads dry wet snow] [--drivers ...] [--seeds 0 1 2] [--size high] [--effects brake_lag ...] [--jobs 2]
        [--json PATH]
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, replace

import numpy as np

from agents.robustness import MAX_ERROR, MAX_FLAGS, RMS_FACTOR, RMS_MARGIN  # the targets, in one place
from estimators.base import Health, run
from estimators.registry import make_estimator
from fricenv.effects.grid import EFFECT_GRID, GRID_SIZES, grid_effect
from fricenv.effects.quarter_car import make_effect
from fricenv.gap.quarter_car.simulate import DRIVERS, simulate_log
from fricenv.plants.quarter_car import PAPER_PARAMS
from fricenv.plants.tire import ROADS
from validation import independent_sim as ind

__all__ = ["MismatchRow", "format_table", "main", "measure", "run_cell"]

SETTLE_TIME = 0.5  # errors over t >= this [s]
NOMINAL = "nominal"
SOURCE_DRIVERS = {"stand-in": DRIVERS, "independent": ind.DRIVERS}  # source -> its drivers


@dataclass(frozen=True)
class MismatchRow:
    """One estimator on one log."""

    estimator: str
    driver: str
    road: str
    seed: int
    effect: str  # "nominal" or the grid effect
    rms: float  # rms speed error after SETTLE_TIME [m/s]
    worst: float  # largest |speed error| after SETTLE_TIME [m/s]
    flags: float  # share of samples flagged OUTLIER or REINITIALISED [-]
    reinits: int  # samples flagged REINITIALISED


def _errors(name: str, log, v_true: np.ndarray) -> tuple[float, float, float, int]:
    cols = {"t": log.t, "omega": log.omega, "T_b": log.T_b, "a_x": log.a_x}
    out = run(make_estimator(name), cols)
    settled = log.t >= SETTLE_TIME
    err = out["v"][settled] - v_true[settled]
    flagged = np.isin(out["health"], (Health.OUTLIER, Health.REINITIALISED))
    return (float(np.sqrt(np.mean(err**2))), float(np.max(np.abs(err))), float(np.mean(flagged)),
            int(np.sum(out["health"] == Health.REINITIALISED)))


def _stand_in_logs(driver: str, road_name: str, seed: int, size: str, effects) -> list[tuple[str, object, np.ndarray]]:
    """(effect or nominal, log, true speed) of the stand-in's nominal stop and its stop with each effect."""
    road = ROADS[road_name]
    log, truth = simulate_log([], road, driver, seed=seed)
    out = [(NOMINAL, log, truth["v"])]
    for effect in effects:
        cell = grid_effect(effect, size, road_name, truth["v0"], PAPER_PARAMS)
        elog, etruth = simulate_log([make_effect(cell["effect"], **cell["params"])], road, driver, seed=seed)
        out.append((effect, elog, etruth["v"]))
    return out


def _independent_logs(driver: str, road_name: str, seed: int, size: str,
                      effects) -> list[tuple[str, object, np.ndarray]]:
    """The same from :mod:`validation.independent_sim`: one drawn case (initial speed, free roll, noise) per seed,
    the nominal plant and each grid cell on it with the driver's and the noise's random stream unchanged."""
    case = ind.study_case(driver, road_name, seed)
    out = [(NOMINAL, *ind.study_log(case))]
    for effect in effects:
        cell = grid_effect(effect, size, road_name, case.v0, PAPER_PARAMS)
        on = replace(case, category=effect, effects=(ind.Effect(effect, dict(cell["params"])),))
        out.append((effect, *ind.study_log(on)))
    return out


def run_cell(task: tuple) -> list[MismatchRow]:
    """Every estimator on the nominal log and every effect's log of one (source, driver, road, seed).

    :param task: (estimators, driver, road, seed, size, effects, source).
    """
    names, driver, road_name, seed, size, effects, source = task
    logs = (_stand_in_logs if source == "stand-in" else _independent_logs)(driver, road_name, seed, size, effects)
    return [MismatchRow(n, driver, road_name, seed, effect, *_errors(n, log, v)) for effect, log, v in logs
            for n in names]


def measure(estimators, drivers, roads, seeds, size: str = "high", effects=tuple(EFFECT_GRID),
            jobs: int = 1, source: str = "stand-in") -> list[MismatchRow]:
    """All cells (see :func:`run_cell`), on ``jobs`` processes.

    :param source: ``stand-in`` or ``independent`` (module docstring); ``drivers`` must be that source's.
    """
    if source not in SOURCE_DRIVERS:
        raise ValueError(f"source must be one of {', '.join(SOURCE_DRIVERS)}, got {source!r}")
    bad = [d for d in drivers if d not in SOURCE_DRIVERS[source]]
    if bad:
        raise ValueError(f"driver(s) {', '.join(bad)} not of the {source} source; its drivers: "
                         f"{', '.join(SOURCE_DRIVERS[source])}")
    tasks = [(tuple(estimators), d, r, int(s), size, tuple(effects), source)
             for d in drivers for r in roads for s in seeds]
    if jobs <= 1:
        return [row for t in tasks for row in run_cell(t)]
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        return [row for rows in pool.map(run_cell, tasks) for row in rows]


def verdicts(rows: list[MismatchRow]) -> list[dict]:
    """Per row: the targets against the same estimator's nominal run (same driver, road, seed)."""
    nominal = {(r.estimator, r.driver, r.road, r.seed): r.rms for r in rows if r.effect == NOMINAL}
    out = []
    for r in rows:
        bound = RMS_FACTOR * nominal[(r.estimator, r.driver, r.road, r.seed)] + RMS_MARGIN
        out.append({**asdict(r), "rms_bound": bound, "rms_ok": r.rms <= bound or r.effect == NOMINAL,
                    "worst_ok": r.worst <= MAX_ERROR, "flags_ok": r.flags <= MAX_FLAGS})
    return out


def format_table(rows: list[MismatchRow]) -> str:
    """Per estimator and effect: worst rms over the runs against its bound, worst error, worst flag share, misses."""
    checked = verdicts(rows)
    header = (f"{'estimator':<9} {'effect':<18} {'runs':>4} {'rms mean':>9} {'rms max':>8} {'worst':>7} "
              f"{'flags max':>9} {'reinits':>7} {'missed':>6}")
    lines = [header]
    keys = sorted({(c["estimator"], c["effect"]) for c in checked}, key=lambda k: (k[0], k[1] != NOMINAL, k[1]))
    for est, eff in keys:
        cs = [c for c in checked if c["estimator"] == est and c["effect"] == eff]
        missed = sum(not (c["rms_ok"] and c["worst_ok"] and c["flags_ok"]) for c in cs)
        lines.append(f"{est:<9} {eff:<18} {len(cs):>4d} {np.mean([c['rms'] for c in cs]):>9.3f} "
                     f"{max(c['rms'] for c in cs):>8.3f} {max(c['worst'] for c in cs):>7.2f} "
                     f"{max(c['flags'] for c in cs):>9.4f} {sum(c['reinits'] for c in cs):>7d} {missed:>6d}")
    return "\n".join(lines)


def main(argv=None) -> int:
    """``python -m validation.estimator_mismatch`` (module docstring)."""
    ap = argparse.ArgumentParser(prog="python -m validation.estimator_mismatch",
                                 description="Quarter-car estimators on plants with the effect grid's effects.")
    ap.add_argument("--estimators", nargs="+", default=["ekf", "mhe", "ekf-rls"])
    ap.add_argument("--source", choices=tuple(SOURCE_DRIVERS), default="stand-in")
    ap.add_argument("--drivers", nargs="+", choices=sorted({d for ds in SOURCE_DRIVERS.values() for d in ds}),
                    default=None, help="the source's drivers (default: all of them)")
    ap.add_argument("--roads", nargs="+", choices=("dry", "wet", "snow"), default=["dry", "wet", "snow"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--size", choices=GRID_SIZES, default="high")
    ap.add_argument("--effects", nargs="+", choices=tuple(EFFECT_GRID), default=list(EFFECT_GRID))
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--json", default=None, help="write every run and its verdicts to this JSON file")
    args = ap.parse_args(argv)
    drivers = args.drivers or list(SOURCE_DRIVERS[args.source])
    try:
        rows = measure(args.estimators, drivers, args.roads, args.seeds, args.size, args.effects, args.jobs,
                       args.source)
    except ValueError as exc:  # a driver of the other source: refused before any stop runs
        ap.error(f"--drivers: {exc}")
    print(format_table(rows))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"args": vars(args), "rows": verdicts(rows)}, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
