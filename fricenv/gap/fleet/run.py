"""Fleet diagnosis: every log of a folder or glob pattern diagnosed, one report folder each, and a fleet summary.

``run_fleet(source, out, settings)`` writes ``OUT/<log stem>/`` (report.json, report.md, plots: the single-log
report) and ``OUT/fleet.json`` ``{"rows": [row, ...]}``, one row per log in file-name order (:data:`ROW_KEYS`),
then ``OUT/fleet.md`` and the fleet plots (:mod:`fricenv.gap.fleet.summary`).

* One bad log is a row with its ``error`` (verdict ``"error"``), never a stop.
* Resumable: a log whose report folder is complete (its report.json and its row file ``fleet_row.json``, written
  last) is skipped unless ``force``; ``fleet.json`` is rewritten atomically after every log, so a killed run loses
  at most the logs in flight, and a re-run finishes the rest. A failed log is retried by the next run.
* Parallel through :func:`fricenv.gap.core.pool.imap_tasks`: ``jobs`` local processes, or Ray (``ray="auto"`` or an
  address); each log is diagnosed in one process (its candidate fits in series), so the logs are the parallel unit.
  The rows do not depend on the backend (apart from ``seconds``).
"""

from __future__ import annotations

import glob
import json
import time
from dataclasses import dataclass, replace
from pathlib import Path

from fricenv.errors import InputFileError, InvalidInputError
from fricenv.gap.core.pool import default_jobs, imap_tasks
from fricenv.gap.plants import get_plant
from fricenv.utils import to_jsonable, write_json

__all__ = ["FLEET_JSON", "ROW_FILE", "ROW_KEYS", "FleetSettings", "diagnose_log", "find_logs", "is_complete",
           "is_fleet_source", "run_fleet"]

ROW_KEYS = ("file", "verdict", "effects", "gap_before", "gap_after", "params", "seconds", "error")
ROW_FILE = "fleet_row.json"  # a log's row, written after its report: its presence marks the report complete
FLEET_JSON = "fleet.json"
ERROR_VERDICT = "error"
NO_EFFECT_VERDICTS = ("none", "unexplained", ERROR_VERDICT)


@dataclass(frozen=True)
class FleetSettings:
    """How every log of a fleet is diagnosed and run.

    :param plant: ``"quarter-car"`` or ``"payload"`` (every log of the fleet).
    :param params_file: nominal plant parameters (JSON) for every log, or None for the paper's.
    :param config: the plant's diagnosis settings (:class:`fricenv.gap.quarter_car.diagnose.DiagnoseConfig` or
        :class:`fricenv.gap.payload.diagnose.PayloadDiagnoseConfig`; None: the defaults). A quarter-car log runs its
        candidate fits in its own process (``jobs=1``): the logs are the parallel unit.
    :param plots: write each log's PNG plots (the fleet plots are always written).
    :param force: diagnose again the logs whose report is already complete.
    :param jobs: local worker processes (None: up to 2); not used with ``ray``.
    :param ray: None (local processes), ``"auto"`` or a Ray cluster address.
    """

    plant: str = "quarter-car"
    params_file: str | None = None
    config: object | None = None
    plots: bool = True
    force: bool = False
    jobs: int | None = None
    ray: str | None = None


def is_fleet_source(source: str) -> bool:
    """Whether ``source`` names a fleet (a folder, or a glob pattern that is not an existing file's name)."""
    p = Path(source)
    return p.is_dir() or (not p.exists() and glob.has_magic(source))


def find_logs(source: str) -> list[Path]:
    """The logs of a fleet: a folder's ``*.csv`` files, or the files a glob pattern matches; sorted by path.

    :raises InputFileError: nothing matches.
    :raises InvalidInputError: two logs share a file stem (their report folders would collide).
    """
    pattern = str(Path(source) / "*.csv") if Path(source).is_dir() else source
    logs = sorted(Path(p) for p in glob.glob(pattern, recursive=True) if Path(p).is_file())
    if not logs:
        raise InputFileError(f"{source}: no log files found (a folder of *.csv logs or a quoted glob pattern)")
    seen: dict[str, Path] = {}
    for log in logs:
        if log.stem in seen:
            raise InvalidInputError(f"logs {seen[log.stem]} and {log} share the name {log.stem!r}, so their report "
                                    f"folders would collide; rename one or run them separately")
        seen[log.stem] = log
    return logs


