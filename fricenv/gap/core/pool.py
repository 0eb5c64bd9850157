"""The one parallel map of the gap tool: tasks mapped in a local process pool or on a Ray cluster, progress reported
through :mod:`fricenv.progress`, and the workers stopped when the main process is interrupted (no orphans after
Ctrl-C, no Ray instance left running).

Backends (``ray`` argument of :func:`map_tasks` / :func:`imap_tasks`):

* ``None``: ``jobs`` local worker processes (one process: in this one), as before Ray.
* ``"auto"``: Ray; an instance this process already joined, else the cluster named by ``RAY_ADDRESS`` or started
  with ``ray start`` on this machine, else a local instance started here (and shut down at the end).
* an address (``"ray://head:10001"``, ``"10.0.0.5:6379"``): that Ray cluster (``ray.init(address=...)``).

Ray is imported only when asked for, so ``import fricenv`` does not pay for it. On a cluster every node needs
fricenv installed (same version) and the input and output paths the tasks name (a shared file system).
"""

from __future__ import annotations

import os
import signal
import threading
import warnings
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from contextlib import contextmanager

from fricenv import progress
from fricenv.errors import InvalidInputError

__all__ = ["RAY_AUTO", "default_jobs", "imap_tasks", "map_tasks", "ray_session", "shared_pool", "start_tasks"]

RAY_AUTO = "auto"  # --ray value: join a running Ray instance or cluster, else start one in this process
WAIT_S = 0.5  # longest wait on Ray between checks for an interrupt [s]
# The local pool that :func:`shared_pool` keeps open: (owner pid, executor); a forked child sees its parent's entry
# and ignores it (the pid differs).
_SHARED: dict = {}


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


def _import_ray():
    """The ray module, imported now (never at ``import fricenv``)."""
    try:
        import ray
    except ImportError:  # pragma: no cover - ray is a dependency
        raise InvalidInputError("--ray needs the ray package: pip install ray") from None
    return ray


class _Stopped(Exception):
    """SIGINT or SIGTERM arrived during a Ray session (raised by its ``check``, handled by :func:`ray_session`)."""


def _no_check() -> None:
    """The ``check`` of a Ray session this process does not own: signals take their usual course."""


class _HeldSignals:
    """SIGINT and SIGTERM held during a Ray session (see :func:`_held_signals`)."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self):
        self.got: list[int] = []
        self.previous = {sig: signal.getsignal(sig) for sig in self.SIGNALS}

    def install(self) -> None:
        """Record the signals from now on (again after ``ray.init``, which installs its own handlers)."""
        for sig in self.SIGNALS:
            signal.signal(sig, lambda signum, frame: self.got.append(signum))

    def check(self) -> None:
        """Raise :class:`_Stopped` if a signal arrived."""
        if self.got:
            raise _Stopped(signal.Signals(self.got[0]).name)

    def release(self) -> None:
        """Restore the previous handlers and deliver the first signal that arrived to them."""
        for sig, handler in self.previous.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)
        if self.got:
            signal.raise_signal(self.got[0])


@contextmanager
def _held_signals():
    """Hold SIGINT and SIGTERM during a Ray session; yields a :class:`_HeldSignals` (None outside the main thread).

    ``ray.init`` installs handlers that exit or abort the process, and a front end's handler may kill Ray's processes
    under the driver (which then exits). Instead the signal is recorded, ``check()`` raises :class:`_Stopped` in the
    loop that waits on Ray, and after Ray is shut down the old handlers are restored and the signal is delivered to
    them (the CLI's: exit 130 / 143; the defaults: KeyboardInterrupt, or the end of the process).
    """
    if threading.current_thread() is not threading.main_thread():
        yield None
        return
    held = _HeldSignals()
    held.install()
    try:
        yield held
    finally:
        held.release()


def _init(ray, address: str, held: _HeldSignals | None) -> None:
    """``ray.init`` for ``address``, then the held signals' handlers installed again. A SIGTERM while Ray starts
    meets Ray's own handler (``sys.exit(15)``, installed first thing): it is recorded as held, then stops the run."""
    kwargs = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False}
    try:
        ray.init(**kwargs) if address == RAY_AUTO else ray.init(address=address, **kwargs)
    except SystemExit as exc:
        if held is None or exc.code != signal.SIGTERM:
            raise
        held.got.append(signal.SIGTERM)
        raise _Stopped("SIGTERM") from None
    if held is not None:
        held.install()


@contextmanager
def ray_session(address: str):
    """Yield ``(ray module, check)`` joined to ``address`` (``"auto"`` or a cluster address, see the module
    docstring); ``check()`` raises when SIGINT or SIGTERM arrived (call it while waiting on Ray).

    If Ray is already initialised in this process it is used as it is and left running (its owner shuts it down);
    otherwise this call connects (or starts a local instance) and always shuts it down at the end, before an
    interrupt that arrived meanwhile is delivered.

    :param address: ``"auto"`` or a Ray address.
    """
    if not address or not isinstance(address, str):
        raise InvalidInputError(f"--ray must be 'auto' or a Ray cluster address, got {address!r}")
    ray = _import_ray()
    if ray.is_initialized():
        yield ray, _no_check
        return
    with _held_signals() as held:
        try:
            _init(ray, address, held)
            yield ray, held.check if held else _no_check  # a _Stopped passes: the signal replaces it after shutdown
        finally:
            ray.shutdown()


