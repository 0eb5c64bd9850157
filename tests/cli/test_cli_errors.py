"""The CLI's one error path: every bad input gives exit code 2, one line on stderr, no traceback, and no
output file; paths are checked before the work starts; a bug keeps its traceback."""

import errno
import json
import os
import sys
import types

import pytest

from fricenv import cli
from fricenv.cli import main
from fricenv.errors import FricenvError, InvalidInputError, OutputPathError, is_user_error


@pytest.fixture(scope="module")
def small_log(tmp_path_factory):
    """A short simulated quarter-car log (2 s)."""
    path = tmp_path_factory.mktemp("log") / "log.csv"
    assert main(["gap", "simulate", "--seed", "1", "--duration", "2", "--out", str(path)]) == 0
    return path


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.count("\n") == 1 and err.endswith("\n"), err
    return err


def _files(root) -> set:
    return {p.relative_to(root) for p in root.rglob("*")}


def _no_diagnosis(monkeypatch):
    """Make any diagnosis fail loudly: a test passing with it proves the error came before the long work."""
    from fricenv.gap.quarter_car import diagnose

    def started(*args, **kwargs):
        raise AssertionError("the diagnosis started before the bad input was reported")

    monkeypatch.setattr(diagnose, "diagnose", started)


def _bad_input_cases(tmp_path, log):
    """(argv, text the one-line message must hold) for every bad-input case."""
    a_file = tmp_path / "a_file.txt"
    a_file.write_text("keep\n")
    bad_json = tmp_path / "bad.json"
    bad_json.write_text("{not json")
    list_json = tmp_path / "list.json"
    list_json.write_text("[1, 2]")
    out = str(tmp_path / "out")
    return [
        (["gap", "diagnose", str(log), "--out", str(a_file)], "is a file, expected a directory"),
        (["gap", "diagnose", str(log), "--out", str(a_file / "sub")], "is a file, not a directory"),
        (["gap", "diagnose", str(log), "--out", out, "--json", str(tmp_path)], "is a directory, expected a file"),
        (["gap", "diagnose", str(log), "--out", out, "--params", str(tmp_path / "none.json")], "no such file"),
        (["gap", "diagnose", str(log), "--out", out, "--params", str(bad_json)], "not valid JSON"),
        (["gap", "diagnose", str(log), "--out", out, "--params", str(list_json)], "expected a JSON object"),
        (["gap", "diagnose", str(tmp_path / "none.csv"), "--out", out], "no such file"),
        (["gap", "diagnose", str(tmp_path), "--out", out], "no log files found"),
        (["gap", "diagnose", str(log), "--out", out, "--plant", "bicycle"], "valid plants: quarter-car, payload"),
        (["gap", "diagnose", str(log), "--out", out, "--jobs", "0"], "--jobs must be >= 1"),
        (["gap", "diagnose", str(log), "--out", out, "--candidates", "nope"], "unknown candidate effect(s) nope"),
        (["gap", "simulate", "--effect", "nope", "--out", out], "unknown effect 'nope'; valid effects:"),
        (["gap", "simulate", "--road", "gravel", "--out", out], "unknown road 'gravel'; valid roads:"),
        (["gap", "simulate", "--driver", "foo", "--out", out], "unknown driver 'foo'; valid drivers: abs"),
        (["gap", "simulate", "--v0", "-5", "--out", out], "--v0 must be a speed"),
        (["gap", "simulate", "--duration", "0", "--out", out], "--duration must be"),
        (["gap", "simulate", "--effect", "brake_lag", "--param", "tau=x", "--out", out], "is not a number"),
        (["gap", "simulate", "--out", str(tmp_path)], "is a directory, expected a file"),
        (["gap", "simulate", "--plant", "payload", "--wrench", "square", "--out", out], "--wrench"),
        (["gap", "validate", "--n", "0"], "--n must be >= 1"),
        (["gap", "policy", "rule-abs", "--effect", "brake_lag", "--report", str(tmp_path / "none.json")],
         "no such file"),
        (["demo", "--v0", "-5", "--out", out], "--v0: v0 must be finite"),
        (["demo", "--roads", "gravel", "--out", out], "unknown road 'gravel'"),
        (["demo", "--out", str(a_file)], "is a file, expected a directory"),
        (["bench", "env", "--repeats", "0"], "--repeats and --steps must be >= 1"),
        (["paper", "fms", "--seeds", "0", "--out", out], "--seeds >= 1"),
        (["excitation", "--noise-scale", "-1"], "--noise-scale"),
        (["excitation", "--episodes", "1", "--json", str(a_file / "x.json")], "is a file, not a directory"),
        (["train", "--steps", "0", "--out", out], "--steps must be >= 1"),
        (["evaluate", "--seeds", "0", "--out", out], "--seeds must be >= 1"),
        (["bogus"], "invalid choice: 'bogus'"),
        (["gap", "simulate", "--seed", "x", "--out", out], "invalid int value: 'x'"),
    ]


