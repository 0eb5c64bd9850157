"""Evaluate ABS policies and classical controllers on the fixed scenario set (mean +- std over seeds).

Scenarios: dry, wet, snow, ice at 20 and 30 m/s, dry->ice and ice->dry (at 15 m) at 20 and 30 m/s, sensor noise
on. Policies (:mod:`agents.policy_spec`): a controller (``rule-abs``, ``oracle-slip``, ``slip-pi``, ``locked``),
``pipeline:EST`` (estimator EST + slip controller) or a training run directory. Prints ratio to the physical limit (mean +- std), lock events and mean |slip - lambda*|;
writes ``results.csv`` and ``ratios.png`` into ``--out`` and ``{"rows": [...]}`` to ``--json``.

Episodes run in ``--workers`` local processes, or with ``--ray auto|ADDRESS`` as Ray tasks (one CPU each) on a Ray
instance: the one this machine runs (``ray start``) or ``RAY_ADDRESS`` names, else a local one started for the run;
an address (``ray://head:10001``) joins that cluster, whose nodes need fricenv installed and the policy run
directories on a shared path. Both give the same rows.

The plant: ``--effects SPEC`` switches the corrected simulator's effects on in every scenario (JSON text when SPEC
starts with ``[``, else a path to a JSON list or a ``gap diagnose`` report.json; the entries of
``gymnasium.make("fricenv/Braking-v0", effects=...)``, e.g. ``'[{"effect": "brake_lag", "params": {"tau": 0.04}}]'``).
``--effect-grid`` runs dry and wet at 20 m/s on every cell of the effect grid (the nominal plant, then each effect
at its low and high size) and also writes the robustness matrix: ``robustness.txt``, ``robustness.json`` and the
heatmap ``robustness.png`` (policy x cell, mean ratio over the scenarios). Every row names its plant: ``cell`` and
``effects`` (``[]`` on the nominal plant).
"""

from __future__ import annotations

import argparse

DEFAULT_POLICIES = ("rule-abs", "pipeline:ekf")
RATIO_COLOUR_MAX = 2.0  # heatmap colour scale top: a policy that fails in one cell keeps the others readable


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
    plant = parser.add_mutually_exclusive_group()
    plant.add_argument("--effects", metavar="SPEC", default=None,
                       help="effects of the plant: a JSON list (starts with '['), or a path to a JSON list or a "
                            "report.json")
    plant.add_argument("--effect-grid", action="store_true",
                       help="dry and wet at 20 m/s on every cell of the effect grid; writes the robustness matrix")
    parser.add_argument("--out", metavar="DIR", default="runs/evaluate", help="CSV and PNG directory")
    parser.add_argument("--json", metavar="PATH", help="write {\"rows\": [...]} as JSON")


def run(args) -> int:
    """Evaluate, print the table, write CSV, PNG and JSON."""
    import time

    from agents.evaluation import SCENARIOS, evaluate, format_table, parse_policy, write_outputs
    from fricenv.errors import InvalidInputError, user_input

    if args.seeds < 1:
        raise InvalidInputError("--seeds must be >= 1")
    if args.workers < 1:
        raise InvalidInputError("--workers must be >= 1")
    with user_input("--policy"):
        specs = [parse_policy(p) for p in (args.policy or DEFAULT_POLICIES)]
    scenarios = _scenarios(args, SCENARIOS)
    t0 = time.perf_counter()
    rows = evaluate(specs, scenarios=scenarios, seeds=args.seeds, workers=args.workers, ray=args.ray)
    wall = time.perf_counter() - t0
    print(format_table(rows))
    engine = f"Ray {args.ray}" if args.ray else f"{args.workers} worker(s)"
    print(f"evaluation wall time {wall:.1f} s ({args.seeds} seed(s), {engine})")
    written = write_outputs(rows, args.out, args.json)
    if args.effect_grid:
        written.update(_write_grid(rows, args.out, args.seeds))
    for kind, path in written.items():
        print(f"wrote {kind}: {path}")
    return 0


def _scenarios(args, default):
    """The scenarios of the chosen plant: nominal, ``--effects`` or ``--effect-grid``."""
    from agents.effect_scenarios import fixed_effect_scenarios, grid_scenarios, parse_effects_arg
    from fricenv.errors import InvalidInputError

    if args.effect_grid:
        return grid_scenarios()
    if args.effects is not None:
        try:
            return fixed_effect_scenarios(default, parse_effects_arg(args.effects))
        except ValueError as exc:
            raise InvalidInputError(str(exc)) from None
    return list(default)


def _write_grid(rows, out: str, seeds: int) -> dict:
    """The robustness matrix of a grid evaluation (policy x cell) and its table on stdout."""
    from agents.robustness_report import format_matrix, policy_matrix, write_matrix

    matrix = policy_matrix(rows)
    print()
    print("mean stopping-distance ratio over dry and wet at 20 m/s, per plant cell")
    print(format_matrix(matrix, "policy", "ratio_mean", "{:.3f}"))
    print("lock events per plant cell")
    print(format_matrix(matrix, "policy", "locks", "{:.0f}"))
    return write_matrix(out, matrix, "policy", "ratio_mean",
                        f"stopping-distance ratio under the effect grid (dry, wet at 20 m/s; {seeds} seeds; "
                        f"colour clipped at {RATIO_COLOUR_MAX:g})",
                        "stopping distance / physical limit", extra={"rows": rows, "seeds": seeds},
                        vmax=RATIO_COLOUR_MAX)
