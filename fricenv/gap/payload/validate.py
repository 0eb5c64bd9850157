"""Validation of the payload gap diagnosis on withheld effects (issue 6, items 5 and 6).

Random payload logs: each payload library effect at a realistic size, logs with no effect, and logs with a
physically real effect outside the library: viscous damping of the payload's motion (a payload sliding on a table or
moving through air, ``m X'' = R w - b_lin X'``, ``I_G theta'' = ... - b_rot theta'``). Mass-property errors (m, I_G,
rho) and a constant vision scale or rotation are NOT usable as out-of-library effects: they map the generalised force
by a constant matrix that commutes with the rotation, so they are exactly a ``calibration_error`` (``S' = G^-1 D G S``
does not depend on theta). Logs use the paper's or a random multi-sine wrench, 1 or 2 ms sampling, paper noise.
Each log is written, re-read and diagnosed blind.
"""

from __future__ import annotations

import os
import tempfile
import time
import warnings
from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import dataclass, fields

import numpy as np
from scipy.integrate import solve_ivp

from fricenv import progress
from fricenv.effects.payload import PAYLOAD_EFFECTS, make_payload_effect, simulate_payload_with_effects
from fricenv.gap.core.pool import map_tasks
from fricenv.gap.payload.diagnose import PayloadDiagnoseConfig, diagnose_payload
from fricenv.logs import PayloadLog, read_log, write_log
from fricenv.plants import payload as pl
from fricenv.utils import as_generator

__all__ = ["PAYLOAD_CATEGORIES", "PayloadCase", "draw_payload_case", "draw_payload_cases", "format_payload_summary", "run_payload_case",
           "score_payload_case", "simulate_payload_case", "summarize_payload", "validate_payload"]

NONE, OUT = "none", "out_of_library"
PAYLOAD_CATEGORIES = tuple(PAYLOAD_EFFECTS) + (NONE, OUT)
DURATION = 8.0  # log length [s]
DTS = (1e-3, 2e-3)  # sample times drawn [s]
PARAM_TOLERANCE = 0.15  # relative parameter error counted as right [-]
DAMPING_LIN = (0.3, 0.8)  # out-of-library viscous damping, translation [N s/m]
DAMPING_ROT = (0.05, 0.15)  # rotation [N m s/rad]
ODE_TOL = 1e-9  # relative tolerance of the damped reference integration


@dataclass(frozen=True)
class PayloadCase:
    """One validation log's recipe."""

    category: str
    effects: tuple  # payload effect specs
    damping: tuple[float, float] | None  # (b_lin, b_rot) of the out-of-library effect
    wrench: str  # "paper" or "random"
    dt: float
    seed: int


def _random_effect(category: str, rng: np.random.Generator):
    u = rng.uniform
    if category == "wrench_offset":
        amp = pl.PAPER_WRENCH_AMPLITUDE
        return make_payload_effect(category, **{k: float(rng.choice([-1, 1]) * u(0.04, 0.1) * a)
                                                for k, a in zip(("M0", "fx0", "fy0"), amp)})
    if category == "calibration_error":
        return make_payload_effect(category, S=pl.PAPER_S * (1 + rng.choice([-1, 1], (3, 3)) * u(0.04, 0.12, (3, 3))))
    if category == "calibration_drift":
        return make_payload_effect(category, rate=float(rng.choice([-1, 1]) * u(0.008, 0.02)))
    if category == "vision_delay":
        return make_payload_effect(category, delay=float(u(0.01, 0.08)))
    raise ValueError(f"unknown payload category {category!r}; valid: {', '.join(PAYLOAD_CATEGORIES)}")


def draw_payload_case(category: str, rng: np.random.Generator) -> PayloadCase:
    """A random case of the given category."""
    if category not in PAYLOAD_CATEGORIES:
        raise ValueError(f"unknown payload category {category!r}; valid: {', '.join(PAYLOAD_CATEGORIES)}")
    effects = (_random_effect(category, rng),) if category in PAYLOAD_EFFECTS else ()
    damping = (float(rng.uniform(*DAMPING_LIN)), float(rng.uniform(*DAMPING_ROT))) if category == OUT else None
    return PayloadCase(category, effects, damping, "paper" if rng.random() < 0.5 else "random",
                       float(DTS[int(rng.integers(len(DTS)))]), int(rng.integers(2**31)))


