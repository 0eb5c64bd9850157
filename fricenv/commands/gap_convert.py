"""Convert a real export to the log contract, through a column map: units, resampling, held samples.

Example: fricenv gap convert export.csv --map export.map.json --out log.csv [--plant payload]

The map (docs/contracts.md, "Column map") names, per contract channel, the source column, its unit and any factor
(the wheel radius for a rim speed in km/h, the brake torque per pressure [N m per Pa] for a line pressure). Jittered time
stamps and dropped rows are resampled onto a uniform grid; held samples of a slower channel are written as nan. Time is
re-based to the first sample ('# t_offset_s:' keeps that sample's time, full precision). The log checks run first
(fricenv.logs.checks): a mistake they are sure of is an error; a doubt is a warning, one line on stderr and a
'# warning:' line of the output. The output's '#' lines say what was done, and '# torque_source: pressure' marks a
torque from a nominal pressure factor.
"""

from __future__ import annotations

import argparse
import os

from fricenv.gap.plants import GAP_PLANTS

PLANTS = tuple(GAP_PLANTS)
PATH_OPTIONS = {"map": "input file", "out": "output file"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``fricenv gap convert``."""
    parser.add_argument("log", help="the export (CSV with a header row, or a header written as the last '#' line "
                                    "before the data; other '#' lines first are kept as comments)")
    parser.add_argument("--map", required=True, metavar="MAP.json", help='column map (docs/contracts.md, "Column map")')
    parser.add_argument("--out", required=True, metavar="CONTRACT.csv", help="the contract log to write")
    parser.add_argument("--plant", default="quarter-car", choices=PLANTS, help="plant of the log (default %(default)s)")


def convert(log: str | os.PathLike, column_map: str | os.PathLike, plant: str, out: str | os.PathLike):
    """Read ``log`` through ``column_map`` and write it as a contract CSV at ``out``; returns the log object.

    :raises LogFormatError: naming the export's file, line and column; :raises ColumnMapError: naming the map key.
    """
    from fricenv.logs import log_notes, read_log, write_log

    converted = read_log(log, plant, column_map=column_map)
    write_log(out, converted, comments=converted.comments + log_notes(converted))
    return converted


def run(args: argparse.Namespace) -> int:
    """Convert, then print what was done (each warning of the log checks as one line on stderr)."""
    from fricenv.logs import log_notes
    from fricenv.logs.checks import one_line_warnings

    with one_line_warnings():
        converted = convert(args.log, args.map, args.plant, args.out)
    offset = f", time from {converted.t_offset!r} s" if converted.t_offset else ""
    print(f"{args.out}: {len(converted)} samples at {1.0 / converted.dt:.4g} Hz{offset}")
    for note in log_notes(converted):
        print(f"  {note}")
    return 0
