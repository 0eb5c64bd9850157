"""The payload suites scored against what the data show, from three sources:

- ``stand_in``: the library's own real stand-in (:mod:`fricenv.gap.payload.validate`: 1-2 ms, 8 s);
- ``independent``: :mod:`validation.payload_sim`, written from the paper alone (10 ms, 10 s; the force-moment
  reading sampled at the stamp or averaged over the sample, stamps from 0 or from an epoch);
- ``real_like``: the stand-in exported through a rig's acquisition (:mod:`validation.real_payload`).

Each log is diagnosed blind and scored in three numbers (docs/validation.md): the share of logs whose data show the
answer (:mod:`validation.payload_oracle`; a nominal log always counts), the right verdicts on those logs, and the
share of all logs with a named effect that is not in the log.

Measurement command::

    python -m validation.payload_suite --source independent --n 60 --seed S [--only none] [--jobs 2] [--json P]
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
import warnings
from collections.abc import Sequence

import numpy as np

from validation import payload_sim as ps
from validation.measure_cli import measurement_parser, pool_map

__all__ = ["CATEGORIES", "SOURCES", "draw_independent", "measure", "score_rows"]

NONE, OUT = "none", "out_of_library"
EFFECTS = ("wrench_offset", "calibration_error", "calibration_drift", "vision_delay")
CATEGORIES = EFFECTS + (NONE, OUT)
DELAY_TOL = (0.15, 0.005)  # a vision delay is read right within 15 % or 5 ms, whichever is larger
N_PARAMS = {"wrench_offset": 3, "calibration_error": 9, "calibration_drift": 1, "vision_delay": 1, OUT: 2, NONE: 0}
EPOCH = 1.7e9  # stamps of an epoch-stamped log start here [s]
SOURCES = ("stand_in", "independent", "real_like")


# ----------------------------------------------------------------------------------------------- independent source
def draw_independent(category: str, rng: np.random.Generator) -> tuple[ps.PayloadRecipe, dict]:
    """A recipe of :mod:`validation.payload_sim` for the category, and its truth for the oracle."""
    exc = ps.paper_excitation() if rng.random() < 0.5 else ps.random_excitation(rng)
    kw: dict = {"excitation": exc, "ft_sample": ps.FT_SAMPLING[int(rng.integers(2))],
                "t0": EPOCH + float(rng.uniform(0, 86400)) if rng.random() < 0.5 else 0.0}
    truth: dict = {}
    if category == "wrench_offset":
        amp = np.array([1.5, 1.5, 2.6])
        kw["offset"] = tuple(float(v) for v in rng.choice([-1, 1], 3) * rng.uniform(0.04, 0.1, 3) * amp)
        truth["offset"] = kw["offset"]
    elif category == "calibration_error":
        S = np.asarray(ps.S_PAPER) * (1 + rng.choice([-1, 1], (3, 3)) * rng.uniform(0.04, 0.12, (3, 3)))
        kw["S_true"] = tuple(map(tuple, S))
        truth["S"] = S.tolist()
    elif category == "calibration_drift":
        kw["rate"] = float(rng.choice([-1, 1]) * rng.uniform(0.008, 0.02))
        truth["rate"] = kw["rate"]
    elif category == "vision_delay":
        kw["delay"] = float(rng.uniform(0.01, 0.08))
        truth["delay"] = kw["delay"]
    elif category == OUT:
        kw["damping"] = (float(rng.uniform(0.3, 0.8)), float(rng.uniform(0.05, 0.15)))
    elif category != NONE:
        raise ValueError(f"unknown category {category!r}; valid: {', '.join(CATEGORIES)}")
    return ps.PayloadRecipe(**kw), truth


def _independent_row(args: tuple) -> dict:
    category, seed = args
    rng = np.random.default_rng(seed)
    recipe, truth = draw_independent(category, rng)
    cols = ps.simulate(recipe, rng)
    oracle = dict(truth)
    lag = 0.5 * recipe.dt if recipe.ft_sample == "mean" else 0.0
    oracle["shift"] = truth.get("delay", 0.0) - lag
    if recipe.damping != (0.0, 0.0):
        t = cols["t"] - recipe.t0
        v = ps.states_at(t, recipe.excitation, recipe.damping)[:, 3:]
        oracle["damping_force"] = v * np.array([recipe.damping[1], recipe.damping[0], recipe.damping[0]])
    raw = ps.true_noise(recipe)

    def read(tmp: str):
        from fricenv.logs import read_log

        path = os.path.join(tmp, "log.csv")
        ps.write_csv(path, cols)
        return read_log(path, "payload")

    row = diagnose_row(category, truth, oracle, raw, read)
    row.update(seed=seed, ft_sample=recipe.ft_sample, epoch=recipe.t0 > 0)
    return row


# ----------------------------------------------------------------------------------------------- stand-in and rig
def _stand_in_truth(case) -> tuple[dict, dict]:
    """The truth of a :class:`fricenv.gap.payload.validate.PayloadCase` for scoring and for the oracle."""
    from fricenv.gap.payload.validate import simulate_payload_case

    _, truth = simulate_payload_case(case)
    oracle = {}
    if case.category == "wrench_offset":
        oracle["offset"] = (truth["M0"], truth["fx0"], truth["fy0"])
    elif case.category == "calibration_error":
        oracle["S"] = truth["S"]
    elif case.category == "calibration_drift":
        oracle["rate"] = truth["rate"]
    elif case.category == "vision_delay":
        oracle["delay"] = oracle["shift"] = truth["delay"]
    return truth, oracle


def _damping_force(case, t: np.ndarray) -> np.ndarray:
    """The stand-in's out-of-library viscous force on its true motion at times ``t`` (its own integration again)."""
    from scipy.integrate import solve_ivp

    from fricenv.plants import payload as pl
    from fricenv.utils import as_generator

    wrench = pl.multisine_wrench(case.wrench, as_generator(case.seed))
    b_lin, b_rot = case.damping
    p = pl.PAPER_PARAMS
    damp = np.array([b_rot / p.I_G, b_lin / p.m, b_lin / p.m])

    def f(tt, x):
        return np.concatenate([x[3:], pl.accelerations(x[0], wrench(tt), p) - damp * x[3:]])

    sol = solve_ivp(f, (0.0, float(t[-1])), np.zeros(6), method="DOP853", t_eval=t, rtol=1e-9, atol=1e-9)
    return sol.y[3:].T * np.array([b_rot, b_lin, b_lin])


