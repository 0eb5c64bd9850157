"""Validate the gap diagnosis on withheld effects: random logs, blind diagnosis, confusion matrix.

Example: fricenv gap validate --n 50 --seed 1 --jobs 2 --json validate.json
(--ray auto or --ray ADDRESS: the diagnoses run on a Ray cluster instead of --jobs local processes)

Draws N logs from the real stand-in (each library effect at realistic sizes, no effect, and a physically real effect
outside the library: brake fade or pitch load transfer) on random roads and drivers, diagnoses each without telling
the tool, and prints the confusion matrix, the share of right verdicts, the median gap_after/gap_before on effect
logs and the parameter errors. --plant payload does the same for payload logs (fricenv.gap.payload.validate).
"""

from __future__ import annotations

import argparse

from fricenv.errors import InvalidInputError
from fricenv.gap.plants import GAP_PLANTS

PLANTS = tuple(GAP_PLANTS)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``fricenv gap validate``."""
    parser.add_argument("--n", type=int, default=50, help="number of logs (default %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the draw (default %(default)s)")
    parser.add_argument("--jobs", type=int, default=2, help="parallel diagnoses (default %(default)s)")
    parser.add_argument("--required-only-share", type=float, default=0.0,
                        help="share of logs with only the required columns t, T_b, omega (default %(default)s)")
    parser.add_argument("--json", metavar="PATH", help="write the figures (and every log's result) as JSON")
    parser.add_argument("--ray", metavar="auto|ADDRESS", default=None,
                        help="run the diagnoses on Ray (auto: a running instance or cluster, else a local one; "
                             "or a cluster address); quarter-car only")
    parser.add_argument("--plant", default="quarter-car",
                        help="quarter-car or payload (payload: its four effects, none, and viscous damping as the "
                             "out-of-library effect; one process; default %(default)s)")


def run(args: argparse.Namespace) -> int:
    """Run the validation and print the figures."""
    from fricenv.utils import write_json

    if args.n < 1:
        raise InvalidInputError(f"--n must be >= 1, got {args.n}")
    if args.jobs < 1:
        raise InvalidInputError(f"--jobs must be >= 1, got {args.jobs}")
    if not 0.0 <= args.required_only_share <= 1.0:
        raise InvalidInputError(f"--required-only-share must be in [0, 1], got {args.required_only_share}")
    if args.plant not in PLANTS:
        raise InvalidInputError(f"unknown plant {args.plant!r}; valid plants: {', '.join(PLANTS)}")
    from fricenv.gap.plants import get_plant

    summary, text = get_plant(args.plant).validate(args.n, args.seed, args.jobs, args.ray, args.required_only_share)
    print(text)
    print(f"wall time {summary['wall_seconds']:.0f} s")
    if args.json:
        write_json(args.json, summary)
    return 0