def draw_payload_cases(n: int, seed=None) -> list[PayloadCase]:
    """``n`` cases, the categories in turn, shuffled."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    rng = as_generator(seed)
    cats = [PAYLOAD_CATEGORIES[i % len(PAYLOAD_CATEGORIES)] for i in range(n)]
    rng.shuffle(cats)
    return [draw_payload_case(c, rng) for c in cats]


def _damped_log(case: PayloadCase, rng: np.random.Generator, wrench) -> PayloadLog:
    """The out-of-library stand-in: eq. (1) plus viscous damping, integrated by an adaptive RK (DOP853)."""
    p = pl.PAPER_PARAMS
    b_lin, b_rot = case.damping

    def f(t, x):
        acc = pl.accelerations(x[0], wrench(t), p)
        acc = acc - np.array([b_rot / p.I_G, b_lin / p.m, b_lin / p.m]) * x[3:]
        return np.concatenate([x[3:], acc])

    t = np.arange(round(DURATION / case.dt) + 1) * case.dt
    sol = solve_ivp(f, (0.0, t[-1]), np.zeros(6), method="DOP853", t_eval=t, rtol=ODE_TOL, atol=ODE_TOL)
    w_hat = pl.sensor_reading(wrench(t), np.linalg.inv(pl.PAPER_S), pl.PAPER_NOISE, rng)
    pose = pl.vision(sol.y.T, pl.PAPER_NOISE, rng)
    return PayloadLog(t=t, M=w_hat[:, 0], f_x=w_hat[:, 1], f_y=w_hat[:, 2], theta=pose[:, 0], X=pose[:, 1],
                      Y=pose[:, 2])


def _errors(category: str, truth: dict, fitted: dict) -> tuple[float, dict]:
    if category == "calibration_error":
        S_t, S_f = np.asarray(truth["S"]), np.asarray(fitted["S"])
        # the deviation from the known S is what the log shows: error relative to it
        dev = np.linalg.norm(S_f - S_t) / np.linalg.norm(S_t - pl.PAPER_S)
        return float(dev), {"S_rel_to_deviation": float(dev),
                            "E_eq16": float(pl.calibration_error(S_f, S_t))}
    errs = {k: abs(fitted[k] - v) / abs(v) for k, v in truth.items() if k in fitted}
    return float(max(errs.values())), errs


def simulate_payload_case(case: PayloadCase) -> tuple[PayloadLog, dict]:
    """The case's log (as simulated, before any file) and its true effect parameters."""
    rng = as_generator(case.seed)
    wrench = pl.multisine_wrench(case.wrench, rng)
    if case.damping is not None:
        log = _damped_log(case, rng, wrench)
    else:
        log, _ = simulate_payload_with_effects(list(case.effects), DURATION, case.dt, wrench=wrench, rng=rng)
    truth = {f.name: getattr(case.effects[0], f.name) for f in fields(case.effects[0])} if case.effects else {}
    if "S" in truth:
        truth["S"] = np.asarray(truth["S"]).tolist()
    return log, truth


def score_payload_case(case: PayloadCase, truth: dict, read: Callable[[str], PayloadLog],
                       cfg: PayloadDiagnoseConfig | None = None) -> dict:
    """Read a case's log with ``read(tmp_dir)`` (it writes the log there and reads it back), diagnose it blind and
    score it: the result row of :func:`validate_payload` (a log the reader rejects counts as wrong)."""
    cfg = cfg or PayloadDiagnoseConfig()
    expected = {NONE: "none", OUT: "unexplained"}.get(case.category, case.category)
    out = {"category": case.category, "expected": expected, "true_params": truth, "wrench": case.wrench,
           "dt": case.dt, "seed": case.seed, "damping": case.damping}
    try:
        with tempfile.TemporaryDirectory() as tmp:
            log = read(tmp)
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            dg = diagnose_payload(log, cfg=cfg)
        out["seconds"] = time.perf_counter() - t0
    except ValueError as exc:  # a log the reader rejects counts as a wrong verdict
        out.update(verdict="error", error=str(exc), right=False, seconds=0.0)
        return out
    out.update(verdict=dg.verdict, right=dg.verdict == expected, gap_before=dg.gap_before, gap_after=dg.gap_after,
               params=dg.params, candidates=[c.effect for c in dg.candidates[:3]],
               not_testable=sorted(dg.where.get("not_testable", {})))
    if case.category in PAYLOAD_EFFECTS:
        out["ratio"] = dg.gap_after / dg.gap_before if dg.gap_before > 0 else float("nan")
        if out["right"]:
            out["param_error"], out["param_errors"] = _errors(case.category, truth, dg.params)
    return out


