"""Wheel-speed spikes against the quarter-car estimators' outlier gate (:mod:`estimators.outliers`).

On each study log (the MHE paper's cases 1-4 for the EKF and the MHE, the EKF/RLS paper's stop for the EKF/RLS; with
``--stops stand-in`` the gap tool's stand-in stops instead, ABS and open-loop on dry, wet and snow, whose brake
releases the paper's stops do not have; with ``--stops independent`` the stops of :mod:`validation.independent_sim`,
its pedal press, threshold ABS and sine-modulated torque on dry, wet and snow) a share ``SPIKE_FRACTION`` of the
wheel speeds is multiplied by a spike factor; the run is compared with the clean run of the same log: the rms speed error after ``SETTLE_TIME``, the share of spiked samples marked ``Health.OUTLIER``
and the share of the other samples marked ``OUTLIER`` or ``REINITIALISED``. A spiked sample the factor moves by at
most ``SPIKE_MIN_MOVE`` times the log's wheel-speed noise std (a locked wheel's zero halved is still zero) is one the
noise itself could give: it counts in neither share (``within_noise``).

Command (tuning seeds 0-2; the test runs seeds 7-8)::

    python -m validation.estimator_spikes --seeds 0 1 2 [--estimators ekf mhe] [--stops paper|stand-in|independent]
        [--json PATH]
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from estimators import scenarios
from estimators.base import Health, run
from estimators.ekf import QuarterCarEKF
from estimators.ekf_rls import QuarterCarEkfRls
from estimators.mhe import RegularizedMHE
from estimators.outliers import DEFAULT_GATE
from estimators.registry import make_estimator
from fricenv.gap.quarter_car.simulate import DRIVERS, simulate_log
from fricenv.plants.sui_johansen import OMEGA_NOISE_STD, OMEGA_NOISE_VAR
from fricenv.plants.tire import ROADS
from validation import independent_sim as ind

__all__ = ["STUDY_ESTIMATORS", "StudyRow", "format_table", "main", "spike_indices", "spike_moves", "study",
           "study_logs"]

SPIKE_FACTORS = (0.5, 2.0, 5.0, 10.0)  # wheel speed multiplied by this on a spiked sample [-]
SPIKE_FRACTION = 0.01  # share of the samples spiked [-]
SPIKE_START = 11  # first sample that may be spiked: the filters (and the MHE's window) have a prior by then
# A spike moves its sample by more than this many wheel-speed noise std (white noise goes that far on 0.27 % of the
# samples); a smaller move is within the noise, and no test can tell it from the sample it replaced [-]
SPIKE_MIN_MOVE = 3.0
SETTLE_TIME = 0.5  # rms errors over t >= this, as the paper commands do [s]
MHE_STUDY_CASES = (1, 2, 3, 4)  # the MHE paper cases run by the EKF and the MHE
TARGET_RATIO = 1.5  # spiked rms speed error within 1.5x of the clean run
TARGET_HIT = 0.95  # OUTLIER marks >= 95 % of the spiked samples
TARGET_FALSE = 0.01  # < 1 % false marks


def spike_moves(omega: np.ndarray, factor: float, noise_std: float) -> np.ndarray:
    """Whether a spike of ``factor`` moves each wheel speed ``omega`` [rad/s] beyond the noise: by more than
    ``SPIKE_MIN_MOVE`` times the wheel-speed noise std ``noise_std`` [rad/s]."""
    return np.abs((factor - 1.0) * np.asarray(omega, dtype=float)) > SPIKE_MIN_MOVE * noise_std


@dataclass(frozen=True)
class StudyRow:
    """One estimator and spike size, pooled over seeds (and cases)."""

    estimator: str
    factor: float  # spike size [-]
    runs: int  # logs run (seeds x cases)
    rms_clean: float  # mean over runs of the clean run's rms speed error [m/s]
    rms_spiked: float  # mean over runs of the spiked run's rms speed error [m/s]
    ratio: float  # worst run's rms_spiked / rms_clean [-]
    hit_rate: float  # spiked samples marked OUTLIER / spiked samples [-]
    false_rate: float  # other samples marked OUTLIER or REINITIALISED / other samples [-]
    spikes: int  # spiked samples in all runs
    within_noise: int = 0  # samples drawn for a spike that it moves within the noise (SPIKE_MIN_MOVE), not counted

    @property
    def meets_target(self) -> bool:
        return self.ratio <= TARGET_RATIO and self.hit_rate >= TARGET_HIT and self.false_rate < TARGET_FALSE


def spike_indices(n: int, rng: np.random.Generator, fraction: float = SPIKE_FRACTION,
                  start: int = SPIKE_START) -> np.ndarray:
    """Sorted distinct random sample indices in [start, n): ``round(fraction n)`` of them, at least one."""
    count = max(1, round(fraction * n))
    return np.sort(rng.choice(np.arange(start, n), size=count, replace=False))


@dataclass(frozen=True)
class SimulatedStop:
    """A simulated stop as a study log: the log, its true speed and no estimated parameters."""

    log: Any  # fricenv.gap.quarter_car.simulate's log (t, omega, T_b, a_x)
    v: np.ndarray  # true speed [m/s]
    omega_noise_std: float  # the log's wheel-speed noise std [rad/s]
    estimated: tuple = ()


STOP_SOURCES = ("paper", "stand-in", "independent")
SIMULATED = ("stand-in", "independent")  # the sources of simulated stops, which the env's estimators read
ENV_ESTIMATORS = ("ekf-rls-env", "ekf-ax", "mhe-ax")  # the env's estimators the study builds
SIMULATED_ROADS = ("dry", "wet", "snow")


def study_logs(estimator: str, seed: int, stops: str = "paper") -> list:
    """Every study log of an estimator for one seed: :class:`SimulatedStop` rows on simulated stops, the papers'
    :class:`estimators.scenarios.PaperCase` rows otherwise (each with ``log``, ``v`` and ``estimated``)."""
    if stops == "stand-in":
        return [SimulatedStop(log, truth["v"], OMEGA_NOISE_STD) for driver in DRIVERS
                for road in SIMULATED_ROADS for log, truth in [simulate_log([], ROADS[road], driver, seed=seed)]]
    if stops == "independent":
        cases = [ind.study_case(driver, road, seed) for driver in ind.DRIVERS for road in SIMULATED_ROADS]
        return [SimulatedStop(*ind.study_log(case), ind.case_noise(case)["omega"]) for case in cases]
    if estimator.startswith("ekf-rls") or estimator.endswith("-ax"):  # the stop with a (noisy) a_x
        pc = scenarios.ekf_rls_scenario(noisy=True, seed=seed, omega_noise_var=OMEGA_NOISE_VAR)
        return [pc]
    return [scenarios.mhe_case(case, seed=seed) for case in MHE_STUDY_CASES]


def _factory(estimator: str, estimated: tuple[str, ...], gated: bool = True):
    opt = {"outlier_gate": DEFAULT_GATE if gated else None}
    makers = {"ekf": lambda: QuarterCarEKF(estimated=estimated, **opt),
              "mhe": lambda: RegularizedMHE(estimated=estimated, **opt), "ekf-rls": lambda: QuarterCarEkfRls(**opt),
              "ekf-rls-env": lambda: make_estimator("ekf-rls", **opt), "ekf-ax": lambda: make_estimator("ekf-ax", **opt),
              "mhe-ax": lambda: make_estimator("mhe-ax", **opt)}
    return makers[estimator]()


# ``ekf-rls-env``: the EKF/RLS as the braking env runs it (the registry's entry: its a_x loop and braking rules);
# ``ekf-ax``, ``mhe-ax``: the registry's EKF and MHE whose speed follows a_x, on the EKF/RLS paper's stop (the study
# log with a noisy a_x)
STUDY_ESTIMATORS = ("ekf", "ekf-rls", "mhe", "ekf-rls-env", "ekf-ax", "mhe-ax")


def _run_one(est, pc, omega: np.ndarray) -> tuple[float, np.ndarray]:
    log = {"t": pc.log.t, "omega": omega, "T_b": pc.log.T_b, "a_x": pc.log.a_x}
    out = run(est, log)
    settled = pc.log.t >= SETTLE_TIME
    return float(np.sqrt(np.mean((out["v"][settled] - pc.v[settled]) ** 2))), out["health"]


def study(estimator: str, seeds, factors=SPIKE_FACTORS, gated: bool = True, stops: str = "paper") -> list[StudyRow]:
    """Run one estimator over its study logs, clean and with spikes of every size (module docstring).

    :param estimator: one of :data:`STUDY_ESTIMATORS` (with simulated stops: of :data:`ENV_ESTIMATORS`).
    :param seeds: noise seeds of the logs (the spike places are drawn from (seed, log, factor)).
    :param factors: spike sizes.
    :param gated: False runs the estimators without the gate (the behaviour before it, for comparison).
    :param stops: ``paper`` (the papers' scenarios), ``stand-in`` (the gap tool's stand-in stops) or
        ``independent`` (the independent simulator's stops).
    """
    if estimator not in STUDY_ESTIMATORS:
        raise ValueError(f"estimator must be one of {', '.join(STUDY_ESTIMATORS)}, got {estimator!r}")
    if stops not in STOP_SOURCES:
        raise ValueError(f"stops must be one of {', '.join(STOP_SOURCES)}, got {stops!r}")
    if stops in SIMULATED and estimator not in ENV_ESTIMATORS:
        raise ValueError(f"--stops {stops} runs the env's estimators ({', '.join(ENV_ESTIMATORS)}), "
                         f"got {estimator!r}")
    cache: dict = {}
    acc = {f: {"clean": [], "spiked": [], "ratio": [], "hits": 0, "spikes": 0, "false": 0, "other": 0, "within": 0}
           for f in factors}
    for seed in seeds:
        for j, pc in enumerate(study_logs(estimator, seed, stops)):
            if pc.estimated not in cache:
                cache[pc.estimated] = _factory(estimator, pc.estimated, gated)
            est = cache[pc.estimated]
            rms_clean, _ = _run_one(est, pc, pc.log.omega)
            for k, factor in enumerate(factors):
                idx = spike_indices(len(pc.log.t), np.random.default_rng([int(seed), j, k]))
                omega = pc.log.omega.copy()
                omega[idx] *= factor
                rms, health = _run_one(est, pc, omega)
                moved = spike_moves(pc.log.omega[idx], factor,
                                    pc.omega_noise_std if isinstance(pc, SimulatedStop) else OMEGA_NOISE_STD)
                bad = np.zeros(len(omega), dtype=bool)
                bad[idx[moved]] = True
                counted = np.ones(len(omega), dtype=bool)
                counted[idx[~moved]] = False
                a = acc[factor]
                a["clean"].append(rms_clean)
                a["spiked"].append(rms)
                a["ratio"].append(rms / rms_clean)
                a["hits"] += int(np.sum(health[bad] == Health.OUTLIER))
                a["spikes"] += int(bad.sum())
                other = counted & ~bad
                a["false"] += int(np.sum(np.isin(health[other], (Health.OUTLIER, Health.REINITIALISED))))
                a["other"] += int(other.sum())
                a["within"] += int(np.sum(~moved))
    return [StudyRow(estimator, float(f), len(a["clean"]), float(np.mean(a["clean"])), float(np.mean(a["spiked"])),
                     float(np.max(a["ratio"])), a["hits"] / max(a["spikes"], 1), a["false"] / a["other"], a["spikes"],
                     a["within"])
            for f, a in acc.items()]


def format_table(rows: list[StudyRow]) -> str:
    """The study as a text table."""
    header = (f"{'estimator':<9} {'spike':>6} {'runs':>5} {'rms clean':>10} {'rms spiked':>11} {'worst ratio':>12} "
              f"{'hit rate':>9} {'false rate':>11} {'spikes':>7} {'in noise':>9} {'target':>7}")
    lines = [header]
    for r in rows:
        lines.append(f"{r.estimator:<9} {r.factor:>6g} {r.runs:>5d} {r.rms_clean:>10.4f} {r.rms_spiked:>11.4f} "
                     f"{r.ratio:>12.3f} {r.hit_rate:>9.3f} {r.false_rate:>11.5f} {r.spikes:>7d} {r.within_noise:>9d} "
                     f"{'met' if r.meets_target else 'MISSED':>7}")
    return "\n".join(lines)


def main(argv=None) -> int:
    """``python -m validation.estimator_spikes [--seeds ...] [--factors ...] [--estimators ...] [--json PATH]``."""
    ap = argparse.ArgumentParser(prog="python -m validation.estimator_spikes",
                                 description="Wheel-speed spikes against the estimators' outlier gate.")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--factors", type=float, nargs="+", default=list(SPIKE_FACTORS))
    ap.add_argument("--estimators", nargs="+", choices=STUDY_ESTIMATORS, default=list(STUDY_ESTIMATORS))
    ap.add_argument("--json", default=None, help="write the rows to this JSON file")
    ap.add_argument("--no-gate", action="store_true", help="run without the outlier gate (for comparison)")
    ap.add_argument("--stops", choices=STOP_SOURCES, default="paper",
                    help="study logs: the papers' scenarios, the gap tool's stand-in stops (ABS and open-loop, dry, "
                         "wet, snow) or the independent simulator's (pedal, threshold ABS, sine; dry, wet, snow); "
                         f"simulated stops with the env's estimators {', '.join(ENV_ESTIMATORS)}")
    args = ap.parse_args(argv)
    refused = [name for name in args.estimators if args.stops in SIMULATED and name not in ENV_ESTIMATORS]
    if refused:  # before any stop runs
        ap.error(f"--stops {args.stops} runs the env's estimators: --estimators {' '.join(ENV_ESTIMATORS)}")
    rows = [row for name in args.estimators
            for row in study(name, args.seeds, args.factors, not args.no_gate, args.stops)]
    print(format_table(rows))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"seeds": args.seeds, "gated": not args.no_gate, "stops": args.stops,
                       "rows": [{**asdict(r), "meets_target": r.meets_target} for r in rows]}, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
