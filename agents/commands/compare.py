"""Reproduce the headline table from scratch: PPO with none / EKF-RLS / oracle observations (``--estimators``; the
MHE row is left out of the default budget: 10x slower per step), the memory baselines without estimates (PPO on a
frame stack of the last 4 observations, RecurrentPPO), the rule ABS and estimator + slip controller, on the fixed
evaluation scenario set.

Trains every row on every ``--train-seeds`` seed (``--steps`` each, ``--workers`` trainings at a time; existing
runs in ``--out`` are reused with ``--reuse``), then evaluates all of them with ``fricenv evaluate``'s scenario set
and prints the table, a per-policy and training-seed summary (mean and worst ratio over the scenarios, lock events)
and the training wall times. The budget is printed at the start. ``--excitation`` also trains excitation policies on PayloadExcitation-v0 with and without the RLS estimate
S_hat in the observation and compares their time to E < 1e-2 and final E with the multi-sine and PRBS.

``--effect-grid`` evaluates the rows on dry and wet at 20 m/s on every cell of the effect grid instead of the
scenario set, and writes the robustness matrix (``robustness.txt``, ``robustness.json``, the heatmap
``robustness.png``: policy x cell) into ``--out``; the classical rows keep their nominal tuning.

``--ray auto|ADDRESS`` runs the trainings and the evaluation episodes as Ray tasks (one CPU each) instead of
``--workers`` local processes: 'auto' joins the instance this machine runs or ``RAY_ADDRESS`` names, else starts a
local one; an address joins that cluster (every node needs fricenv installed and ``--out`` on a shared path).
"""

from __future__ import annotations

import argparse

