"""Progress of long library work, reported to whichever front end listens (the CLI installs a progress bar).

Library code (a diagnosis, a validation run) announces its phases with :func:`task` and never prints; with no
sink installed every call is a no-op, so tests and library users see nothing. The CLI installs a sink with
:func:`use_sink` for the duration of one command: progress bars on a terminal, :class:`LineSink` (plain stage and
progress lines on stderr) when the output goes to a file or a pipe, none with ``--quiet``.

    with progress.task("fit candidates", total=len(candidates)) as advance:
        for c in candidates:
            fit(c)
            advance()
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Protocol, TextIO

__all__ = ["LineSink", "ProgressSink", "task", "use_sink"]


class ProgressSink(Protocol):
    """What a front end implements to show progress."""

    def start(self, label: str, total: int | None) -> None:
        """A task begins; ``total`` steps, or None when unknown."""

    def advance(self, n: int) -> None:
        """``n`` more steps of the current task are done."""

    def finish(self) -> None:
        """The current task ended (normally or by an exception)."""


_sink: ProgressSink | None = None


@contextmanager
def use_sink(sink: ProgressSink | None) -> Iterator[None]:
    """Send the progress of the enclosed work to ``sink`` (None: discard it)."""
    global _sink
    previous, _sink = _sink, sink
    try:
        yield
    finally:
        _sink = previous


@contextmanager
def task(label: str, total: int | None = None) -> Iterator[Callable[[int], None]]:
    """Announce one task; yields ``advance(n=1)`` to report steps done.

    :param label: short name of the task, shown to the user (e.g. ``"fit brake_lag"``).
    :param total: number of steps, or None when unknown.
    """
    sink = _sink
    if sink is None:
        yield lambda n=1: None
        return
    sink.start(label, total)
    try:
        yield lambda n=1: sink.advance(n)
    finally:
        sink.finish()


class LineSink:
    """Progress as plain lines, for a log file or a pipe: a line when a top-level task starts and ends, and at most
    one ``label: done/total`` line every ``interval`` seconds for the innermost task. Events from another process
    (a forked worker inherits the sink) are ignored.

    :param prefix: put before every line (e.g. ``"fricenv paper ekf-rls"``).
    :param stream: where the lines go (default stderr).
    :param interval: least seconds between two progress lines.
    """

    def __init__(self, prefix: str = "", stream: TextIO | None = None, interval: float = 10.0):
        self._prefix = f"{prefix}: " if prefix else ""
        self._stream = stream
        self._interval = float(interval)
        self._tasks: list[list] = []  # [label, total, done, start time]
        self._last = time.monotonic()
        self._pid = os.getpid()

    def _line(self, text: str) -> None:
        stream = self._stream if self._stream is not None else sys.stderr
        print(f"{self._prefix}{text}", file=stream, flush=True)

    def start(self, label: str, total: int | None) -> None:
        if os.getpid() != self._pid:
            return
        self._tasks.append([label, total, 0, time.monotonic()])
        if len(self._tasks) == 1:
            self._line(f"{label}: started" + (f" ({total} steps)" if total else ""))
            self._last = time.monotonic()

    def advance(self, n: int) -> None:
        if os.getpid() != self._pid or not self._tasks:
            return
        task_ = self._tasks[-1]
        task_[2] += n
        now = time.monotonic()
        if now - self._last >= self._interval:
            label, total, done, t0 = task_
            self._line(f"{label}: {done}/{total if total else '?'} ({now - t0:.0f} s)")
            self._last = now

    def finish(self) -> None:
        if os.getpid() != self._pid or not self._tasks:
            return
        label, total, done, t0 = self._tasks.pop()
        if not self._tasks:
            self._line(f"{label}: done" + (f" {done}/{total}" if total else "") + f" in {time.monotonic() - t0:.0f} s")