def _paper_raw(wrench_scale: float = 1.0, pose_scale: float = 1.0) -> dict:
    from fricenv.plants import payload as pl

    n = pl.PAPER_NOISE
    w = n.wrench_std * wrench_scale
    return {"M": float(w[0]), "f_x": float(w[1]), "f_y": float(w[2]), "theta": n.theta_std * pose_scale,
            "X": n.position_std * pose_scale, "Y": n.position_std * pose_scale}


def _stand_in_row(case) -> dict:
    from fricenv.gap.payload.validate import simulate_payload_case
    from fricenv.logs import read_log, write_log

    log, _ = simulate_payload_case(case)
    truth, oracle = _stand_in_truth(case)
    if case.damping is not None:
        oracle["damping_force"] = _damping_force(case, np.asarray(log.t, dtype=float))

    def read(tmp: str):
        path = os.path.join(tmp, "log.csv")
        write_log(path, log)
        return read_log(path, "payload")

    row = diagnose_row(case.category, truth, oracle, _paper_raw(), read)
    row.update(seed=case.seed, dt=case.dt)
    return row


def _real_like_row(args: tuple) -> dict:
    from fricenv.gap.payload.validate import simulate_payload_case
    from fricenv.logs import read_log
    from validation.real_artifacts import PayloadArtifacts, real_like_payload, write_export
    from validation.real_payload import SIM_DT

    case, rate = args
    case = dataclasses.replace(case, dt=SIM_DT)
    log, _ = simulate_payload_case(case)
    truth, oracle = _stand_in_truth(case)
    clean = {n: np.asarray(getattr(log, n), dtype=float) for n in ("t", "M", "f_x", "f_y", "theta", "X", "Y")}
    spec = PayloadArtifacts(rate_hz=rate)
    export = real_like_payload(clean, np.random.default_rng(case.seed + 1), spec)
    # the F/T's Butterworth lag at low frequency: sqrt(2) / (2 pi fc) for order 2 (its mean group delay there)
    lag = np.sqrt(2.0) / (2 * np.pi * spec.ft_cutoff_hz) if spec.ft_cutoff_hz else 0.0
    oracle["shift"] = oracle.get("delay", 0.0) - lag
    if case.damping is not None:
        oracle["_damping_case"] = case
    raw = _paper_raw(np.sqrt(rate * SIM_DT), np.sqrt(rate / spec.camera_hz))

    def read(tmp: str):
        csv_path, map_path = write_export(os.path.join(tmp, "rig"), export)
        return read_log(csv_path, "payload", column_map=map_path)

    row = diagnose_row(case.category, truth, oracle, raw, read)
    row.update(seed=case.seed, rate_hz=rate)
    return row


