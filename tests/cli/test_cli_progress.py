"""The CLI's progress sink: a tqdm bar on stderr per fricenv.progress task, installed by main unless --quiet or
stdout is not a terminal (then plain stage lines, fricenv.progress.LineSink)."""

import io
import sys

import pytest

from fricenv import progress
from fricenv.cli import TqdmSink, main, progress_sink
from fricenv.utils import progress as progress_loop
from tests.cli.test_cli_errors import register_fake_verb


def test_sink_shows_a_fake_task_to_its_end():
    stream = io.StringIO()
    with progress.use_sink(TqdmSink(stream, mininterval=0)), progress.task("fit brake_lag", total=3) as advance:
        for _ in range(3):
            advance()
    text = stream.getvalue()
    assert "fit brake_lag" in text
    assert "3/3" in text and "4/3" not in text


def test_nested_tasks_advance_the_inner_bar_and_close_both():
    stream = io.StringIO()
    sink = TqdmSink(stream, mininterval=0)
    with progress.use_sink(sink), progress.task("diagnose", total=2) as outer:
        with progress.task("fit candidates", total=5) as inner:
            inner(5)
            assert [bar.n for bar in sink._bars] == [0, 5]
        outer()
        assert [bar.n for bar in sink._bars] == [1]
    assert sink._bars == []
    assert "fit candidates" in stream.getvalue() and "diagnose" in stream.getvalue()


def test_a_failing_task_closes_its_bar():
    sink = TqdmSink(io.StringIO())
    with progress.use_sink(sink), pytest.raises(RuntimeError), progress.task("fit", total=4) as advance:
        advance()
        raise RuntimeError("fit failed")
    assert sink._bars == []


def test_loop_helper_reports_each_item_through_the_sink():
    stream = io.StringIO()
    with progress.use_sink(TqdmSink(stream, mininterval=0)):
        assert list(progress_loop(range(7), desc="validate")) == list(range(7))
    assert "validate" in stream.getvalue() and "7/7" in stream.getvalue()
    assert list(progress_loop(iter([1, 2]), desc="x", disable=True)) == [1, 2]


def test_sink_choice():
    assert progress_sink(quiet=True, stdout_is_terminal=True) is None
    assert progress_sink(quiet=True, stdout_is_terminal=False) is None
    assert isinstance(progress_sink(quiet=False, stdout_is_terminal=False), progress.LineSink)
    assert isinstance(progress_sink(quiet=False, stdout_is_terminal=True), TqdmSink)


def test_line_sink_writes_stage_and_throttled_progress_lines(monkeypatch):
    clock = [0.0]
    monkeypatch.setattr(progress.time, "monotonic", lambda: clock[0])
    out = io.StringIO()
    sink = progress.LineSink("fricenv paper x", out, interval=10.0)
    with progress.use_sink(sink), progress.task("episodes", total=5) as advance:
        for _ in range(5):
            clock[0] += 4.0
            with progress.task("inner"):  # nested: no start or end line of its own
                pass
            advance()
    lines = out.getvalue().splitlines()
    assert lines[0] == "fricenv paper x: episodes: started (5 steps)"
    assert lines[1:-1] == ["fricenv paper x: episodes: 3/5 (12 s)"]  # one line per 10 s, not one per step
    assert lines[-1] == "fricenv paper x: episodes: done 5/5 in 20 s"


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.mark.parametrize("argv, terminal, shown, lines", [
    (["fake"], True, True, True),
    (["--quiet", "fake"], True, False, False),
    (["fake"], False, False, True),  # piped: no bars, but stage lines on stderr
])
def test_main_installs_the_sink_for_a_command(monkeypatch, capsys, argv, terminal, shown, lines):
    seen = {}

    def run(args):
        seen["show_progress"] = args.show_progress
        with progress.task("work", total=2) as advance:
            advance(2)
        return 0

    register_fake_verb(monkeypatch, run)
    if terminal:
        monkeypatch.setattr(sys, "stdout", _Terminal())
    assert main(argv) == 0
    assert seen["show_progress"] is shown
    assert ("work" in capsys.readouterr().err) is lines
