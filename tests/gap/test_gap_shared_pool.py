"""The shared local pool of the gap tool (:func:`fricenv.gap.core.pool.shared_pool`): every map inside the block runs in
the same worker processes, results stay in task order, and an interrupt still ends the workers."""

import os
import signal
import threading
import time
from pathlib import Path

import pytest

from fricenv.gap.core.pool import map_tasks, shared_pool, start_tasks

from .test_gap_pool import _alive, ctrl_c_raises  # noqa: F401  (a fixture)


def _pid_after(pause: float) -> int:
    time.sleep(pause)
    return os.getpid()


def _square(x: int) -> int:
    return x * x


def test_maps_in_a_shared_pool_reuse_its_two_workers():
    with shared_pool(2):
        first = map_tasks(_pid_after, [(0.2,), (0.2,)], 2, "first")
        second = map_tasks(_pid_after, [(0.2,), (0.2,)], 2, "second")
        squares = map_tasks(_square, [(3,), (1,), (2,)], 2, "squares")
    assert squares == [9, 1, 4]
    assert len(set(first)) == 2 and set(second) == set(first)  # the same two processes, neither of them this one
    assert os.getpid() not in first
    assert not any(_alive(pid) for pid in first)  # shut down at the end of the block


def test_without_a_shared_pool_every_map_starts_its_own_workers():
    first = map_tasks(_pid_after, [(0.2,), (0.2,)], 2, "first")
    second = map_tasks(_pid_after, [(0.2,), (0.2,)], 2, "second")
    assert not set(first) & set(second)


@pytest.mark.usefixtures("ctrl_c_raises")
def test_interrupt_inside_a_shared_pool_ends_its_workers():
    main = threading.get_ident()
    with shared_pool(2):
        pids = map_tasks(_pid_after, [(0.0,), (0.3,)], 2, "pids")

        def interrupt_soon():
            time.sleep(0.5)
            signal.pthread_kill(main, signal.SIGINT)

        threading.Thread(target=interrupt_soon, daemon=True).start()
        with pytest.raises(KeyboardInterrupt):
            map_tasks(time.sleep, [(60,), (60,)], 2, "sleepers")
        assert map_tasks(_square, [(4,), (5,)], 2, "after") == [16, 25]  # a fresh pool: the shared one is closed
    time.sleep(0.2)
    assert not any(_alive(pid) for pid in set(pids))


def _write_pid(path: str) -> int:
    Path(path).write_text(str(os.getpid()))
    return os.getpid()


def test_started_tasks_run_before_collect_and_come_back_in_order(tmp_path):
    paths = [str(tmp_path / f"pid{i}") for i in range(3)]
    with shared_pool(2):
        collect = start_tasks(_write_pid, [(p,) for p in paths], 2, "started")
        deadline = time.monotonic() + 60.0  # a generous bound: the tasks only need to start
        while not all(os.path.exists(p) and os.path.getsize(p) for p in paths) and time.monotonic() < deadline:
            time.sleep(0.05)
        ran_before_collect = all(os.path.exists(p) for p in paths)
        pids = collect()
    assert ran_before_collect  # started in the workers while this process did something else
    assert pids == [int(Path(p).read_text()) for p in paths]  # in task order
    assert os.getpid() not in pids


def test_started_tasks_without_a_shared_pool_run_on_collect():
    collect = start_tasks(_square, [(3,), (1,), (2,)], 2, "squares")
    assert collect() == [9, 1, 4]
