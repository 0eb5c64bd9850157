"""Write a fleet of blind 5 s quarter-car logs for the fleet measurement (docs/benchmarks.md).

``python -m tests.fleet_logs N SEED DIR`` writes ``DIR/log000.csv`` ... : ``fricenv.gap.quarter_car.validate``'s cases over its
categories in turn (every library effect, ``none`` and out-of-library), through ``write_simulated_log`` without
provenance comments, and the truth to ``DIR_truth.json``; then ``fricenv gap diagnose DIR --out OUT --jobs 2``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from fricenv.gap.quarter_car.simulate import write_simulated_log
from fricenv.gap.quarter_car.validate import DURATION, categories, draw_case


def write_fleet(n: int, seed: int, out: Path) -> dict[str, dict]:
    """Write ``n`` logs to ``out`` and return the truth per file name."""
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    cats = categories()
    truth = {}
    for i in range(n):
        case = draw_case(cats[i % len(cats)], rng)
        name = f"log{i:03d}.csv"
        write_simulated_log(out / name, list(case.effects), case.road, case.driver, case.seed, DURATION,
                            comments=False)
        truth[name] = {"category": case.category, "effects": [e.name for e in case.effects], "seed": case.seed}
    return truth


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("n", type=int, help="number of logs")
    ap.add_argument("seed", type=int, help="seed of the case draws")
    ap.add_argument("out", type=Path, help="folder to write the logs to")
    args = ap.parse_args()
    truth = write_fleet(args.n, args.seed, args.out)
    (args.out.parent / f"{args.out.name}_truth.json").write_text(json.dumps(truth, indent=1))
    print(f"{args.n} logs in {args.out}")


if __name__ == "__main__":
    main()
