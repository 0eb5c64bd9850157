"""Fleet diagnosis: every log of a folder or glob, one report folder each, fleet.json rows in file
order, a bad log as an error row, resumable after a kill (SIGTERM), --force, and the CLI's fleet options."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fricenv.cli import main
from fricenv.errors import InputFileError, InvalidInputError
from fricenv.gap.fleet.run import (
    FLEET_JSON,
    ROW_KEYS,
    FleetSettings,
    find_logs,
    is_complete,
    is_fleet_source,
    run_fleet,
)
from fricenv.gap.fleet.summary import PLOT_GAPS, PLOT_PARAMS, PLOT_VERDICTS
from tests.gap.fleet_helpers import FAST, GAIN, simulate_fleet

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def fleet_dir(tmp_path_factory) -> Path:
    """Three small logs (brake_gain, brake_gain, none) and one unreadable one."""
    folder = tmp_path_factory.mktemp("fleet") / "logs"
    simulate_fleet(folder, 3)
    (folder / "bad.csv").write_text("t,T_b\n0,1\n")
    return folder


def _rows(out: Path) -> list[dict]:
    return json.loads((out / FLEET_JSON).read_text())["rows"]


def test_find_logs_folder_glob_and_errors(tmp_path):
    for name in ("b.csv", "a.csv", "notes.txt"):
        (tmp_path / name).write_text("x")
    assert find_logs(str(tmp_path)) == [tmp_path / "a.csv", tmp_path / "b.csv"]
    assert find_logs(str(tmp_path / "b*")) == [tmp_path / "b.csv"]
    assert is_fleet_source(str(tmp_path)) and is_fleet_source(str(tmp_path / "*.csv"))
    assert not is_fleet_source(str(tmp_path / "a.csv"))
    with pytest.raises(InputFileError, match="no log files found"):
        find_logs(str(tmp_path / "*.parquet"))
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "a.csv").write_text("x")
    with pytest.raises(InvalidInputError, match="share the name 'a'"):
        find_logs(str(tmp_path / "**" / "*.csv"))


def test_fleet_rows_errors_resume_and_force(fleet_dir, tmp_path):
    out = tmp_path / "out"
    s = run_fleet(str(fleet_dir), out, FleetSettings(config=FAST, jobs=2, plots=False))
    rows = _rows(out)
    assert rows == s["rows"]
    assert [Path(r["file"]).name for r in rows] == ["bad.csv", "log_00.csv", "log_01.csv", "log_02.csv"]
    assert all(tuple(r) == ROW_KEYS for r in rows)
    bad, lag0, lag1, none = rows
    assert bad["verdict"] == "error" and "at least 3 data rows" in bad["error"] and not is_complete(out / "bad")
    for r in (lag0, lag1):
        assert r["verdict"] == "brake_gain" and r["effects"] == ["brake_gain"] and r["error"] is None
        assert abs(r["params"]["gain"] - GAIN) < 0.15 * GAIN
        assert r["gap_after"] < r["gap_before"]
        report = json.loads((out / Path(r["file"]).stem / "report.json").read_text())
        assert (report["verdict"], report["params"]) == (r["verdict"], r["params"])
    assert none["verdict"] == "none" and none["effects"] == [] and none["params"] == {}
    assert (s["diagnosed"], s["skipped"], s["failed"]) == (4, 0, 1)
    md = (out / "fleet.md").read_text()
    assert "| `brake_gain` | 2 | 50% |" in md and "| `brake_gain` | gain | 2 |" in md and "LogFormatError" in md
    assert all((out / name).stat().st_size > 0 for name in (PLOT_VERDICTS, PLOT_PARAMS, PLOT_GAPS))

    again = run_fleet(str(fleet_dir), out, FleetSettings(config=FAST, jobs=1, plots=False))
    assert (again["diagnosed"], again["skipped"]) == (1, 3)  # only the failed log is tried again
    assert again["rows"][1:] == rows[1:]  # the skipped rows as they were, seconds included
    forced = run_fleet(str(fleet_dir), out, FleetSettings(config=FAST, jobs=1, plots=False, force=True))
    assert (forced["diagnosed"], forced["skipped"]) == (4, 0)
    strip = [{k: v for k, v in r.items() if k != "seconds"} for r in rows]
    assert [{k: v for k, v in r.items() if k != "seconds"} for r in forced["rows"]] == strip


KILLABLE = """
import sys
from fricenv.gap.fleet.run import FleetSettings, run_fleet
from tests.gap.fleet_helpers import FAST
run_fleet(sys.argv[1], sys.argv[2], FleetSettings(config=FAST, jobs=1, plots=False))
"""


def test_killed_fleet_run_resumes_without_losing_or_repeating_a_log(tmp_path):
    logs = simulate_fleet(tmp_path / "logs", 5)
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-c", KILLABLE, str(tmp_path / "logs"), str(out)], cwd=ROOT)
    try:
        deadline = time.monotonic() + 300
        while not ((out / FLEET_JSON).exists() and _rows(out)) and proc.poll() is None:
            assert time.monotonic() < deadline, "no log finished in 300 s"
            time.sleep(0.02)
        proc.send_signal(signal.SIGTERM)  # after the first log, while the next one runs
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGTERM
    before = _rows(out)
    assert 1 <= len(before) < len(logs)
    s = run_fleet(str(tmp_path / "logs"), out, FleetSettings(config=FAST, jobs=1, plots=False))
    assert s["skipped"] == len(before) and s["diagnosed"] == len(logs) - len(before)
    rows = _rows(out)
    assert [r["file"] for r in rows] == [str(p) for p in logs]  # every log once, in order
    assert all(r["error"] is None and is_complete(out / p.stem) for r, p in zip(rows, logs))


def test_cli_fleet_options(fleet_dir, tmp_path, capsys):
    log = fleet_dir / "log_00.csv"
    assert main(["gap", "diagnose", str(log), "--out", str(tmp_path / "a"), "--ray", "auto"]) == 2
    assert "--ray applies to a fleet" in capsys.readouterr().err
    assert main(["gap", "diagnose", str(fleet_dir), "--out", str(tmp_path / "b"), "--json", str(tmp_path / "r.json")]) == 2
    assert "--json applies to a single log" in capsys.readouterr().err
    assert main(["gap", "diagnose", str(tmp_path / "none" / "*.csv"), "--out", str(tmp_path / "c")]) == 2
    assert "no log files found" in capsys.readouterr().err
    assert main(["gap", "diagnose", str(tmp_path / "missing.csv"), "--out", str(tmp_path / "d")]) == 2
    assert "missing.csv: no such file" in capsys.readouterr().err
    assert not any((tmp_path / d).exists() for d in "abcd")
    assert main(["gap", "validate", "--plant", "payload", "--n", "1", "--ray", "auto"]) == 2
    assert "--ray applies to --plant quarter-car" in capsys.readouterr().err


def test_import_fricenv_does_not_import_ray():
    code = "import sys, fricenv, fricenv.gap.core.pool, fricenv.gap.fleet.run; sys.exit('ray' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], cwd=ROOT, check=False).returncode == 0