# ----------------------------------------------------------------------------------------------- diagnosis and score
def diagnose_row(category: str, truth: dict, oracle: dict, true_raw: dict, read) -> dict:
    """Read a log with ``read(tmp_dir)``, diagnose it blind, score it and ask the oracle whether its data show the
    answer. A log the reader rejects is a wrong verdict."""
    from fricenv.gap.payload.diagnose import diagnose_payload
    from validation.payload_oracle import payload_shown

    expected = {NONE: "none", OUT: "unexplained"}.get(category, category)
    row = {"category": category, "expected": expected, "truth": {k: v for k, v in truth.items()}}
    try:
        with tempfile.TemporaryDirectory() as tmp:
            log = read(tmp)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            dg = diagnose_payload(log)
    except ValueError as exc:
        row.update(verdict="error", error=str(exc), right=False, named=[], wrong_named=False, shown=True)
        return row
    named = [dg.verdict] if dg.verdict in EFFECTS else []
    row.update(verdict=dg.verdict, right=dg.verdict == expected, named=named,
               wrong_named=any(e != category for e in named), gap_before=dg.gap_before, gap_after=dg.gap_after,
               params={k: v for k, v in dg.params.items()}, time_base=dg.where.get("time_base"))
    if category == "vision_delay" and "delay" in dg.params:
        err = abs(dg.params["delay"] - truth["delay"])
        row["delay_error_s"] = err
        row["delay_ok"] = bool(err <= max(DELAY_TOL[0] * truth["delay"], DELAY_TOL[1]))
    if category == NONE:
        row["shown"] = True
    else:
        if "_damping_case" in oracle:
            case = oracle.pop("_damping_case")  # a rig export: the force on its own (resampled) rows
            grid = np.arange(0.0, float(dg.data.t[-1] - dg.data.t[0]) + 0.01, 1e-3)
            force = _damping_force(case, grid)
            x = dg.data.t - dg.data.t[0]
            oracle["damping_force"] = np.column_stack([np.interp(x, grid, force[:, k]) for k in range(3)])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            row["shown"] = payload_shown(dg, oracle, true_raw, N_PARAMS[category])
    return row