def _read_row(folder: Path) -> dict | None:
    """The row a complete report folder holds, or None when the report is missing, partial or failed."""
    try:
        row = json.loads((folder / ROW_FILE).read_text())
    except (OSError, ValueError):
        return None
    ok = isinstance(row, dict) and set(ROW_KEYS) <= set(row) and row["error"] is None
    return row if ok and (folder / "report.json").is_file() else None


def is_complete(folder: str | Path) -> bool:
    """Whether a log's report folder holds a complete report (report.json, then its row, written last)."""
    return _read_row(Path(folder)) is not None


def _diagnose_and_write(log: Path, folder: Path, s: FleetSettings) -> tuple[dict, float]:
    """The plant's single-log diagnosis and report (as ``fricenv gap diagnose LOG``): (report dict, seconds).
    A plant whose fits run in worker processes runs them in this one: the fleet's workers are the parallelism."""
    plant = get_plant(s.plant)
    cfg = s.config or plant.make_config(None, None)
    if plant.parallel_fits:
        cfg = replace(cfg, jobs=1)
    dg = plant.diagnose_file(log, s.params_file, cfg)
    return plant.write_report(dg, folder, s.plots), dg.seconds


def diagnose_log(log: str, folder: str, s: FleetSettings) -> dict:
    """Diagnose one log into its report folder and return its row (any error becomes the row's ``error``).

    ``effects`` lists the verdict's effect (empty for ``none``, ``unexplained`` and errors); a joint fit's
    detail stays in the log's report.json (``where.joint_fit``).
    """
    t0 = time.perf_counter()
    try:
        report, seconds = _diagnose_and_write(Path(log), Path(folder), s)
    except Exception as exc:  # noqa: BLE001 - one bad log is a row with its error, never a stop
        return {"file": log, "verdict": ERROR_VERDICT, "effects": [], "gap_before": None, "gap_after": None,
                "params": {}, "seconds": time.perf_counter() - t0, "error": f"{type(exc).__name__}: {exc}"}
    verdict = report["verdict"]
    row = to_jsonable({"file": log, "verdict": verdict, "effects": [] if verdict in NO_EFFECT_VERDICTS else [verdict],
                       "gap_before": report["gap_before"], "gap_after": report["gap_after"],
                       "params": report["params"], "seconds": seconds, "error": None})
    write_json(Path(folder) / ROW_FILE, row)
    return row


def _write_rows(out: Path, logs: list[Path], rows: dict[Path, dict]) -> None:
    """fleet.json: the rows known so far, in log order (atomically)."""
    write_json(out / FLEET_JSON, {"rows": [rows[log] for log in logs if log in rows]})


def run_fleet(source: str, out: str | Path, settings: FleetSettings = FleetSettings()) -> dict:
    """Diagnose every log of ``source`` into ``out`` (see the module docstring) and write the fleet summary.

    Progress: one task ``"diagnose logs"`` with a step per log diagnosed (the skipped ones are not counted).

    :param source: a folder of ``*.csv`` logs or a glob pattern.
    :param out: output folder (created).
    :param settings: see :class:`FleetSettings`.
    :return: ``{"rows", "diagnosed", "skipped", "failed", "wall_seconds", "busy_seconds"}`` (``busy_seconds``: the
        diagnosed logs' summed diagnosis time).
    """
    out = Path(out)
    logs = find_logs(source)
    out.mkdir(parents=True, exist_ok=True)
    rows: dict[Path, dict] = {}
    for log in logs:
        row = None if settings.force else _read_row(out / log.stem)
        if row is not None:
            rows[log] = {**row, "file": str(log)}
    todo = [log for log in logs if log not in rows]
    _write_rows(out, logs, rows)
    t0 = time.perf_counter()
    tasks = [(str(log), str(out / log.stem), replace(settings, jobs=None, ray=None)) for log in todo]
    for i, row in imap_tasks(diagnose_log, tasks, default_jobs(settings.jobs), "diagnose logs", settings.ray):
        rows[todo[i]] = row
        _write_rows(out, logs, rows)
    wall = time.perf_counter() - t0
    ordered = [rows[log] for log in logs]
    from fricenv.gap.fleet.summary import write_fleet_summary

    write_fleet_summary(ordered, out)
    done = [rows[log] for log in todo]
    return {"rows": ordered, "diagnosed": len(todo), "skipped": len(logs) - len(todo),
            "failed": sum(r["error"] is not None for r in ordered), "wall_seconds": wall,
            "busy_seconds": sum(r["seconds"] for r in done)}
