"""Worker processes of the gap tool: tasks mapped in order, progress reported through :mod:`fricenv.progress`,
and the workers terminated when the main process is interrupted (no orphans after Ctrl-C)."""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor

from fricenv import progress

__all__ = ["default_jobs", "map_tasks"]


def default_jobs(jobs: int | None) -> int:
    """``jobs`` if given (at least 1), else min(2, available cores)."""
    if jobs is not None:
        return max(int(jobs), 1)
    try:
        avail = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - non-Linux
        avail = os.cpu_count() or 1
    return max(min(2, avail), 1)


def _worker(job):
    """``(fn, args)`` -> ``fn(*args)`` in a worker process: RuntimeWarnings silenced, no progress sink (a forked
    worker inherits the parent's, which is the parent's to drive)."""
    fn, args = job
    with warnings.catch_warnings(), progress.use_sink(None):
        warnings.simplefilter("ignore", RuntimeWarning)
        return fn(*args)


def _terminate(pool: ProcessPoolExecutor) -> None:
    """End the worker processes now and cancel what has not started (the executor forgets its processes on
    shutdown, so they are taken first)."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    for proc in procs:
        if proc.is_alive():
            proc.terminate()
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        proc.join(timeout=5)


def map_tasks(fn: Callable, tasks: Sequence[tuple], jobs: int, label: str) -> list:
    """``[fn(*t) for t in tasks]``, in ``jobs`` worker processes when there are several tasks; results in task order.

    Progress: one task ``label`` of ``len(tasks)`` steps. On KeyboardInterrupt or SystemExit (or any error) in the
    main process the workers are terminated before the exception propagates.

    :param fn: a picklable function; :param tasks: its argument tuples; :param jobs: processes (1: in this one).
    """
    with progress.task(label, total=len(tasks)) as advance:
        if jobs <= 1 or len(tasks) <= 1:
            out = []
            for t in tasks:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)
                    out.append(fn(*t))
                advance()
            return out
        pool = ProcessPoolExecutor(max_workers=min(jobs, len(tasks)))
        try:
            futures = [pool.submit(_worker, (fn, t)) for t in tasks]
            out = []
            for f in futures:
                out.append(f.result())
                advance()
        except BaseException:
            _terminate(pool)
            raise
        pool.shutdown(wait=True)
        return out
