"""Real-like payload logs for measuring the payload gap diagnosis.

The cases are those of ``fricenv gap validate --plant payload`` (:mod:`fricenv.gap.payload.validate`: each library
effect, none, and viscous damping outside the library), simulated at 1 ms and then exported through
:func:`tests.real_artifacts.real_like_payload`: the force-moment sensor low-passed and sampled at the logger rate, a
30 Hz camera whose pose is held between frames, tracking glitches of 5 mm, jittered epoch-millisecond stamps with the
odd dropped row, the pose in degrees and millimetres. Each export is read through its column map and diagnosed blind.

Measurement command::

    python -m tests.real_payload --n 12 --seed 41 [--jobs 2] [--json P]
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence

import numpy as np

from tests.measure_cli import measurement_parser, pool_map
from tests.real_artifacts import PayloadArtifacts, real_like_payload, write_export

__all__ = ["LOGGER_RATES", "SIM_DT", "measure_payload", "real_payload_row"]

SIM_DT = 1e-3  # the clean log's sample time [s]
LOGGER_RATES = (100.0, 200.0)  # F/T logger rates drawn [Hz]


def real_payload_row(case, rate_hz: float) -> dict:
    """Simulate one payload validation case, export it real-like at ``rate_hz`` and diagnose it blind."""
    from fricenv.gap.payload.validate import score_payload_case, simulate_payload_case
    from fricenv.logs import read_log

    case = dataclasses.replace(case, dt=SIM_DT)
    log, truth = simulate_payload_case(case)
    clean = {name: np.asarray(getattr(log, name), dtype=float) for name in ("t", "M", "f_x", "f_y", "theta", "X", "Y")}
    export = real_like_payload(clean, np.random.default_rng(case.seed + 1), PayloadArtifacts(rate_hz=rate_hz))

    def read(tmp: str):
        csv_path, map_path = write_export(os.path.join(tmp, "rig"), export)
        return read_log(csv_path, "payload", column_map=map_path)

    row = score_payload_case(case, truth, read)
    row.update(rate_hz=rate_hz, glitch_frames=export.truth["glitch_frames"], glitch_axis=export.truth["glitch_axis"])
    return row


def _task(args: tuple) -> dict:
    return real_payload_row(*args)


def measure_payload(n: int, seed: int, jobs: int = 1) -> dict:
    """Draw ``n`` payload validation cases, export each real-like, diagnose blind; the payload summary."""
    from fricenv.gap.payload.validate import draw_payload_cases, summarize_payload

    cases = draw_payload_cases(n, seed)
    rates = np.random.default_rng([seed, 15]).uniform(*LOGGER_RATES, n)
    rows = pool_map(_task, list(zip(cases, (float(r) for r in rates))), jobs)
    s = summarize_payload(rows)
    s.update(seed=seed, source="tests.real_payload")
    return s


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: ``python -m tests.real_payload --n 12 --seed 41 [--jobs 2] [--json P]``."""
    ap = measurement_parser("Measure the payload gap diagnosis on real-like rig exports.", n=12, seed=41)
    args = ap.parse_args(argv)
    if args.n < 1 or args.jobs < 1:
        ap.error("--n and --jobs must be >= 1")
    from fricenv.gap.payload.validate import format_payload_summary
    from fricenv.utils import write_json
    from tests import real_payload as mod  # noqa: PLW0406 -- by its import name, so that worker processes can unpickle

    s = mod.measure_payload(args.n, args.seed, args.jobs)
    for r in s["logs"]:
        print(f"  {r['category']:>18} | {r['rate_hz']:5.0f} Hz | {r['verdict']:>18} {'OK ' if r['right'] else 'BAD'} | "
              f"{r.get('gap_before', float('nan')):.2f} -> {r.get('gap_after', float('nan')):.2f} | "
              f"{r.get('error', '')}")
    print(format_payload_summary(s))
    if args.json:
        write_json(args.json, s)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
