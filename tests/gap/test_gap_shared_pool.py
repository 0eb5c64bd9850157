"""The shared local pool of the gap tool (:func:`fricenv.gap.pool.shared_pool`): every map inside the block runs in
the same worker processes, results stay in task order, and an interrupt still ends the workers."""

import os
import signal
import threading
import time

import pytest

from fricenv.gap.pool import map_tasks, shared_pool


def _pid_after(pause: float) -> int:
    time.sleep(pause)
    return os.getpid()


def _square(x: int) -> int:
    return x * x


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


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
