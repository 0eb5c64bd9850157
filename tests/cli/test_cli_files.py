"""Files the CLI writes get the user's umask mode (0644 under umask 022), not mkstemp's 0600, and are atomic."""

import os
import stat

import numpy as np
import pytest

from fricenv.cli import main
from fricenv.logs import QuarterCarLog, write_log
from fricenv.utils import atomic_write, save_figure, write_json


@pytest.fixture(params=[0o022, 0o077, 0o002])
def umask(request):
    old = os.umask(request.param)
    yield request.param
    os.umask(old)


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def test_writers_use_the_umask(tmp_path, umask):
    expected = 0o666 & ~umask
    write_json(tmp_path / "a.json", {"x": 1})
    log = QuarterCarLog(t=np.arange(5) * 0.01, T_b=np.zeros(5), omega=np.full(5, 50.0))
    write_log(tmp_path / "log.csv", log)
    from matplotlib.figure import Figure

    save_figure(Figure(figsize=(1, 1)), tmp_path / "fig.png")
    for name in ("a.json", "log.csv", "fig.png"):
        assert _mode(tmp_path / name) == expected, name
    assert (tmp_path / "fig.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_outputs_are_0644_under_umask_022(tmp_path):
    old = os.umask(0o022)
    try:
        log, truth = tmp_path / "log.csv", tmp_path / "truth.json"
        assert main(["gap", "simulate", "--seed", "1", "--duration", "2", "--out", str(log),
                     "--json", str(truth)]) == 0
        assert main(["gap", "diagnose", str(log), "--out", str(tmp_path / "rep"), "--no-plots", "--jobs", "1",
                     "--candidates", "brake_lag", "--json", str(tmp_path / "r.json")]) == 0
    finally:
        os.umask(old)
    for path in (log, truth, tmp_path / "rep" / "report.json", tmp_path / "rep" / "report.md", tmp_path / "r.json"):
        assert _mode(path) == 0o644, path


def test_failed_write_leaves_nothing(tmp_path):
    with pytest.raises(RuntimeError), atomic_write(tmp_path / "x.json") as fh:
        fh.write("half")
        raise RuntimeError("interrupted")
    assert list(tmp_path.iterdir()) == []
