"""Shared by the fleet tests: small simulated logs and a fast diagnosis setting."""

from __future__ import annotations

from pathlib import Path

from fricenv.cli import main
from fricenv.gap.quarter_car.diagnose import DiagnoseConfig

# One candidate, one start, few iterations, no joint fit or drift test: about a second of CPU per 1.5 s log.
FAST = DiagnoseConfig(candidates=("brake_gain",), max_nfev=5, fit_starts=1, joint=False, drift_check=False)
# A brake gain of the simulated effect logs [-]: testable on a 1.5 s log (a brake lag needs two brake apply/release
# events, which a 1.5 s ABS log does not have, so the diagnosis lists it as not testable).
GAIN = 0.8


def simulate_fleet(folder: Path, n: int, duration: float = 1.5) -> list[Path]:
    """``n`` logs written by ``fricenv gap simulate`` into ``folder``: brake_gain (gain=GAIN), every third one none."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i in range(n):
        path = folder / f"log_{i:02d}.csv"
        effect = ["--effect", "none"] if i % 3 == 2 else ["--effect", "brake_gain", "--param", f"gain={GAIN}"]
        assert main(["gap", "simulate", *effect, "--seed", str(i), "--duration", str(duration),
                     "--out", str(path)]) == 0
        paths.append(path)
    return paths
