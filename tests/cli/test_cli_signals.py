"""SIGTERM and Ctrl-C stop a command and its worker processes: one line, exit code 143 / 130, no child left."""

import multiprocessing
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fricenv.cli import main
from tests.cli.test_cli_errors import register_fake_verb

ROOT = Path(__file__).resolve().parents[2]


def _sleep_forever():
    time.sleep(600)


def _alive(pid: int) -> bool:
    """True if ``pid`` runs (a zombie does not count)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def _children(pid: int) -> list[int]:
    kids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except (FileNotFoundError, ProcessLookupError):
                continue
            if int(fields[1]) == pid:
                kids.append(int(entry.name))
    return kids


@pytest.mark.parametrize("signum, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_signal_stops_the_command_and_its_workers_in_process(monkeypatch, capsys, signum, code):
    workers = []

    def run(args):
        worker = multiprocessing.Process(target=_sleep_forever, daemon=True)
        worker.start()
        workers.append(worker)
        os.kill(os.getpid(), signum)
        time.sleep(60)  # interrupted by the handler
        raise AssertionError("the signal did not stop the command")

    register_fake_verb(monkeypatch, run)
    previous = signal.getsignal(signum)
    assert main(["fake"]) == code
    err = capsys.readouterr().err
    assert err == f"fricenv fake: interrupted by {signal.Signals(signum).name}; stopped\n"
    assert not workers[0].is_alive()
    assert signal.getsignal(signum) is previous  # main restores the handlers it replaced


def test_sigterm_stops_gap_diagnose_and_leaves_no_child(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    log = tmp_path / "log.csv"
    subprocess.run([sys.executable, "-m", "fricenv", "gap", "simulate", "--seed", "2", "--duration", "3",
                    "--effect", "brake_lag", "--param", "tau=0.04", "--out", str(log)],
                   check=True, cwd=ROOT, env=env, capture_output=True)
    proc = subprocess.Popen([sys.executable, "-m", "fricenv", "gap", "diagnose", str(log), "--jobs", "2",
                             "--out", str(tmp_path / "rep")], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 180
        kids: list[int] = []
        while not kids and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)
            kids = _children(proc.pid)
        assert kids, "gap diagnose --jobs 2 never started its worker processes"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 143, err
    # stage lines may come first (progress goes to stderr when it is not a terminal); the stop is the last line
    assert err.endswith("fricenv gap diagnose: interrupted by SIGTERM; stopped\n") and "Traceback" not in err, err
    assert not [k for k in kids if _alive(k)]
    assert not (tmp_path / "rep" / "report.json").exists()


def test_a_cleanup_error_during_the_interrupt_is_still_the_interrupt(monkeypatch, capsys):
    """A pool's shutdown interrupted half-way raises its own error while the interrupt unwinds: still exit 143."""

    def run(args):
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(60)
        finally:
            raise RuntimeError("cannot join thread before it is started")

    register_fake_verb(monkeypatch, run)
    assert main(["fake"]) == 143
    assert capsys.readouterr().err == "fricenv fake: interrupted by SIGTERM; stopped\n"


class _SignalInDel:
    """Sends SIGTERM from ``__del__``, where Python swallows any exception (as in an at-fork callback)."""

    def __del__(self):
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):  # give the handler its chance to run (and raise) inside __del__
            pass


def test_a_swallowed_interrupt_is_delivered_again(monkeypatch, capsys):
    def run(args):
        _SignalInDel()
        time.sleep(30)  # the redelivery interrupts this
        raise AssertionError("the swallowed interrupt was not delivered again")

    register_fake_verb(monkeypatch, run)
    assert main(["fake"]) == 143
    assert capsys.readouterr().err == "fricenv fake: interrupted by SIGTERM; stopped\n"


def test_children_unknown_to_multiprocessing_are_stopped_too(monkeypatch, capsys):
    started = []

    def run(args):
        started.append(subprocess.Popen(["sleep", "120"]))
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(30)

    register_fake_verb(monkeypatch, run)
    assert main(["fake"]) == 143
    assert started[0].poll() is not None or not _alive(started[0].pid)
    capsys.readouterr()