def run_payload_case(case: PayloadCase, cfg: PayloadDiagnoseConfig | None = None) -> dict:
    """Simulate, write, re-read and diagnose one case blind; score it."""
    log, truth = simulate_payload_case(case)

    def read(tmp: str) -> PayloadLog:
        path = os.path.join(tmp, "log.csv")
        write_log(path, log, comments=("validation log",))
        return read_log(path, "payload")

    return score_payload_case(case, truth, read, cfg)


def validate_payload(n: int, seed=None, show_progress: bool = True,
                     cfg: PayloadDiagnoseConfig | None = None) -> dict:
    """Draw ``n`` payload logs (categories in turn, shuffled), diagnose each blind, summarise."""
    cases = draw_payload_cases(n, seed)
    t0 = time.perf_counter()
    with nullcontext() if show_progress else progress.use_sink(None):
        results = map_tasks(run_payload_case, [(c, cfg) for c in cases], 1, "validate payload")
    s = summarize_payload(results)
    s.update(n=n, seed=seed, wall_seconds=time.perf_counter() - t0)
    return s


def summarize_payload(results: list[dict]) -> dict:
    """The headline figures and the confusion matrix of payload result rows (:func:`score_payload_case`)."""
    labels = list(PAYLOAD_EFFECTS) + ["none", "unexplained", "error"]
    conf = {c: {lab: 0 for lab in labels} for c in PAYLOAD_CATEGORIES}
    for r in results:
        conf[r["category"]][r["verdict"]] += 1
    ratios = [r["ratio"] for r in results if "ratio" in r and np.isfinite(r["ratio"])]
    perr = np.array([r["param_error"] for r in results if "param_error" in r], dtype=float)
    secs = np.array([r["seconds"] for r in results])
    return {
        "plant": "payload", "n": len(results),
        "accuracy": float(np.mean([r["right"] for r in results])),
        "accuracy_by_category": {c: float(np.mean([r["right"] for r in results if r["category"] == c]))
                                 for c in PAYLOAD_CATEGORIES if any(r["category"] == c for r in results)},
        "median_gap_ratio_effect_logs": float(np.median(ratios)) if ratios else float("nan"),
        "param_within_15pct": float(np.mean(perr <= PARAM_TOLERANCE)) if perr.size else float("nan"),
        "param_error_median": float(np.median(perr)) if perr.size else float("nan"),
        "param_error_max": float(np.max(perr)) if perr.size else float("nan"),
        "confusion": conf,
        "seconds_per_log": {"median": float(np.median(secs)), "max": float(np.max(secs))},
        "logs": results,
    }


def format_payload_summary(s: dict) -> str:
    """A plain-text confusion matrix and the headline figures."""
    labels = list(PAYLOAD_EFFECTS) + ["none", "unexplained", "error"]
    lines = ["confusion matrix (rows: truth, columns: verdict)",
             f"{'':>18}" + "".join(f"{lab[:11]:>12}" for lab in labels)]
    for cat, row in s["confusion"].items():
        if sum(row.values()):
            lines.append(f"{cat:>18}" + "".join(f"{row.get(lab, 0):>12d}" for lab in labels))
    lines += [f"right verdicts: {s['accuracy'] * 100:.1f} % of {s['n']} logs",
              f"median gap_after/gap_before on effect logs: {s['median_gap_ratio_effect_logs']:.3f}",
              (f"fitted parameter within 15 % (right verdicts): {s['param_within_15pct'] * 100:.1f} % "
               f"(median error {s['param_error_median']:.3f}, max {s['param_error_max']:.3f}; calibration_error: "
               f"||S_fit - S|| / ||S - S_known||)"),
              (f"seconds per diagnosis: median {s['seconds_per_log']['median']:.2f}, "
               f"max {s['seconds_per_log']['max']:.2f}")]
    return "\n".join(lines)
