"""Reproduce the MHE friction paper (Sui & Johansen): cases 1-4 with the MHE (default and the paper's), the EKF.

For each case (1: theta on dry, 2: theta on snow, 3: theta, B, C, E on dry, 4: the same on snow; logs from
estimators/scenarios.py, ABS-like excitation, wheel-speed noise variance 0.2) and each estimator

  mhe          regularized MHE, default (estimators/mhe.py): SVD-thresholded weighting of eq. (16) in the scaled
               reading, with the beyond-the-paper EKF arrival cost, process noise in the window and EKF gate;
  mhe-paper    the paper's MHE: scaled reading, the paper's prior terms beta_i and hard dynamics (12b);
  mhe-ekf      the paper's hard dynamics with the EKF arrival cost only (no process noise, no gate);
  ekf          the EKF on the same augmented model (the baseline);
  mhe-literal  the literal reading of eq. (16), W = (1/alpha) V S_delta^+ U^T in SI units (for comparison);

it prints the RMS error of v and slip after 0.5 s, theta's error at 0.5 s and at the end, final B, C, E errors and
the mean and max time per update (wall clock, and process CPU time, which is what counts on a shared machine),
saves one PNG per case in --out (truth solid, estimates dashed) and, with
--json, writes {"cases": [{"case", "estimator", "rms_v", "rms_slip", "theta_error", "update_ms_mean",
"update_ms_max", ...}, ...]}. With --seeds K > 1 the errors are means over K noise seeds (times from all runs).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

SETTLE_TIME = 0.5  # [s] errors are measured after this time
ESTIMATORS = ("mhe", "mhe-paper", "mhe-ekf", "ekf", "mhe-literal")
CASES = (1, 2, 3, 4)
PARAMS = ("theta", "B", "C", "E")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``fricenv paper mhe``."""
    parser.add_argument("--out", default="runs/paper_mhe", help="directory for the PNG figures (default %(default)s)")
    parser.add_argument("--json", metavar="PATH", help="write the figures as JSON")
    parser.add_argument("--seed", type=int, default=0, help="seed of the measurement noise (default %(default)s)")
    parser.add_argument("--seeds", type=int, default=1, help="number of seeds averaged (default %(default)s)")
    parser.add_argument("--cases", default="1,2,3,4", help="comma-separated cases (default %(default)s)")
    parser.add_argument("--estimators", default=",".join(ESTIMATORS),
                        help="comma-separated subset of " + ", ".join(ESTIMATORS))
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG figures")


def make_estimator(name: str, estimated: tuple[str, ...]):
    """The estimator called ``name`` (an entry of :data:`estimators.registry.ESTIMATORS` among :data:`ESTIMATORS`)
    for the given augmented parameters, on the paper's vehicle (Table I) and sample time, on the paper's model
    (no brake-gain or deceleration-bias state)."""
    from estimators.registry import get_estimator

    return get_estimator(name, ESTIMATORS).make(estimated=estimated, mismatch_states=())


def run_case(pc, name: str) -> dict:
    """Run one estimator over one generated case; returns outputs, errors and update times."""
    est = make_estimator(name, pc.estimated)
    est.reset()
    log = pc.log
    n = len(log.t)
    out = {k: np.empty(n) for k in est.names}
    times = np.empty(n)
    cpu = np.empty(n)
    for k in range(n):
        t0, c0 = time.perf_counter(), time.process_time()
        e = est.update(log.omega[k], log.T_b[k])
        times[k], cpu[k] = time.perf_counter() - t0, time.process_time() - c0
        for key in est.names:
            out[key][k] = e.values[key]
    m = log.t >= SETTLE_TIME - 1e-9
    i_settle = int(np.argmax(m))
    truth = {"theta": pc.road.theta, "B": pc.road.B, "C": pc.road.C, "E": pc.road.E}
    res = {
        "rms_v": float(np.sqrt(np.mean((out["v"][m] - pc.v[m]) ** 2))),
        "rms_slip": float(np.sqrt(np.mean((out["slip"][m] - pc.slip[m]) ** 2))),
        "rms_mu": float(np.sqrt(np.mean((out["mu"][m] - pc.mu[m]) ** 2))),
        "theta_error": float(out["theta"][-1] - truth["theta"]),
        "theta_error_at_0.5s": float(out["theta"][i_settle] - truth["theta"]),
        "B_error": float(out["B"][-1] - truth["B"]),
        "C_error": float(out["C"][-1] - truth["C"]),
        "E_error": float(out["E"][-1] - truth["E"]),
        # the first N updates only buffer samples: the times are of the solving updates
        "times_ms": times * 1e3,
        "cpu_ms": cpu * 1e3,
    }
    return {"out": out, "res": res}


