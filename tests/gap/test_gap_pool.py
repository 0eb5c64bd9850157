"""Worker processes and progress of the gap tool: results in task order, progress steps reported through
fricenv.progress, and no worker left running when the main process is interrupted."""

import os
import signal
import threading
import time
from pathlib import Path

import pytest

from fricenv import progress
from fricenv.gap.core.pool import map_tasks


class RecordingSink:
    """A progress sink that records what it is told."""

    def __init__(self):
        self.events = []

    def start(self, label, total):
        self.events.append(("start", label, total))

    def advance(self, n):
        self.events.append(("advance", n))

    def finish(self):
        self.events.append(("finish",))


def _square_after(x: int, pause: float) -> int:
    time.sleep(pause)
    return x * x


def _write_pid_and_sleep(path: str) -> None:
    Path(path).write_text(str(os.getpid()))
    time.sleep(120)


@pytest.mark.parametrize("jobs", [1, 2])
def test_results_in_task_order_and_one_progress_step_per_task(jobs):
    sink = RecordingSink()
    tasks = [(3, 0.2), (1, 0.0), (2, 0.1)]  # the first finishes last in two workers
    with progress.use_sink(sink):
        assert map_tasks(_square_after, tasks, jobs, "squares") == [9, 1, 4]
    assert sink.events[0] == ("start", "squares", 3)
    assert sink.events[1:] == [("advance", 1)] * 3 + [("finish",)]


@pytest.fixture
def ctrl_c_raises():
    """SIGINT raises KeyboardInterrupt during the test, as in an interactive shell. A process started in the background
    (``nohup``, ``&``) inherits SIGINT ignored, and Python then installs no handler: the interrupt tests would
    send a signal nobody hears."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.mark.usefixtures("ctrl_c_raises")
def test_interrupt_terminates_the_worker_processes(tmp_path):
    """Ctrl-C in the main process while two workers sleep: the KeyboardInterrupt propagates and both workers are
    gone (terminated, not left to finish their two-minute task)."""
    paths = [str(tmp_path / f"pid{i}") for i in range(2)]
    main = threading.get_ident()

    def interrupt_when_started():
        while not all(os.path.exists(p) and os.path.getsize(p) for p in paths):
            time.sleep(0.05)
        signal.pthread_kill(main, signal.SIGINT)

    threading.Thread(target=interrupt_when_started, daemon=True).start()
    with pytest.raises(KeyboardInterrupt):
        map_tasks(_write_pid_and_sleep, [(p,) for p in paths], 2, "sleepers")
    pids = [int(Path(p).read_text()) for p in paths]
    assert not any(_alive(pid) for pid in pids)
