"""Evaluate ABS policies and classical controllers on the fixed scenario set (mean +- std over seeds).

Scenarios: dry, wet, snow, ice at 20 and 30 m/s, dry->ice and ice->dry (at 15 m) at 20 and 30 m/s, sensor noise
on. Policies (:mod:`agents.policy_spec`): a controller (``rule-abs``, ``oracle-slip``, ``slip-pi``, ``locked``),
``pipeline:EST`` (estimator EST + slip controller) or a training run directory. Prints ratio to the physical limit (mean +- std), lock events and mean |slip - lambda*|;
writes ``results.csv`` and ``ratios.png`` into ``--out`` and ``{"rows": [...]}`` to ``--json``.

Episodes run in ``--workers`` local processes, or with ``--ray auto|ADDRESS`` as Ray tasks (one CPU each) on a Ray
instance: the one this machine runs (``ray start``) or ``RAY_ADDRESS`` names, else a local one started for the run;
an address (``ray://head:10001``) joins that cluster, whose nodes need fricenv installed and the policy run
directories on a shared path. Both give the same rows.
"""

from __future__ import annotations

import argparse

DEFAULT_POLICIES = ("rule-abs", "pipeline:ekf")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``fricenv evaluate``."""
    parser.add_argument("--policy", action="append", metavar="SPEC",
                        help="policy spec, repeatable (default: rule-abs and pipeline:ekf)")
    parser.add_argument("--seeds", type=int, default=3, help="episodes (seeds 0..n-1) per scenario "
                                                              "(default %(default)s)")
    parser.add_argument("--workers", type=int, default=2, help="worker processes (default %(default)s)")
    parser.add_argument("--ray", metavar="auto|ADDRESS", default=None,
                        help="run the episodes as Ray tasks: 'auto' (a running instance, else a local one) or a "
                             "cluster address; --workers is then not used")
    parser.add_argument("--out", metavar="DIR", default="runs/evaluate", help="CSV and PNG directory")
    parser.add_argument("--json", metavar="PATH", help="write {\"rows\": [...]} as JSON")


def run(args) -> int:
    """Evaluate, print the table, write CSV, PNG and JSON."""
    import time

    from agents.evaluation import evaluate, format_table, parse_policy, write_outputs

    if args.seeds < 1:
        raise SystemExit("fricenv evaluate: --seeds must be >= 1")
    try:
        specs = [parse_policy(p) for p in (args.policy or DEFAULT_POLICIES)]
    except ValueError as exc:
        raise SystemExit(f"fricenv evaluate: {exc}") from None
    t0 = time.perf_counter()
    rows = evaluate(specs, seeds=args.seeds, workers=args.workers, ray=args.ray)
    wall = time.perf_counter() - t0
    print(format_table(rows))
    engine = f"Ray {args.ray}" if args.ray else f"{args.workers} worker(s)"
    print(f"evaluation wall time {wall:.1f} s ({args.seeds} seed(s), {engine})")
    written = write_outputs(rows, args.out, args.json)
    for kind, path in written.items():
        print(f"wrote {kind}: {path}")
    return 0
