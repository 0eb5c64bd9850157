"""Diagnose the sim-to-real gap of a log: where it lies, which unmodelled effect causes it, how far it shrinks.

Example: fricenv gap diagnose log.csv --plant quarter-car --out report_dir

Writes DIR/report.json (DESIGN.md schema), DIR/report.md and PNG plots (atomically: temporary name, then rename)
and prints a short summary. --params FILE.json overrides the nominal vehicle parameters (m, J, r, Fz, g); for
--plant payload (log columns t, M, f_x, f_y, theta, X, Y) it gives the known calibration "S" (3x3 row-major) and
optionally m, I_G, rho_x, rho_y.
"""

from __future__ import annotations

import argparse

from fricenv.errors import InvalidInputError
from fricenv.utils import read_json_object

PLANTS = ("quarter-car", "payload")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``fricenv gap diagnose``."""
    parser.add_argument("log", help="log CSV (DESIGN.md format)")
    parser.add_argument("--plant", default="quarter-car", help="plant of the log (default %(default)s)")
    parser.add_argument("--out", required=True, help="report directory")
    parser.add_argument("--params", metavar="FILE.json", help="nominal plant parameters (JSON object)")
    parser.add_argument("--json", metavar="PATH", help="also write the report.json object here")
    parser.add_argument("--jobs", type=int, default=None, help="processes for the candidate fits (default: up to 2)")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.add_argument("--candidates", metavar="A,B,...", default=None,
                        help="comma-separated candidate effects to try (default: the whole library)")
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
    """Read, diagnose, report."""
    check_options(args)
    if args.plant == "payload":
        return _run_payload(args)
    from fricenv.gap.diagnose import DiagnoseConfig, diagnose_file
    from fricenv.gap.report import summary_line, write_report

    names = _candidates(args, DiagnoseConfig().candidates)
    cfg = DiagnoseConfig(jobs=args.jobs) if names is None else DiagnoseConfig(jobs=args.jobs, candidates=names)
    dg = diagnose_file(_mapped_log(args), args.plant, args.params, cfg)  # reports its phases through fricenv.progress
    return _report(args, dg, write_report(dg, args.out, args.plant, plots=not args.no_plots), summary_line(dg))


def _report(args: argparse.Namespace, dg, report: dict, summary: str) -> int:
    """Write --json and print the short summary (both plants)."""
    from fricenv.utils import write_json

    if args.json:
        write_json(args.json, report)
    print(summary)
    top = ", ".join(f"{c['effect']} {c['gap_after']:.3g}" for c in report["candidates"][:3])
    print(f"best candidates (held-out gap): {top}")
    print(f"report: {args.out}/report.json, report.md ({dg.seconds:.1f} s)")
    return 0


def _run_payload(args: argparse.Namespace) -> int:
    """``--plant payload``: the payload diagnosis (fricenv.gap.payload_diagnose); --jobs is not used (its fits are
    linear least squares and 1-D searches, about a second in total)."""
    from fricenv.gap.payload_diagnose import PayloadDiagnoseConfig, diagnose_payload_file, summary_line
    from fricenv.gap.payload_report import write_payload_report

    names = _candidates(args, PayloadDiagnoseConfig().candidates)
    cfg = PayloadDiagnoseConfig() if names is None else PayloadDiagnoseConfig(candidates=names)
    dg = diagnose_payload_file(_mapped_log(args), args.params, cfg)
    return _report(args, dg, write_payload_report(dg, args.out, plots=not args.no_plots), summary_line(dg))
