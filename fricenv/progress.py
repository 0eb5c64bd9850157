"""Progress of long library work, reported to whichever front end listens (the CLI installs a progress bar).

Library code (a diagnosis, a validation run) announces its phases with :func:`task` and never prints; with no
sink installed every call is a no-op, so tests and library users see nothing. The CLI installs a sink with
:func:`use_sink` for the duration of one command (and none with ``--quiet`` or when stdout is not a terminal).

    with progress.task("fit candidates", total=len(candidates)) as advance:
        for c in candidates:
            fit(c)
            advance()
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Protocol

__all__ = ["ProgressSink", "task", "use_sink"]


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