def test_every_bad_input_is_one_line_exit_2_and_writes_nothing(tmp_path, small_log, capsys, monkeypatch):
    _no_diagnosis(monkeypatch)
    cases = _bad_input_cases(tmp_path, small_log)
    before = _files(tmp_path)
    for argv, expected in cases:
        assert main(argv) == 2, argv
        err = _one_line_error(capsys)
        assert expected in err, (argv, err)
        assert err.startswith("fricenv"), err
        assert _files(tmp_path) == before, argv
    assert (tmp_path / "a_file.txt").read_text() == "keep\n"


def test_unwritable_out_is_reported_before_the_diagnosis(tmp_path, small_log, capsys, monkeypatch):
    _no_diagnosis(monkeypatch)
    parent = tmp_path / "locked"
    parent.mkdir()
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode: False if str(p) == str(parent) else real_access(p, mode))
    assert main(["gap", "diagnose", str(small_log), "--out", str(parent / "rep")]) == 2
    assert f"directory {parent} is not writable" in _one_line_error(capsys)
    assert list(parent.iterdir()) == []


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write a directory whatever its mode")
def test_read_only_directory_is_reported(tmp_path, small_log, capsys):
    parent = tmp_path / "ro"
    parent.mkdir(mode=0o555)
    assert main(["gap", "diagnose", str(small_log), "--out", str(parent / "rep")]) == 2
    assert "is not writable" in _one_line_error(capsys)


def test_version(capsys):
    from importlib.metadata import version

    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"fricenv {version('fricenv')}"


def register_fake_verb(monkeypatch, run, add_arguments=lambda parser: None) -> None:
    """Make ``fake`` the only verb of the CLI, running ``run(args)`` (also used by the other test_cli_* files)."""
    module = types.ModuleType("fake_verb")
    module.__doc__ = "A verb for tests."
    module.add_arguments = add_arguments
    module.run = run
    monkeypatch.setitem(sys.modules, "fake_verb", module)
    monkeypatch.setattr(cli, "VERBS", {("fake", None): "fake_verb"})


@pytest.mark.parametrize("exc", [ValueError("x must be > 0"), TypeError("unsupported operand"),
                                 KeyError("k"), OSError("no filename")])
def test_a_bug_keeps_its_traceback(monkeypatch, exc):
    def run(args):
        raise exc

    register_fake_verb(monkeypatch, run)
    with pytest.raises(type(exc)):
        main(["fake"])


@pytest.mark.parametrize("exc, expected", [
    (InvalidInputError("--x must be > 0"), "fricenv fake: error: --x must be > 0"),
    (OSError(errno.ENOSPC, "No space left on device", "/data/out.csv"),
     "fricenv fake: error: /data/out.csv: No space left on device"),
    (SystemExit("fricenv fake: --steps must be >= 1\n(really)"), "fricenv fake: error: --steps must be >= 1 (really)"),
    (SystemExit("--seeds must be >= 1"), "fricenv fake: error: --seeds must be >= 1"),
])
def test_user_errors_from_anywhere_are_one_line(monkeypatch, capsys, exc, expected):
    def run(args):
        raise exc

    register_fake_verb(monkeypatch, run)
    assert main(["fake"]) == 2
    assert _one_line_error(capsys).strip() == expected


def test_known_domain_errors_are_user_errors():
    from fricenv.plants.tire import UnknownRoadError, get_road

    with pytest.raises(UnknownRoadError) as info:
        get_road("gravel")
    assert is_user_error(info.value)
    assert not is_user_error(ValueError("math domain error"))
    assert is_user_error(OutputPathError("--out x: is a file"))
    assert isinstance(OutputPathError("x"), OSError) and isinstance(InvalidInputError("x"), ValueError)
    assert issubclass(InvalidInputError, FricenvError)


def test_log_format_error_is_in_the_family(tmp_path):
    from fricenv.logs import LogFormatError, read_log

    with pytest.raises(LogFormatError) as info:
        read_log(tmp_path / "absent.csv")
    assert isinstance(info.value, InvalidInputError) and isinstance(info.value, ValueError)


def test_no_plots_report_has_no_image_links(tmp_path, small_log):
    """--no-plots: no PNG written and report.md links none (stale plots of an earlier run included)."""
    out = tmp_path / "rep"
    out.mkdir()
    (out / "residual_time.png").write_bytes(b"old")  # a previous run's plot
    assert main(["gap", "diagnose", str(small_log), "--out", str(out), "--no-plots", "--candidates",
                 "brake_lag", "--jobs", "1"]) == 0
    md = (out / "report.md").read_text()
    assert ".png" not in md, "report.md links plots that --no-plots did not write"
    report = json.loads((out / "report.json").read_text())
    assert report["verdict"]


def test_closed_stdout_ends_quietly(monkeypatch, capsys):
    def run(args):
        raise BrokenPipeError(32, "Broken pipe")

    register_fake_verb(monkeypatch, run)
    assert main(["fake"]) == 141
    assert capsys.readouterr().err == ""