DEFAULT_ESTIMATORS = ("none", "ekf-rls", "oracle")
DEFAULT_BASELINES = ("ppo-stack4", "recurrent-ppo")  # agents.evaluation.MEMORY_BASELINES
DEFAULT_TRAIN_SEEDS = (0, 1, 2)
DEFAULT_STEPS = 600_000  # PPO with minibatch 1024 needs the longer budget (agents/hyperparams/braking.json)
DEFAULT_PAYLOAD_STEPS = 120_000


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``fricenv compare``."""
    parser.add_argument("--estimators", nargs="+", default=list(DEFAULT_ESTIMATORS),
                        help="observation estimators of the PPO rows (default: %(default)s)")
    parser.add_argument("--algo", choices=("ppo", "sac"), default="ppo", help="algorithm (default %(default)s)")
    parser.add_argument("--steps", type=int, default=DEFAULT_STEPS, help="training steps per policy "
                                                                          "(default %(default)s)")
    parser.add_argument("--pipeline", default="ekf-rls",
                        help="estimator of the estimator + slip controller row (default %(default)s)")
    parser.add_argument("--train-seeds", type=int, nargs="+", default=list(DEFAULT_TRAIN_SEEDS),
                        help="training seeds: every trained row is trained on each (default: %(default)s)")
    parser.add_argument("--baselines", nargs="*", default=list(DEFAULT_BASELINES),
                        help="memory baselines without estimates (default: %(default)s)")
    parser.add_argument("--seeds", type=int, default=3, help="evaluation seeds (default %(default)s)")
    parser.add_argument("--effect-grid", action="store_true",
                        help="evaluate every row on dry and wet at 20 m/s on every cell of the effect grid (the "
                             "nominal plant, each effect at its low and high size) and write the robustness matrix")
    parser.add_argument("--workers", type=int, default=2, help="parallel processes (default %(default)s)")
    parser.add_argument("--ray", metavar="auto|ADDRESS", default=None,
                        help="run trainings and episodes as Ray tasks: 'auto' (a running instance, else a local "
                             "one) or a cluster address; --workers is then not used")
    parser.add_argument("--out", default="runs/compare", metavar="DIR", help="output directory")
    parser.add_argument("--reuse", action="store_true", help="reuse finished runs found in --out")
    parser.add_argument("--excitation", action="store_true",
                        help="also train and compare excitation policies on PayloadExcitation-v0")
    parser.add_argument("--payload-steps", type=int, default=DEFAULT_PAYLOAD_STEPS,
                        help="training steps per excitation policy (default %(default)s)")
    parser.add_argument("--json", metavar="PATH", help="write {\"rows\": [...], ...} as JSON")


def run(args) -> int:
    """Train, evaluate, print and write the comparison."""
    import time
    from pathlib import Path

    from agents.evaluation import (
        check_compare_args,
        compare_abs,
        compare_excitation,
        format_table,
        summarize_policies,
        write_outputs,
    )
    from fricenv.errors import InvalidInputError, one_line
    from fricenv.utils import write_json

    out = Path(args.out)
    if args.seeds < 1 or args.workers < 1 or args.steps < 1:
        raise InvalidInputError("--seeds, --workers and --steps must be >= 1")
    try:
        check_compare_args(args.estimators, args.baselines, args.pipeline, args.train_seeds)
    except ValueError as exc:
        raise InvalidInputError(one_line(exc)) from None
    scenarios = None
    if args.effect_grid:
        from agents.effect_scenarios import grid_scenarios

        scenarios = grid_scenarios()
    n_runs = (len(args.estimators) + len(args.baselines)) * len(args.train_seeds)
    print(f"budget: {n_runs} trainings ({len(args.estimators)} estimator rows + {len(args.baselines)} memory "
          f"baselines) x {args.steps} steps on training seeds {args.train_seeds}, then evaluation over "
          f"{args.seeds} seeds, " + (f"on Ray {args.ray}" if args.ray else f"{args.workers} workers"))
    t0 = time.perf_counter()
    abs_result = compare_abs(out, estimators=args.estimators, algo=args.algo, steps=args.steps,
                             pipeline=args.pipeline, train_seeds=args.train_seeds, seeds=args.seeds,
                             workers=args.workers, reuse=args.reuse, baselines=args.baselines,
                             ray=args.ray, scenarios=scenarios)
    rows = abs_result["rows"]
    print(format_table(rows))
    print()
    summary = summarize_policies(rows)
    print(f"{'policy':<26} {'seed':>4} {'mean ratio':>10} {'worst':>7} {'locks':>5}   (over "
          f"{len(summary[0]['scenarios'])} scenarios x {args.seeds} seeds)" if summary else "no rows")
    for s in summary:
        seed = "-" if s["train_seed"] is None else str(s["train_seed"])
        print(f"{s['policy']:<26} {seed:>4} {s['ratio_mean']:>10.3f} {s['ratio_worst']:>7.3f} {s['locks']:>5d}")
    for t in abs_result["training"]:
        cpu = "" if t.get("cpu_time_s") is None else f", {t['cpu_time_s']:.0f} s CPU"
        print(f"training {t['policy']:<24} seed {t['train_seed']}: {t['steps']} steps, {t['wall_time_s']:.0f} s"
              f"{cpu}, {t['steps_per_second']:.0f} steps/s")
    cpu = [t["cpu_time_s"] for t in abs_result["training"] if t.get("cpu_time_s") is not None]
    if cpu:  # one torch thread per training: its CPU time is its wall time on a core of its own
        print(f"training CPU time {sum(cpu):.0f} s over {len(cpu)} runs: about {sum(cpu) / max(args.workers, 1):.0f} s "
              f"of training wall time on {args.workers} quiet cores")
    print(f"evaluation wall time {abs_result['evaluation_time_s']:.0f} s")
    written = write_outputs(rows, out, None, title="headline comparison")
    if args.effect_grid:
        from agents.commands.evaluate import _write_grid

        written.update(_write_grid(rows, str(out), args.seeds))
    payload = None
    if args.excitation:
        payload = compare_excitation(out / "excitation", steps=args.payload_steps, seed=args.train_seeds[0],
                                     workers=args.workers, reuse=args.reuse, ray=args.ray)
        print()
        print(f"{'excitation policy':<22} {'t(E<1e-2)':>10} {'E_end':>10} {'effort':>8} {'left ws':>7}")
        for r in payload["rows"]:
            tb = "never" if r["t_below_1e-2"] is None else f"{r['t_below_1e-2']:.2f} s"
            print(f"{r['policy']:<22} {tb:>10} {r['E_end']:>10.2e} {r['effort']:>8.3f} {r['left_workspace']:>7d}")
    total = time.perf_counter() - t0
    print(f"total wall time {total:.0f} s")
    for kind, path in written.items():
        print(f"wrote {kind}: {path}")
    if args.json:
        write_json(args.json, {"rows": rows, "summary": summary, "training": abs_result["training"],
                               "evaluation_time_s": abs_result["evaluation_time_s"],
                               "excitation": payload, "total_time_s": total})
        print(f"wrote json: {args.json}")
    return 0
