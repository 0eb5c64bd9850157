"""Unmodelled effects of the planar payload with a force-moment sensor (docs/contracts.md).

| name                | parameters                 | where it acts                                              |
| ------------------- | -------------------------- | ---------------------------------------------------------- |
| ``wrench_offset``     | ``M0`` [N m], ``fx0``, ``fy0`` [N] | the raw reading carries a constant offset             |
| ``calibration_error`` | ``S`` [3x3]                | the true calibration is ``S`` instead of the known one       |
| ``calibration_drift`` | ``rate`` [1/s]             | the true calibration scales over time, ``S(t) = S (1 + rate t)`` |
| ``vision_delay``      | ``delay`` [s]              | the pose measurement is delayed                             |

:func:`simulate_payload_with_effects` is the payload's real stand-in: the rigid-body dynamics are those of
:mod:`fricenv.plants.payload` (its accurate RK4 cascade), the effects act on the sensor reading (offset, calibration)
and on the vision (delay). The diagnosis of payload logs is :mod:`fricenv.gap.payload.diagnose`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from typing import ClassVar

import numpy as np

from fricenv.logs import PayloadLog
from fricenv.plants import payload as pl

__all__ = [
    "PAYLOAD_EFFECTS",
    "PAYLOAD_EFFECT_PARAMS",
    "PAYLOAD_TESTABLE",
    "CalibrationDrift",
    "CalibrationError",
    "PayloadExcitation",
    "VisionDelay",
    "WrenchOffset",
    "make_payload_effect",
    "simulate_payload_with_effects",
]


@dataclass(frozen=True)
class WrenchOffset:
    """The raw sensor reading carries a constant offset ``(M0, fx0, fy0)``."""

    M0: float  # moment offset [N m]
    fx0: float  # force offset, x [N]
    fy0: float  # force offset, y [N]
    name: ClassVar[str] = "wrench_offset"

    def __post_init__(self):
        for k in ("M0", "fx0", "fy0"):
            if not np.isfinite(getattr(self, k)):
                raise ValueError(f"wrench_offset.{k} must be finite, got {getattr(self, k)!r}")


@dataclass(frozen=True)
class CalibrationError:
    """The true calibration is ``S`` (3x3, row-major nested list or array) instead of the known one."""

    S: tuple  # true calibration matrix, 3x3 [-]
    name: ClassVar[str] = "calibration_error"

    def __post_init__(self):
        S = np.asarray(self.S, dtype=float)
        if S.shape != (3, 3) or not np.all(np.isfinite(S)):
            raise ValueError(f"calibration_error.S must be a finite 3x3 matrix, got shape {S.shape}")
        if abs(np.linalg.det(S)) < 1e-12:
            raise ValueError("calibration_error.S must be invertible")
        object.__setattr__(self, "S", tuple(tuple(float(v) for v in row) for row in S))


@dataclass(frozen=True)
class CalibrationDrift:
    """The calibration scales over time: ``S(t) = S (1 + rate t)``."""

    rate: float  # relative drift rate [1/s]
    name: ClassVar[str] = "calibration_drift"

    def __post_init__(self):
        if not np.isfinite(self.rate):
            raise ValueError(f"calibration_drift.rate must be finite, got {self.rate!r}")


@dataclass(frozen=True)
class VisionDelay:
    """The pose measurement is delayed by ``delay``."""

    delay: float  # vision latency [s]
    name: ClassVar[str] = "vision_delay"

    def __post_init__(self):
        if not np.isfinite(self.delay) or self.delay < 0:
            raise ValueError(f"vision_delay.delay must be finite and >= 0, got {self.delay!r}")


PAYLOAD_EFFECTS: dict[str, type] = {c.name: c for c in (WrenchOffset, CalibrationError, CalibrationDrift,
                                                         VisionDelay)}
PAYLOAD_EFFECT_PARAMS: dict[str, tuple[str, ...]] = {n: tuple(f.name for f in fields(c))
                                                      for n, c in PAYLOAD_EFFECTS.items()}


@dataclass(frozen=True)
class PayloadExcitation:
    """What a payload log shows, for the effects' testability rules.

    :param duration: log length [s].
    :param wrench_snr: the smallest, over the three wrench readings, of their spread over their noise std [-].
    :param pose_rate: rate of fresh (not held) pose samples [Hz].
    """

    duration: float
    wrench_snr: float
    pose_rate: float


MIN_WRENCH_SNR = 5.0  # a calibration is read from wrench readings varying this far above their noise [-]
MIN_DRIFT_DURATION = 4.0  # a calibration drift needs this long a log [s]
MIN_POSE_RATE = 20.0  # a vision delay needs fresh poses at this rate at least [Hz]


def _needs_wrench(x: PayloadExcitation) -> str | None:
    if x.wrench_snr < MIN_WRENCH_SNR:
        return f"the wrench readings vary {x.wrench_snr:.1f} noise std; a calibration needs {MIN_WRENCH_SNR:g}"
    return None


def _needs_duration(x: PayloadExcitation) -> str | None:
    if x.duration < MIN_DRIFT_DURATION:
        return f"log of {x.duration:.1f} s; a drift needs {MIN_DRIFT_DURATION:g} s"
    return _needs_wrench(x)


def _needs_pose_rate(x: PayloadExcitation) -> str | None:
    if x.pose_rate < MIN_POSE_RATE:
        return f"fresh poses at {x.pose_rate:.0f} Hz; a vision delay needs {MIN_POSE_RATE:g} Hz"
    return None


# The payload effects' testability rules: name -> (excitation -> None, or why the log cannot show the effect).
PAYLOAD_TESTABLE: dict[str, Callable[[PayloadExcitation], str | None]] = {
    "wrench_offset": lambda x: None,
    "calibration_error": _needs_wrench,
    "calibration_drift": _needs_duration,
    "vision_delay": _needs_pose_rate,
}


def make_payload_effect(name: str, **params):
    """A payload effect spec from its registry name and parameters; unknown names/parameters raise ValueError."""
    if name not in PAYLOAD_EFFECTS:
        raise ValueError(f"unknown payload effect {name!r}; valid effects: {', '.join(PAYLOAD_EFFECTS)}")
    valid = PAYLOAD_EFFECT_PARAMS[name]
    unknown = sorted(set(params) - set(valid))
    missing = [v for v in valid if v not in params]
    if unknown or missing:
        what = f"unknown parameter(s) {', '.join(unknown)}" if unknown else f"missing parameter(s) {', '.join(missing)}"
        raise ValueError(f"payload effect {name!r}: {what}; its parameters are: {', '.join(valid)}")
    return PAYLOAD_EFFECTS[name](**params)


def simulate_payload_with_effects(effects: Sequence, duration: float, dt: float = 1e-3, *,
                                  wrench: Callable = pl.paper_wrench, S_known=pl.PAPER_S,
                                  noise: pl.NoiseParams = pl.PAPER_NOISE, rng: np.random.Generator | None = None,
                                  p: pl.PayloadParams = pl.PAPER_PARAMS):
    """Simulate the payload with effects and return its log and the true trajectory.

    :param effects: payload effect specs (each name at most once).
    :param duration: length [s]; :param dt: sample time [s]; :param wrench: true wrench ``w(t)``.
    :param S_known: the calibration the nominal model assumes (the true one unless calibration_error).
    :param noise: measurement noise; :param rng: generator (required unless noise is zero); :param p: payload.
    :return: (PayloadLog, Trajectory) where the trajectory is the noise-free truth of the plant.
    """
    names = [e.name for e in effects]
    if len(set(names)) != len(names):
        raise ValueError(f"each effect may appear once, got {names}")
    for e in effects:
        if e.name not in PAYLOAD_EFFECTS:
            raise ValueError(f"unknown payload effect {e.name!r}; valid effects: {', '.join(PAYLOAD_EFFECTS)}")
    by = {e.name: e for e in effects}
    traj = pl.simulate(duration, dt, wrench=wrench, noise=pl.NO_NOISE, p=p)
    t = traj.t
    S = np.asarray(by["calibration_error"].S if "calibration_error" in by else S_known, dtype=float)
    scale = 1.0 + (by["calibration_drift"].rate * t if "calibration_drift" in by else 0.0 * t)
    S_t = S[None] * np.asarray(scale)[:, None, None]
    w_hat = pl.sensor_reading(traj.w, np.linalg.inv(S_t), noise, rng)
    if "wrench_offset" in by:
        o = by["wrench_offset"]
        w_hat = w_hat + np.array([o.M0, o.fx0, o.fy0])
    state = traj.state
    if "vision_delay" in by:
        td = np.maximum(t - by["vision_delay"].delay, t[0])
        state = np.column_stack([np.interp(td, t, traj.state[:, i]) for i in range(3)])
    pose = pl.vision(state, noise, rng)
    log = PayloadLog(t=t, M=w_hat[:, 0], f_x=w_hat[:, 1], f_y=w_hat[:, 2], theta=pose[:, 0], X=pose[:, 1],
                        Y=pose[:, 2])
    return log, traj
