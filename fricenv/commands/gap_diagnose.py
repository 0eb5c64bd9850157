"""Diagnose the sim-to-real gap of a log: where it lies, which unmodelled effect causes it, how far it shrinks.

Example: fricenv gap diagnose log.csv --plant quarter-car --out report_dir

A fleet: fricenv gap diagnose logs/ --out fleet_dir (a folder: its *.csv logs; or a quoted glob pattern such as
'logs/**/*.csv') diagnoses every log into fleet_dir/<log stem>/ and writes fleet_dir/fleet.json, fleet.md and plots
(fricenv.gap.fleet.run). A re-run skips the logs already reported (--force redoes them); --jobs sets the parallel logs;
--ray auto (or a Ray cluster address) runs them on Ray. A log that fails is a row with its error, and the exit
code is then 1.

Writes DIR/report.json (the schema of docs/contracts.md), DIR/report.md and PNG plots (atomically: temporary
name, then rename) and prints a short summary. --params FILE.json overrides the nominal vehicle parameters (m, J,
r, Fz, g) and may hold a car section ({"car": {"mass": 790.0, "lf": 1.248, "lr": 1.7328}}); a car's session (a log
with a throttle, yaw rate or several wheels) is diagnosed across its braking events (fricenv.gap.car); for --plant
payload (log columns t, M, f_x, f_y, theta, X, Y) it gives the known calibration "S" (3x3 row-major) and
optionally m, I_G, rho_x, rho_y.
"""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path

from fricenv.errors import InvalidInputError
from fricenv.gap.plants import GAP_PLANTS
from fricenv.utils import read_json_object

