"""Policy-level sim-to-real gap: a controller's stopping distance in the nominal sim, on the real stand-in, and in the sim augmented with the diagnosed effect.

Examples:
  fricenv gap policy rule-abs --effect brake_lag --param tau=0.04 --road wet --seeds 5
  fricenv gap policy slip-pi --effect drag --param c0=100 --param c2=1.5 --retune --json gap.json
  fricenv gap policy runs/ppo-none --report report_dir/report.json --road dry

POLICY is a controller (rule-abs, slip-pi, oracle-slip, locked), pipeline:<estimator>, or a training run
directory (SB3). With --effect/--param (the syntax of `fricenv gap simulate`), the controller brakes the real
stand-in (the plant with those effects), once more with a free-rolling start to make a log, which `gap diagnose`'s
diagnosis turns into a verdict and fitted parameters: the augmented simulator. With --report, the verdict and
parameters come from a report.json (for a real log, whose stopping distance is then only predicted). The
prediction errors are (d_sim - d_real) / d_real before (nominal) and after (augmented). --retune grids one
controller parameter (rule-abs: decel_dump; slip-pi: slip reference factor) in the augmented and nominal sims and
measures each choice on the stand-in.
"""

from __future__ import annotations

import argparse
import sys


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``fricenv gap policy``."""
    parser.add_argument("policy", help="controller name, pipeline:<estimator>, or a training run directory")
    parser.add_argument("--effect", action="append", default=[], metavar="NAME",
                        help="effect of the real stand-in (repeatable), as in gap simulate")
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                        help="effect parameter, SI units (repeatable), as in gap simulate")
    parser.add_argument("--report", metavar="DIR/report.json",
                        help="use this diagnosis (verdict + params) as the augmented simulator")
    parser.add_argument("--road", default="dry", help="road preset (dry, wet, snow, ice; default %(default)s)")
    parser.add_argument("--seeds", type=int, default=10, help="noise seeds averaged over (default %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="first seed (default %(default)s)")
    parser.add_argument("--v0", type=float, default=20.0, help="initial speed [m/s] (default %(default)s)")
    parser.add_argument("--retune", action="store_true", help="retune a controller parameter in the augmented sim")
    parser.add_argument("--log-out", metavar="PATH", help="write the stand-in's closed-loop log (CSV)")
    parser.add_argument("--report-out", metavar="DIR", help="write the diagnosis report of that log")
    parser.add_argument("--jobs", type=int, default=None, help="processes for the diagnosis' candidate fits")
    parser.add_argument("--json", metavar="PATH", help="write the figures as JSON")


def run(args: argparse.Namespace) -> int:
    """Run the three (or two) simulators, print the table, write the JSON."""
    import json
    import time

    from agents.gap_policy import UnknownPolicyError, format_table, policy_gap
    from fricenv.envs.effect_spec import parse_effect_args
    from fricenv.plants.tire import UnknownRoadError, get_road
    from fricenv.utils import write_json

    def fail(msg: str) -> int:
        print(f"fricenv gap policy: error: {msg}", file=sys.stderr)
        return 2

    try:
        effects = parse_effect_args(args.effect, args.param)
        get_road(args.road)
    except (ValueError, UnknownRoadError) as exc:
        return fail(str(exc))
    report = None
    if args.report:
        try:
            with open(args.report) as fh:
                report = json.load(fh)
        except (OSError, json.JSONDecodeError) as exc:
            return fail(f"cannot read --report {args.report}: {exc}")
    if not effects and report is None:
        return fail("give the real stand-in's effects (--effect NAME --param k=v) or a diagnosis (--report)")
    t0 = time.perf_counter()
    try:
        res = policy_gap(args.policy, args.road, effects, report=report, seeds=args.seeds, seed=args.seed,
                         v0=args.v0, retune=args.retune, log_path=args.log_out, report_dir=args.report_out,
                         diagnose_jobs=args.jobs, progress=lambda msg: print(f"... {msg}", file=sys.stderr))
    except UnknownPolicyError as exc:
        return fail(str(exc))
    except ValueError as exc:
        return fail(str(exc))
    res["wall_time_s"] = time.perf_counter() - t0
    print(format_table(res))
    if res["diagnosis"]:
        dg = res["diagnosis"]
        print(f"diagnosis ({dg['source']}): gap_before {dg['gap_before']:.3g} -> gap_after {dg['gap_after']:.3g}")
    print(f"wall time {res['wall_time_s']:.1f} s")
    if args.json:
        write_json(args.json, res)
        print(f"wrote {args.json}")
    return 0