def _plot(pc, runs: dict, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = ["v", "slip"] + list(pc.estimated)
    truth = {"v": pc.v, "slip": pc.slip, "theta": pc.road.theta, "B": pc.road.B, "C": pc.road.C, "E": pc.road.E}
    fig, axes = plt.subplots(len(names), 1, figsize=(7, 2.0 * len(names)), sharex=True)
    t = pc.log.t
    for ax, key in zip(axes, names):
        tr = truth[key]
        ax.plot(t, np.broadcast_to(tr, t.shape), "k-", lw=1.5, label="truth")
        for name, run in runs.items():
            ax.plot(t, run["out"][key], "--", lw=1.0, label=name)
        ax.set_ylabel(key)
    axes[0].legend(fontsize=7, ncol=3)
    axes[-1].set_xlabel("t [s]")
    fig.suptitle(f"case {pc.case}: {pc.road.name}, estimated {', '.join(pc.estimated)}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(args) -> int:
    from pathlib import Path

    from estimators.scenarios import mhe_case
    from fricenv.utils import progress, write_json

    try:
        cases = [int(c) for c in args.cases.split(",") if c.strip()]
    except ValueError:
        raise SystemExit(f"--cases must be a comma-separated list of {CASES}, got {args.cases!r}") from None
    bad = [c for c in cases if c not in CASES]
    names = [e.strip() for e in args.estimators.split(",") if e.strip()]
    bad_e = [e for e in names if e not in ESTIMATORS]
    if bad or bad_e:
        raise SystemExit(f"unknown cases {bad} / estimators {bad_e}; valid cases {CASES}, "
                         f"estimators {', '.join(ESTIMATORS)}")
    if args.seeds < 1:
        raise SystemExit("--seeds must be >= 1")
    out_dir = Path(args.out)
    if not args.no_plots:
        out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    jobs = [(c, s, e) for c in cases for s in range(args.seed, args.seed + args.seeds) for e in names]
    acc: dict = {}
    plot_runs: dict = {}
    logs = {}
    for c, s, e in progress(jobs, total=len(jobs), desc="paper mhe"):
        if (c, s) not in logs:
            logs[(c, s)] = mhe_case(c, seed=s)
        pc = logs[(c, s)]
        r = run_case(pc, e)
        acc.setdefault((c, e), []).append(r["res"])
        if s == args.seed:
            plot_runs.setdefault(c, {})[e] = r
    for c in cases:
        for e in names:
            rs = acc[(c, e)]
            times = np.concatenate([r["times_ms"][10:] for r in rs])
            cpu = np.concatenate([r["cpu_ms"][10:] for r in rs])
            row = {"case": c, "estimator": e, "seeds": len(rs)}
            for key in ("rms_v", "rms_slip", "rms_mu", "theta_error", "theta_error_at_0.5s",
                        "B_error", "C_error", "E_error"):
                row[key] = float(np.mean([r[key] for r in rs]))
            row["update_ms_mean"] = float(times.mean())
            row["update_ms_max"] = float(times.max())
            # process CPU time: what the update costs when the machine is shared with other jobs
            row["update_cpu_ms_mean"] = float(cpu.mean())
            row["update_cpu_ms_max"] = float(cpu.max())
            rows.append(row)
        if not args.no_plots:
            _plot(logs[(c, args.seed)], plot_runs[c], out_dir / f"case{c}.png")
    hdr = (f"{'case':>4} {'estimator':<12} {'rms_v':>8} {'rms_slip':>9} {'th@0.5s':>8} {'th_end':>8} "
           f"{'B_err':>7} {'C_err':>7} {'E_err':>7} {'ms_mean':>8} {'ms_max':>8} {'cpu_mean':>8} {'cpu_max':>8}")
    print(hdr)
    for r in rows:
        print(f"{r['case']:>4} {r['estimator']:<12} {r['rms_v']:8.4f} {r['rms_slip']:9.5f} "
              f"{r['theta_error_at_0.5s']:+8.4f} {r['theta_error']:+8.4f} {r['B_error']:+7.2f} "
              f"{r['C_error']:+7.3f} {r['E_error']:+7.2f} {r['update_ms_mean']:8.3f} {r['update_ms_max']:8.3f} "
              f"{r['update_cpu_ms_mean']:8.3f} {r['update_cpu_ms_max']:8.3f}")
    if not args.no_plots:
        print(f"figures: {out_dir}/case{{{','.join(map(str, cases))}}}.png")
    if args.json:
        write_json(args.json, {"settle_time_s": SETTLE_TIME, "seed": args.seed, "cases": rows})
    return 0
