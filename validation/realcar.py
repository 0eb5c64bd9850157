"""The racecar session through the whole gap path, with the column map and parameters committed in validation/maps:
``fricenv gap diagnose EXPORT --map MAP --params PARAMS --out DIR``, timed, and its report checked against figures
read from the raw export independently of the tool (numpy on the CSV):

- every braking event (the brake above 0 and the throttle at 0, above 5 m/s, for 1 s or more) is found;
- the held-out ``gap_after / gap_before`` of the pooled diagnosis is at most 0.5;
- the mapped wheel's ``r_eff`` agrees within 0.3 % with ``r vx / wheel speed``, the median over the samples with
  brake 0, throttle 0, |yaw rate| < 0.02 rad/s and vx > 10 m/s;
- the command takes 60 s or less.

Run from anywhere: ``python -m validation.realcar [--export CSV] [--out DIR]`` (from the repository root) or
``python /path/to/validation/realcar.py``. The export is GPL-3.0 data: it is read from ``../shared/realdata/av21``
beside the repository (or ``--export``), never copied into it. Exit code 0 when every target holds, 1 otherwise,
2 when the export is absent.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MAPS = ROOT / "validation" / "maps"
EXPORT_NAME = "LVMS_23_01_04_B.csv"
CANDIDATES = (ROOT.parent / "shared" / "realdata" / "av21" / EXPORT_NAME,
              Path("/work/shared/realdata/av21") / EXPORT_NAME)
TARGETS = {"ratio": 0.5, "radius_rel": 3e-3, "seconds": 60.0}
MIN_SPEED, MIN_DURATION = 5.0, 1.0  # a braking event [m/s], [s]
ROLL_SPEED, ROLL_YAW = 10.0, 0.02  # free rolling for the radius reference [m/s], [rad/s]
KMH = 1.0 / 3.6


def default_export() -> Path | None:
    """The racecar export beside the repository, if present."""
    return next((p for p in CANDIDATES if p.is_file()), None)


def read_export(path: Path, cmap: dict) -> dict:
    """The export's columns the map names, by channel, in the map's units (no conversion)."""
    with open(path, encoding="utf-8") as fh:
        header = fh.readline().lstrip("#").strip().split(",")
    names = [h.split("(")[0].strip() for h in header]
    table = np.loadtxt(path, delimiter=",", comments="#")
    return {ch: table[:, names.index(e["column"])] for ch, e in cmap["channels"].items()}


def reference(cols: dict, cmap: dict, r: float) -> dict:
    """Figures from the raw export: the braking events (times from the first sample) and the radius reference."""
    t = cols["t"] - cols["t"][0]
    dt = float(np.median(np.diff(t)))
    v, brake, thr = cols["v"], cols["T_b"], cols["throttle"]
    mask = np.r_[0, ((brake > 0) & (thr == 0) & (v > MIN_SPEED)).astype(np.int8), 0]
    edges = np.diff(mask)
    events = [(float(t[a]), float(t[b - 1])) for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1))
              if (b - a) * dt >= MIN_DURATION - 1e-9]
    wheel = cols["omega"] * (KMH if cmap["channels"]["omega"].get("unit") in ("km/h", "kmph") else 1.0)
    roll = (brake == 0) & (thr == 0) & (np.abs(cols["yaw_rate"]) < ROLL_YAW) & (v > ROLL_SPEED) & (wheel > 0)
    return {"events": events, "r_eff": float(np.median(r * v[roll] / wheel[roll])), "roll_samples": int(roll.sum())}


def run(export: Path, out: Path) -> dict:
    """Run the command, check its report; returns the figures and whether each target holds."""
    cmap = json.loads((MAPS / "av21.json").read_text())
    params = json.loads((MAPS / "av21_params.json").read_text())
    cmd = [sys.executable, "-m", "fricenv", "gap", "diagnose", str(export), "--map", str(MAPS / "av21.json"),
           "--params", str(MAPS / "av21_params.json"), "--out", str(out)]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        return {"ok": False, "error": proc.stderr.strip().splitlines()[-1:] or ["exit " + str(proc.returncode)],
                "seconds": seconds}
    report = json.loads((out / "report.json").read_text())
    ref = reference(read_export(export, cmap), cmap, float(params["r"]))
    found = [(e["t_start"], e["t_end"]) for e in report["where"]["events"]]
    missed = [e for e in ref["events"] if not any(a <= e[1] and e[0] <= b for a, b in found)]
    mapped = report["where"]["car"]["mapped_wheel"]
    r_eff = next((e["params"]["r_eff"] for e in report["effects"] if e["effect"] == "radius_error"),
                 report["where"]["car"][f"r_eff_{mapped}"])
    ratio = report["gap_after"] / report["gap_before"] if report["gap_before"] > 0 else float("nan")
    checks = {"events": not missed, "ratio": ratio <= TARGETS["ratio"],
              "radius": abs(r_eff / ref["r_eff"] - 1.0) <= TARGETS["radius_rel"],
              "seconds": seconds <= TARGETS["seconds"]}
    return {"ok": all(checks.values()), "checks": checks, "seconds": seconds, "verdict": report["verdict"],
            "effects": report["effects"], "gap_before": report["gap_before"], "gap_after": report["gap_after"],
            "ratio": ratio, "events_reference": ref["events"], "events_found": found, "missed": missed,
            "r_eff": r_eff, "r_eff_reference": ref["r_eff"], "roll_samples": ref["roll_samples"],
            "summary": proc.stdout.strip().splitlines()[:1]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--export", type=Path, default=None, help="the racecar export (default: ../shared beside the repo)")
    ap.add_argument("--out", type=Path, default=None, help="report directory (default: a temporary one)")
    args = ap.parse_args(argv)
    export = args.export or default_export()
    if export is None or not export.is_file():
        print(f"racecar export not found ({', '.join(map(str, CANDIDATES))}); pass --export", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        res = run(export, out)
    print(json.dumps(res, indent=1, default=float))
    return 0 if res["ok"] else 1


if __name__ == "__main__":
    if __package__ in (None, ""):
        sys.path.insert(0, str(ROOT))
    sys.exit(main())