PLANTS = tuple(GAP_PLANTS)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``fricenv gap diagnose``."""
    parser.add_argument("source", metavar="LOG",
                        help="log CSV (docs/contracts.md format), or a folder of *.csv logs or a quoted glob "
                             "pattern (a fleet)")
    parser.add_argument("--plant", default="quarter-car", help="plant of the log (default %(default)s)")
    parser.add_argument("--out", required=True, help="report directory")
    parser.add_argument("--params", metavar="FILE.json", help="nominal plant parameters (JSON object)")
    parser.add_argument("--json", metavar="PATH", help="also write the report.json object here")
    parser.add_argument("--jobs", type=int, default=None, help="processes for the candidate fits (default: up to 2)")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.add_argument("--candidates", metavar="A,B,...", default=None,
                        help="comma-separated candidate effects to try (default: the whole library)")
    parser.add_argument("--force", action="store_true", help="fleet: diagnose again the logs already reported")
    parser.add_argument("--ray", metavar="auto|ADDRESS", default=None,
                        help="fleet: run on Ray (auto: a running instance or cluster, else a local one; or an address)")
    _add_map_option(parser)


def _add_map_option(parser: argparse.ArgumentParser) -> None:
    """``--map``: read a real export through a column map (docs/contracts.md, "Column map")."""
    parser.add_argument("--map", metavar="MAP.json", default=None,
                        help="column map of a real export: source column, unit and factor per channel; the "
                             "converted log is written to OUT/log.contract.csv and diagnosed")


def _mapped_log(args: argparse.Namespace) -> str:
    """The log to diagnose: with --map, the export converted into OUT/log.contract.csv (fricenv gap convert)."""
    if getattr(args, "map", None) is None:
        return args.log
    from pathlib import Path

    from fricenv.commands.gap_convert import convert
    from fricenv.utils import check_input_file

    check_input_file(args.map, "--map")
    out = Path(args.out) / "log.contract.csv"
    out.parent.mkdir(parents=True, exist_ok=True)
    convert(args.log, args.map, args.plant, out)
    return str(out)


def _naming_the_export(exc: InvalidInputError, log: str, export: str) -> InvalidInputError:
    """An error about the whole converted log (``OUT/log.contract.csv: ...``, no line) names the export it was
    converted from; an error at a line of the converted log keeps its path, whose lines it counts."""
    message, prefix = str(exc), f"{log}: "
    if log == export or not message.startswith(prefix):
        return exc
    return InvalidInputError(f"{export}: {message[len(prefix):]} (converted to {log})")


def check_options(args: argparse.Namespace) -> None:
    """Reject option values the diagnosis cannot use, before it starts (the paths are checked by fricenv.cli)."""
    if args.plant not in PLANTS:
        raise InvalidInputError(f"plant {args.plant!r} is not supported by gap diagnose; "
                                f"valid plants: {', '.join(PLANTS)}")
    if args.jobs is not None and args.jobs < 1:
        raise InvalidInputError(f"--jobs must be >= 1, got {args.jobs}")
    if args.params is not None:  # its syntax now, before the diagnosis' imports; its keys when the plant loads it
        read_json_object(args.params, f"{args.plant} parameters")


def _candidates(args: argparse.Namespace, valid: tuple[str, ...]) -> tuple[str, ...] | None:
    """The --candidates names (None: the whole library), each checked against ``valid``."""
    if not args.candidates:
        return None
    names = tuple(c.strip() for c in args.candidates.split(",") if c.strip())
    unknown = [n for n in names if n not in valid]
    if unknown or not names:
        raise InvalidInputError(f"--candidates {args.candidates!r}: unknown candidate effect(s) "
                                f"{', '.join(unknown) or '(none named)'}; valid effects: {', '.join(valid)}")
    return names


def run(args: argparse.Namespace) -> int:
    """Read, diagnose, report (a fleet: every log of a folder or glob pattern, and the fleet summary); each warning
    of the log checks is one line on stderr."""
    from fricenv.logs.checks import one_line_warnings

    with one_line_warnings():
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    from fricenv.gap.fleet.run import is_fleet_source

    if is_fleet_source(args.source):
        return _run_fleet(args)
    _single_log(args)
    check_options(args)
    from fricenv.gap.plants import get_plant

    plant = get_plant(args.plant)
    names = _candidates(args, plant.make_config(None, None).candidates)
    log = _mapped_log(args)
    try:
        dg = plant.diagnose_file(log, args.params, plant.make_config(names, args.jobs))
    except InvalidInputError as exc:
        raise _naming_the_export(exc, log, args.log) from None
    return _report(args, dg, plant.write_report(dg, args.out, not args.no_plots), plant.summary_line(dg))


def _report(args: argparse.Namespace, dg, report: dict, summary: str) -> int:
    """Write --json and print the short summary (both plants)."""
    from fricenv.utils import write_json

    if args.json:
        write_json(args.json, report)
    print(summary)
    top = ", ".join(f"{c['effect']} {c['gap_after']:.3g}" for c in report["candidates"][:3])
    print(f"best candidates (held-out gap): {top}")
    print(f"report: {Path(args.out) / 'report.json'}, report.md ({dg.seconds:.1f} s)")
    return 0


def _single_log(args: argparse.Namespace) -> None:
    """One log: ``args.log`` checked as the CLI checks input files; the fleet options rejected."""
    from fricenv.utils import check_input_file

    args.log = args.source
    check_input_file(args.log, "log")
    for option, value in (("--ray", args.ray), ("--force", args.force)):
        if value:
            raise InvalidInputError(f"{option} applies to a fleet (a folder or glob pattern of logs), "
                                    f"not to the single log {args.log}")


def _run_fleet(args: argparse.Namespace) -> int:
    """A folder or glob pattern: every log diagnosed into OUT/<stem>/, then OUT/fleet.json, fleet.md and plots."""
    from fricenv.gap.fleet.run import FleetSettings, run_fleet

    check_options(args)
    if args.json:
        raise InvalidInputError("--json applies to a single log; a fleet's rows are in OUT/fleet.json")
    if args.ray is not None and args.jobs is not None:
        raise InvalidInputError("--jobs sets local processes; with --ray the cluster's CPUs set the parallelism")
    from fricenv.gap.plants import get_plant

    plant = get_plant(args.plant)
    names = _candidates(args, plant.make_config(None, None).candidates)
    settings = FleetSettings(plant=args.plant, params_file=args.params, config=plant.make_config(names, None),
                             plots=not args.no_plots, force=args.force, jobs=args.jobs, ray=args.ray)
    s = run_fleet(args.source, args.out, settings)
    counts = Counter(r["verdict"] for r in s["rows"])
    print(f"{len(s['rows'])} logs: " + ", ".join(f"{v} {n}" for v, n in counts.most_common()))
    rate = s["diagnosed"] / s["wall_seconds"] * 3600 if s["diagnosed"] else 0.0
    print(f"diagnosed {s['diagnosed']} in {s['wall_seconds']:.0f} s ({rate:.0f} logs/hour), "
          f"skipped {s['skipped']} already reported, {s['failed']} failed")
    print(f"fleet: {Path(args.out) / 'fleet.json'}, fleet.md")
    return 1 if s["failed"] else 0
