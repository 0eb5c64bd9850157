"""Odd logs that the reader accepts or rejects, for the rule "no log that the reader accepts makes the diagnosis
crash; every rejection names the file": no braking, a wheel speed that never moves, a wheel locked for good, a
torque too large to be N m, a negative torque, a step in the wheel speed, no noise at all, half of ``v`` missing,
``v`` at zero, wheel-speed spikes on 10 % of the samples, a torque ramp, pure noise. Rates 10 Hz to 1 kHz, 1-6 s,
with ``v`` and ``a_x`` dropped on half of the logs.

    python -m tests.odd_logs --n 24 --seed 1

Each log either gets a verdict or a ``ValueError`` whose one-line message names the file; anything else is a crash.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import traceback
import warnings
from collections.abc import Callable, Sequence

import numpy as np

R = 0.345  # wheel radius of the written logs [m]


def _no_brake(c: dict, t: np.ndarray, rng: np.random.Generator) -> None:
    c["T_b"] = np.zeros(t.size)


def _constant_omega(c: dict, t: np.ndarray, rng: np.random.Generator) -> None:
    c["omega"] = np.full(t.size, 50.0)


def _locked(c: dict, t: np.ndarray, rng: np.random.Generator) -> None:
    c["omega"] = np.where(t > 0.6, 0.0, c["omega"])


def _huge_torque(c: dict, t: np.ndarray, rng: np.random.Generator) -> None:
    c["T_b"] = 100.0 * c["T_b"]


def _negative_torque(c: dict, t: np.ndarray, rng: np.random.Generator) -> None:
    c["T_b"] = -c["T_b"]


def _step(c: dict, t: np.ndarray, rng: np.random.Generator) -> None:
    c["omega"] = np.where(t > t[-1] / 2, c["omega"] - 30.0, c["omega"])


def _noiseless(c: dict, t: np.ndarray, rng: np.random.Generator) -> None:
    c["v"], c["omega"], c["a_x"] = c["_v"], c["_v"] / R, np.where(t > 0.5, -6.0, 0.0)


def _half_v_missing(c: dict, t: np.ndarray, rng: np.random.Generator) -> None:
    c["v"] = np.where(rng.random(t.size) < 0.5, np.nan, c["v"])


def _v_zero(c: dict, t: np.ndarray, rng: np.random.Generator) -> None:
    c["v"] = np.zeros(t.size)


def _spikes(c: dict, t: np.ndarray, rng: np.random.Generator) -> None:
    c["omega"] = c["omega"] + np.where(rng.random(t.size) < 0.1, 40.0, 0.0)


def _ramp(c: dict, t: np.ndarray, rng: np.random.Generator) -> None:
    c["T_b"] = 300.0 * t


def _noise_only(c: dict, t: np.ndarray, rng: np.random.Generator) -> None:
    c["omega"], c["T_b"] = rng.normal(0.0, 1.0, t.size), rng.normal(0.0, 100.0, t.size)


ODD_KINDS: dict[str, Callable[[dict, np.ndarray, np.random.Generator], None]] = {
    "no_brake": _no_brake, "constant_omega": _constant_omega, "locked": _locked, "huge_torque": _huge_torque,
    "negative_torque": _negative_torque, "step": _step, "noiseless": _noiseless, "half_v_missing": _half_v_missing,
    "v_zero": _v_zero, "spikes": _spikes, "ramp": _ramp, "noise_only": _noise_only}
RATES = (10.0, 25.0, 50.0, 100.0, 400.0, 1000.0)  # logger rates drawn [Hz]


def write_odd_log(path: str, kind: str, rng: np.random.Generator, rate_hz: float | None = None,
                  optional: bool | None = None) -> dict:
    """Write a braking log at constant deceleration, made odd by ``kind`` (:data:`ODD_KINDS`).

    :param rate_hz: logger rate (drawn from :data:`RATES` when None).
    :param optional: write ``v`` and ``a_x`` (drawn when None).
    :return: the log's settings (kind, rate, duration, rows, columns).
    """
    fs = float(rng.choice(RATES)) if rate_hz is None else float(rate_hz)
    duration = float(rng.uniform(1.0, 6.0))
    t = np.arange(0.0, duration, 1.0 / fs)
    v = np.maximum(25.0 - 6.0 * t, 1.0)
    c = {"t": t, "T_b": np.where(t > 0.5, 800.0, 0.0), "omega": v / R + rng.normal(0.0, 0.3, t.size),
         "v": v + rng.normal(0.0, 0.05, t.size), "a_x": np.where(t > 0.5, -6.0, 0.0) + rng.normal(0.0, 0.1, t.size)}
    c["_v"] = v  # the noiseless speed, for the kinds that need it
    ODD_KINDS[kind](c, t, rng)
    del c["_v"]
    if not (bool(rng.random() < 0.5) if optional is None else optional):
        del c["v"], c["a_x"]
    with open(path, "w") as fh:
        fh.write(",".join(c) + "\n")
        fh.writelines(",".join("" if not np.isfinite(c[n][k]) else repr(float(c[n][k])) for n in c) + "\n"
                      for k in range(t.size))
    return {"kind": kind, "rate_hz": fs, "seconds": duration, "rows": int(t.size), "columns": list(c)}


def diagnose_odd(path: str) -> str:
    """The verdict, ``"rejected: <message>"`` for a ``ValueError`` naming the file, else ``"crash: <error>"``."""
    from fricenv.gap.quarter_car.diagnose import DiagnoseConfig, diagnose_file

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return diagnose_file(path, cfg=DiagnoseConfig(jobs=1)).verdict
    except ValueError as exc:
        msg = str(exc)
        return f"rejected: {msg}" if path in msg and "\n" not in msg else f"crash: unclear ValueError {msg!r}"
    except Exception as exc:  # noqa: BLE001 -- any other exception is the crash this check looks for
        return "crash: " + "".join(traceback.format_exception_only(type(exc), exc)).strip()


def run(n: int, seed: int) -> list[dict]:
    """``n`` odd logs (the kinds in turn) written to a temporary directory and diagnosed; one row each."""
    rng = np.random.default_rng(seed)
    kinds = list(ODD_KINDS)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(n):
            path = os.path.join(tmp, f"odd{i}.csv")
            row = write_odd_log(path, kinds[i % len(kinds)], rng)
            row["result"] = diagnose_odd(path)
            rows.append(row)
            print(f"{i:3d} {row['kind']:>15} {row['rate_hz']:6.0f} Hz {row['seconds']:4.1f} s "
                  f"{'+v,a_x' if 'v' in row['columns'] else 'omega ':>6} -> {row['result'][:120]}", flush=True)
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: ``python -m tests.odd_logs --n 24 --seed 1``; exit code 1 if any log crashed."""
    ap = argparse.ArgumentParser(description="Diagnose odd logs; count crashes.")
    ap.add_argument("--n", type=int, default=24)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    rows = run(args.n, args.seed)
    crashes = sum(r["result"].startswith("crash") for r in rows)
    rejected = sum(r["result"].startswith("rejected") for r in rows)
    print(f"{len(rows)} logs: {len(rows) - crashes - rejected} diagnosed, {rejected} rejected naming the file, "
          f"{crashes} crashed")
    return 1 if crashes else 0


if __name__ == "__main__":
    raise SystemExit(main())