def _serial(fn: Callable, tasks: Sequence[tuple]) -> Iterator[tuple[int, object]]:
    """The tasks in this process, in order."""
    for i, t in enumerate(tasks):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            yield i, fn(*t)


@contextmanager
def shared_pool(jobs: int):
    """Keep ``jobs`` local worker processes for every :func:`map_tasks` / :func:`imap_tasks` of this process inside
    the block (one start of the workers instead of one per map: a diagnosis maps its fits several times). Nested
    blocks and ``jobs <= 1`` add nothing.

    :param jobs: worker processes.
    """
    if jobs <= 1 or _shared() is not None:
        yield
        return
    pool = ProcessPoolExecutor(max_workers=jobs)
    _SHARED["pool"] = (os.getpid(), pool)
    try:
        yield
    finally:
        _SHARED.pop("pool", None)
        pool.shutdown(wait=True, cancel_futures=True)


def _shared() -> ProcessPoolExecutor | None:
    """This process's pool kept by :func:`shared_pool`, if any."""
    pid, pool = _SHARED.get("pool", (None, None))
    return pool if pid == os.getpid() else None


def _local(fn: Callable, tasks: Sequence[tuple], jobs: int) -> Iterator[tuple[int, object]]:
    """The tasks in ``jobs`` worker processes (those of :func:`shared_pool` when one is open), as they complete; the
    workers terminated on any exit but the end (a shared pool is then closed for the rest of its block)."""
    shared = _shared()
    pool = shared if shared is not None else ProcessPoolExecutor(max_workers=min(jobs, len(tasks)))
    try:
        index = {pool.submit(_worker, (fn, t)): i for i, t in enumerate(tasks)}
        pending = set(index)
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for f in sorted(done, key=index.get):
                yield index[f], f.result()
    except BaseException:  # includes GeneratorExit: the consumer stopped early
        if shared is not None:
            _SHARED.pop("pool", None)
        _terminate(pool)
        raise
    if shared is None:
        pool.shutdown(wait=True)


def _on_ray(fn: Callable, tasks: Sequence[tuple], address: str) -> Iterator[tuple[int, object]]:
    """The tasks as Ray tasks (one CPU each), as they complete; the unfinished ones cancelled on any early exit."""
    with ray_session(address) as (ray, check):
        remote = ray.remote(num_cpus=1, max_retries=0)(_worker)
        index = {remote.remote((fn, t)): i for i, t in enumerate(tasks)}
        pending = list(index)
        try:
            while pending:
                check()
                done, pending = ray.wait(pending, num_returns=1, timeout=WAIT_S)
                for ref in done:
                    yield index[ref], ray.get(ref)
        except BaseException:
            for ref in pending:
                ray.cancel(ref, force=True)
            raise


def imap_tasks(fn: Callable, tasks: Sequence[tuple], jobs: int, label: str,
               ray: str | None = None) -> Iterator[tuple[int, object]]:
    """``(i, fn(*tasks[i]))`` for every task, in completion order (task order in one process).

    Progress: one task ``label`` of ``len(tasks)`` steps (a front end shows steps done and the time left). On
    KeyboardInterrupt or SystemExit (or any error, or the consumer closing the iterator) the workers are stopped
    before the exception propagates.

    :param fn: a picklable (module-level) function; :param tasks: its argument tuples.
    :param jobs: local processes (1: in this one); not used with ``ray`` (Ray schedules one CPU per task).
    :param label: progress label. :param ray: None (local processes), ``"auto"`` or a Ray address.
    """
    if ray is not None:
        runner = _on_ray(fn, tasks, ray)
    elif jobs <= 1 or len(tasks) <= 1:
        runner = _serial(fn, tasks)
    else:
        runner = _local(fn, tasks, jobs)
    with progress.task(label, total=len(tasks)) as advance:
        try:
            for item in runner:
                yield item
                advance()
        finally:
            runner.close()


def map_tasks(fn: Callable, tasks: Sequence[tuple], jobs: int, label: str, ray: str | None = None) -> list:
    """``[fn(*t) for t in tasks]`` through :func:`imap_tasks`; results in task order.

    :param fn: a picklable function; :param tasks: its argument tuples; :param jobs: processes (1: in this one).
    :param label: progress label. :param ray: None (local processes), ``"auto"`` or a Ray address.
    """
    out: list = [None] * len(tasks)
    for i, result in imap_tasks(fn, tasks, jobs, label, ray):
        out[i] = result
    return out


def start_tasks(fn: Callable, tasks: Sequence[tuple], jobs: int, label: str) -> Callable[[], list]:
    """Start ``[fn(*t) for t in tasks]`` now, in the workers of an open :func:`shared_pool`, so that this process can
    do other work meanwhile; returns ``collect()``, which waits and returns the results in task order. Without a
    shared pool (or with ``jobs <= 1``) the tasks run in ``collect()`` through :func:`map_tasks`.

    :param fn: a picklable function; :param tasks: its argument tuples; :param jobs: processes; :param label: progress
        label of the wait.
    """
    pool = _shared()
    if pool is None or jobs <= 1 or len(tasks) <= 1:
        return lambda: map_tasks(fn, tasks, jobs, label)
    futures = [pool.submit(_worker, (fn, t)) for t in tasks]

    def collect() -> list:
        try:
            with progress.task(label, total=len(futures)) as advance:
                out = []
                for f in futures:
                    out.append(f.result())
                    advance()
                return out
        except BaseException:  # the workers are stopped as in _local
            _SHARED.pop("pool", None)
            _terminate(pool)
            raise

    return collect
