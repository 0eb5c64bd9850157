"""The plumbing every blind measurement command shares (validation.independent_sim, validation.real_payload,
tests.outlier_check): its common options and its process pool."""

from __future__ import annotations

import argparse

__all__ = ["measurement_parser", "pool_map"]


def measurement_parser(description: str, n: int, seed: int) -> argparse.ArgumentParser:
    """The options every measurement command shares: ``--n``, ``--seed``, ``--jobs``, ``--json``."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--n", type=int, default=n, help="number of logs")
    ap.add_argument("--seed", type=int, default=seed, help="seed of the draw")
    ap.add_argument("--jobs", type=int, default=1, help="processes (one log each)")
    ap.add_argument("--json", default=None, help="write the summary and per-log results here")
    return ap


def pool_map(fn, tasks: list, jobs: int) -> list:
    """``[fn(t) for t in tasks]``, in ``jobs`` processes when more than one (``fn`` must be importable)."""
    from concurrent.futures import ProcessPoolExecutor

    if jobs <= 1:
        return [fn(t) for t in tasks]
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        return list(pool.map(fn, tasks))