def score_rows(rows: Sequence[dict]) -> dict:
    """The three numbers (docs/validation.md) and the payload targets' figures."""
    rows = list(rows)
    shown = [r for r in rows if r["shown"]]
    nominal = [r for r in rows if r["category"] == NONE]
    delays = [r for r in rows if "delay_ok" in r]
    return {
        "n": len(rows),
        "shown_share": len(shown) / len(rows) if rows else float("nan"),
        "right_on_shown": float(np.mean([r["right"] for r in shown])) if shown else float("nan"),
        "wrong_named_share": float(np.mean([r["wrong_named"] for r in rows])) if rows else float("nan"),
        "nominal_none": (sum(r["verdict"] == "none" for r in nominal), len(nominal)),
        "delay_within_tol": (sum(r["delay_ok"] for r in delays), len(delays)),
        "by_category": {c: {"n": sum(r["category"] == c for r in rows),
                            "shown": sum(r["category"] == c and r["shown"] for r in rows),
                            "right": sum(r["category"] == c and r["right"] for r in rows),
                            "verdicts": sorted(r["verdict"] for r in rows if r["category"] == c)}
                        for c in CATEGORIES if any(r["category"] == c for r in rows)},
    }


def _tasks(source: str, n: int, seed: int, only: str | None) -> tuple:
    rng = np.random.default_rng(seed)
    if source == "independent":
        cats = [only or CATEGORIES[i % len(CATEGORIES)] for i in range(n)]
        rng.shuffle(cats)
        return _independent_row, [(c, int(s)) for c, s in zip(cats, rng.integers(2**31, size=n))]
    from fricenv.gap.payload.validate import draw_payload_case, draw_payload_cases

    cases = [draw_payload_case(only, rng) for _ in range(n)] if only else draw_payload_cases(n, seed)
    if source == "stand_in":
        return _stand_in_row, cases
    rates = np.random.default_rng([seed, 15]).uniform(100.0, 200.0, n)
    return _real_like_row, list(zip(cases, (float(r) for r in rates)))


def measure(source: str, n: int, seed: int, jobs: int = 1, only: str | None = None) -> dict:
    """Draw ``n`` logs of ``source`` (only the category ``only`` when given), diagnose blind, score."""
    if source not in SOURCES:
        raise ValueError(f"unknown source {source!r}; valid: {', '.join(SOURCES)}")
    if only is not None and only not in CATEGORIES:
        raise ValueError(f"unknown category {only!r}; valid: {', '.join(CATEGORIES)}")
    fn, tasks = _tasks(source, n, seed, only)
    rows = pool_map(fn, tasks, jobs)
    s = score_rows(rows)
    s.update(source=source, seed=seed, only=only, logs=rows)
    return s


def format_summary(s: dict) -> str:
    """The three numbers and the payload targets' figures as text."""
    lines = [f"{c:>18}: n {v['n']}, shown {v['shown']}, right {v['right']}; verdicts {v['verdicts']}"
             for c, v in s["by_category"].items()]
    nn, nt = s["nominal_none"]
    dk, dn = s["delay_within_tol"]
    lines += [f"source {s['source']}, seed {s['seed']}, {s['n']} logs" + (f" (only {s['only']})" if s["only"] else ""),
              (f"data show the answer: {s['shown_share']:.1%}; right on those: {s['right_on_shown']:.1%}; "
              f"wrong named effects: {s['wrong_named_share']:.1%}"),
              f"nominal logs 'none': {nn}/{nt}; vision delays within 15 % or 5 ms: {dk}/{dn}"]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Command line (see the module docstring)."""
    ap = measurement_parser("Payload suites scored against what the data show.", n=60, seed=0)
    ap.add_argument("--source", choices=SOURCES, default="independent")
    ap.add_argument("--only", choices=CATEGORIES, default=None, help="draw only this category")
    args = ap.parse_args(argv)
    if args.n < 1 or args.jobs < 1:
        ap.error("--n and --jobs must be >= 1")
    from validation import payload_suite as mod  # noqa: PLW0406 -- by its import name, for worker processes

    s = mod.measure(args.source, args.n, args.seed, args.jobs, args.only)
    print(format_summary(s))
    if args.json:
        from fricenv.utils import write_json

        write_json(args.json, s)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
