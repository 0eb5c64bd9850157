"""Ray as the engine beyond one machine: the same tasks and the same fleet rows on Ray as in the
local process pool, and no Ray instance left running by a run that started one."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fricenv import progress
from fricenv.gap.core.pool import map_tasks
from fricenv.gap.fleet.run import FLEET_JSON, FleetSettings, run_fleet
from tests.gap.fleet_helpers import FAST, simulate_fleet
from tests.gap.test_gap_pool import RecordingSink, _square_after

ray = pytest.importorskip("ray", reason="ray is a dependency of fricenv (pyproject.toml)")
pytestmark = pytest.mark.xdist_group("ray")  # one Ray instance at a time under `make test`'s two workers


def _ray_children() -> list[str]:
    """Command lines of this process' children that belong to a Ray instance (raylet, GCS server)."""
    import os

    names = []
    for path in Path(f"/proc/{os.getpid()}/task").glob("*/children"):
        for pid in path.read_text().split():
            try:
                names.append(Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace"))
            except OSError:
                continue
    return [n for n in names if "raylet" in n or "gcs_server" in n]


@pytest.mark.slow
def test_ray_started_here_gives_task_order_and_is_shut_down():
    assert not ray.is_initialized()
    sink = RecordingSink()
    with progress.use_sink(sink):
        assert map_tasks(_square_after, [(3, 0.2), (1, 0.0), (2, 0.1)], 1, "squares", ray="auto") == [9, 1, 4]
    assert sink.events[0] == ("start", "squares", 3)
    assert sink.events[1:] == [("advance", 1)] * 3 + [("finish",)]
    assert not ray.is_initialized()
    assert _ray_children() == []


@pytest.fixture
def local_ray():
    """A local Ray instance of 2 CPUs, started by the test and always shut down."""
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        yield ray
    finally:
        ray.shutdown()


def test_fleet_rows_identical_on_ray_and_in_the_process_pool(tmp_path, local_ray):
    simulate_fleet(tmp_path / "logs", 3)
    (tmp_path / "logs" / "bad.csv").write_text("t,T_b\n0,1\n")
    rows = {}
    for name, backend in (("pool", {"jobs": 2}), ("ray", {"ray": "auto"})):
        run_fleet(str(tmp_path / "logs"), tmp_path / name, FleetSettings(config=FAST, plots=False, **backend))
        rows[name] = [{k: v for k, v in r.items() if k != "seconds"}
                      for r in json.loads((tmp_path / name / FLEET_JSON).read_text())["rows"]]
    assert local_ray.is_initialized()  # the test's instance was used, and is the test's to shut down
    assert len(rows["ray"]) == 4 and [r["verdict"] for r in rows["ray"]] == ["error", "brake_gain", "brake_gain", "none"]
    assert rows["ray"] == rows["pool"]


KILLABLE = """
from fricenv.gap.core.pool import map_tasks
from tests.gap.test_gap_pool import _square_after
map_tasks(_square_after, [(2, 120.0)] * 2, 1, "sleep", ray="auto")
"""


def _descendants(pid: int) -> dict[int, str]:
    """pid -> command line of every process below ``pid``."""
    out: dict[int, str] = {}
    todo = [pid]
    while todo:
        for path in Path(f"/proc/{todo.pop()}/task").glob("*/children"):
            for child in map(int, path.read_text().split()):
                try:
                    out[child] = Path(f"/proc/{child}/cmdline").read_bytes().decode(errors="replace")
                except OSError:
                    continue
                todo.append(child)
    return out


def _running(pid: int) -> bool:
    """Alive and not a zombie."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def test_sigterm_during_a_ray_run_shuts_its_instance_down():
    import signal
    import subprocess
    import sys
    import time

    root = Path(__file__).resolve().parents[2]
    proc = subprocess.Popen([sys.executable, "-c", KILLABLE], cwd=root, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 180
        below: dict[int, str] = {}
        while not any(c.startswith("ray::_worker") for c in below.values()):  # Ray started and runs a task
            assert proc.poll() is None and time.monotonic() < deadline, "no Ray task started in 180 s"
            below = _descendants(proc.pid)
            time.sleep(0.1)
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGTERM  # the default handler ran, after Ray was shut down
    time.sleep(1)
    assert any("raylet" in c for c in below.values())
    assert [c for p, c in below.items() if _running(p)] == []  # the raylet, GCS, agents and workers all ended
