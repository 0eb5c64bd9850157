"""The gap tool's "real" stand-in: a quarter car with chosen effects, a test driver and a log writer.

The stand-in is :class:`fricenv.effects.quarter_car.EffectSimulator` (the same code as the diagnosis' augmented
simulators). Logs follow docs/contracts.md: ``t, T_b, omega[, v][, a_x]``; ``T_b`` is the commanded torque, before any
actuator effect; every log starts with a short free-rolling stretch; the wheel speed carries white noise of the
paper's variance (:data:`fricenv.plants.sui_johansen.OMEGA_NOISE_VAR`), ``v`` and ``a_x`` small white noise.

Drivers (self-contained; fricenv does not depend on ``agents``):

- ``abs``: a rule-based ABS-like modulation from the measured wheel speed only: a reference speed from the wheel
  speed envelope, torque ramped up until the estimated slip exceeds a threshold (or the wheel decelerates much
  faster than the car can), then released until the wheel re-accelerates below a lower slip threshold;
- ``open-loop``: random torque ramps, holds and steps, mostly below the road's peak, with short pulses beyond it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from fricenv.effects.quarter_car import (
    DEFAULT_SUBSTEPS,
    EffectSimulator,
    ModelBatch,
    effect_params,
)
from fricenv.logs import QuarterCarLog, write_log
from fricenv.plants import quarter_car as qc
from fricenv.plants import sui_johansen as sj
from fricenv.plants.tire import MagicFormula, ecu_slip
from fricenv.utils import as_generator

__all__ = ["DRIVERS", "NoiseSpec", "make_driver", "simulate_log", "write_simulated_log"]

DRIVERS = ("abs", "open-loop")
DT = sj.SAMPLE_TIME  # sample time [s], the paper's
OMEGA_NOISE_VAR = sj.OMEGA_NOISE_VAR  # wheel-speed noise variance [(rad/s)^2], Sui & Johansen
V_NOISE_STD = 0.05  # reference-speed noise [m/s]
AX_NOISE_STD = 0.1  # accelerometer noise [m/s^2]
V_END = 3.0  # the log stops when the car is slower than this [m/s]
FREE_ROLL = (0.3, 0.6)  # free-rolling stretch at the start [s]
V0_RANGE = (20.0, 32.0)  # initial speed [m/s]
# The stand-in integrates twice as finely as the diagnosis' models, so that the diagnosis never relies on sharing
# the stand-in's discretisation (an independent simulator will not share it either).
STAND_IN_SUBSTEPS = 2 * DEFAULT_SUBSTEPS

# ABS driver constants
_ABS_RATE_UP = 3000.0  # first apply rate [N m/s]
_ABS_RATE_UP_CYCLE = 0.5  # apply rate after the first cycle, as a share of the peak torque per 0.1 s [-]
_ABS_RELEASE = 12.0  # exponential release rate [1/s]
_ABS_SLIP_HIGH = 0.16  # release above this estimated slip [-]
_ABS_SLIP_LOW = 0.06  # re-apply below this estimated slip [-]
_ABS_FILTER = 0.5  # wheel-speed low-pass coefficient per sample [-]
_ABS_DECEL_MARGIN = 1.3  # reference-speed slope: this times the torque-implied deceleration [-]
_ABS_MIN_DECEL = 1.0  # smallest reference-speed slope [m/s^2]

# Open-loop driver constants
_OL_LEVEL = (0.15, 0.75)  # hold levels as a share of the peak tire torque r F_z mu_max [-]
_OL_RECOVER = (0.05, 0.2)  # level after an over-peak pulse, so a locked wheel spins up again [-]
_OL_RECOVER_LEN = (0.15, 0.3)  # its length [s]
_OL_PULSE = (1.05, 1.3)  # short over-peak pulse level [-]
_OL_PULSE_P = 0.25  # probability that a segment is an over-peak pulse
_OL_RAMP = (0.05, 0.4)  # ramp time [s]
_OL_HOLD = (0.1, 0.5)  # hold time [s]
_OL_PULSE_LEN = (0.03, 0.08)  # pulse length [s]


@dataclass(frozen=True)
class NoiseSpec:
    """Measurement noise of the stand-in's log."""

    omega_var: float = OMEGA_NOISE_VAR  # wheel-speed noise variance [(rad/s)^2]
    v_std: float = V_NOISE_STD  # reference-speed noise std [m/s]
    a_x_std: float = AX_NOISE_STD  # accelerometer noise std [m/s^2]


def _abs_driver(road: MagicFormula, p: qc.QuarterCarParams, v0: float, free_steps: int,
                dt: float) -> Callable[[int, float, float], float]:
    """Rule-based ABS-like driver from the measured wheel speed (see module docstring)."""
    state = {"w": v0 / p.r, "v_ref": v0, "T": 0.0, "mode": "apply", "cycles": 0, "T_peak": 0.0}

    def drive(k: int, t: float, omega_meas: float) -> float:
        s = state
        s["w"] += _ABS_FILTER * (omega_meas - s["w"])
        decel = max(_ABS_DECEL_MARGIN * s["T"] / (p.r * p.m), _ABS_MIN_DECEL)
        s["v_ref"] = max(s["w"] * p.r, s["v_ref"] - decel * dt)
        if k < free_steps:
            return 0.0
        slip_est = ecu_slip(s["w"], s["v_ref"], p.r)
        if s["mode"] == "apply":
            rate = _ABS_RATE_UP if s["cycles"] == 0 else _ABS_RATE_UP_CYCLE * s["T_peak"] / 0.1
            s["T"] += rate * dt
            if slip_est > _ABS_SLIP_HIGH:
                s["mode"], s["T_peak"] = "release", s["T"]
                s["cycles"] += 1
        else:
            s["T"] *= 1.0 - _ABS_RELEASE * dt
            if slip_est < _ABS_SLIP_LOW:
                s["mode"] = "apply"
        return s["T"]

    return drive


def _open_loop_torque(road: MagicFormula, p: qc.QuarterCarParams, n: int, free_steps: int, dt: float,
                      rng: np.random.Generator) -> np.ndarray:
    """Random ramps, holds and short over-peak pulses after the free-rolling stretch."""
    t_peak = p.r * p.Fz * road.mu_max
    torque = np.zeros(n)
    k, level = free_steps, 0.0
    while k < n:
        if rng.random() < _OL_PULSE_P and level > 0:
            target = rng.uniform(*_OL_PULSE) * t_peak
            length = max(int(rng.uniform(*_OL_PULSE_LEN) / dt), 1)
            torque[k:k + length] = target
            k += length
            # release so that a wheel the pulse locked spins up again (a level below the peak can still hold a
            # locked wheel: the sliding friction mu(1) is lower than the peak)
            rec = max(int(rng.uniform(*_OL_RECOVER_LEN) / dt), 1)
            level = rng.uniform(*_OL_RECOVER) * t_peak
            torque[k:k + rec] = level
            k += rec
            continue
        target = rng.uniform(*_OL_LEVEL) * t_peak
        ramp = max(int(rng.uniform(*_OL_RAMP) / dt), 1) if rng.random() < 0.7 else 1  # ramp or step
        hold = max(int(rng.uniform(*_OL_HOLD) / dt), 1)
        seg = np.concatenate([np.linspace(level, target, ramp + 1)[1:], np.full(hold, target)])
        torque[k:k + len(seg)] = seg[: max(n - k, 0)]
        k += len(seg)
        level = target
    return torque


def make_driver(name: str, road: MagicFormula, p: qc.QuarterCarParams, v0: float, n: int, free_steps: int,
                dt: float, rng: np.random.Generator):
    """A driver by name: a controller ``(k, t, omega_meas) -> T_b`` (abs) or a torque array (open-loop)."""
    if name == "abs":
        return _abs_driver(road, p, v0, free_steps, dt)
    if name == "open-loop":
        return _open_loop_torque(road, p, n, free_steps, dt, rng)
    raise ValueError(f"unknown driver {name!r}; valid drivers: {', '.join(DRIVERS)}")


def simulate_log(effects: Sequence, road: MagicFormula, driver: str = "abs", seed=None, duration: float = 5.0,
                 dt: float = DT, v0: float | None = None, write_v: bool = True, write_ax: bool = True,
                 p: qc.QuarterCarParams = qc.PAPER_PARAMS, noise: NoiseSpec = NoiseSpec(),
                 substeps: int = STAND_IN_SUBSTEPS) -> tuple[QuarterCarLog, dict]:
    """Run the real stand-in and return its log and the truth.

    :param effects: effect specs (library and/or validation-only) switched on in the stand-in.
    :param road: true road.
    :param driver: ``"abs"`` or ``"open-loop"``.
    :param seed: seed or generator (initial speed, free-rolling length, driver, noise).
    :param duration: longest log [s]; the log stops earlier once the car is slower than ``V_END``.
    :param dt: sample time [s].
    :param v0: initial speed [m/s] (random in ``V0_RANGE`` if None).
    :param write_v: include the ``v`` column; :param write_ax: include the ``a_x`` column.
    :param p: vehicle parameters; :param noise: measurement noise; :param substeps: physics substeps per sample.
    :return: (log, truth) where truth has the noise-free ``t``, ``v``, ``omega``, ``a_x`` on the log's rows,
        ``T_applied``, ``effects``, ``road``, ``driver``.
    """
    if driver not in DRIVERS:
        raise ValueError(f"unknown driver {driver!r}; valid drivers: {', '.join(DRIVERS)}")
    if duration <= 0:
        raise ValueError(f"duration must be > 0, got {duration}")
    rng = as_generator(seed)
    v0 = float(rng.uniform(*V0_RANGE)) if v0 is None else float(v0)
    n = round(duration / dt)
    free_steps = round(rng.uniform(*FREE_ROLL) / dt)
    drive = make_driver(driver, road, p, v0, n, free_steps, dt, rng)
    batch = ModelBatch.from_effects(road, effects, p)
    sim = EffectSimulator(batch, dt, n, p, substeps)
    sim.reset(np.array([v0]), np.array([v0 / batch.r_eff[0]]))
    w_noise = np.sqrt(noise.omega_var)
    rec = {name: [] for name in ("t", "T_b", "omega", "v", "a_x", "v_true", "omega_true", "a_x_true", "T_applied")}
    for k in range(n):
        if sim.v[0] < V_END:
            break
        omega_meas = float(sim.omega[0] + w_noise * rng.standard_normal())
        cmd = drive(k, k * dt, omega_meas) if callable(drive) else float(drive[k])
        rec["t"].append(k * dt)
        rec["T_b"].append(cmd)
        rec["omega"].append(omega_meas)
        rec["v"].append(float(sim.v[0] + noise.v_std * rng.standard_normal()))
        a_x = float(sim.accel()[0])
        rec["a_x"].append(a_x + noise.a_x_std * rng.standard_normal())
        rec["a_x_true"].append(a_x)
        rec["v_true"].append(float(sim.v[0]))
        rec["omega_true"].append(float(sim.omega[0]))
        sim.step(np.array([cmd]))
        rec["T_applied"].append(float(sim.applied[0]))
    arr = {k: np.asarray(v) for k, v in rec.items()}
    names = ", ".join(f"{e.name}({', '.join(f'{k}={v:g}' for k, v in effect_params(e).items())})"
                      for e in effects) or "none"
    log = QuarterCarLog(t=arr["t"], T_b=arr["T_b"], omega=arr["omega"], v=arr["v"] if write_v else None,
                        a_x=arr["a_x"] if write_ax else None,
                        comments=(f"fricenv gap simulate: driver={driver}, road={road.name}, v0={v0:.3f}",
                                  f"effects: {names}"))
    truth = {"t": arr["t"], "v": arr["v_true"], "omega": arr["omega_true"], "a_x": arr["a_x_true"],
             "T_applied": arr["T_applied"],
             "effects": list(effects), "road": road, "driver": driver, "v0": v0}
    return log, truth


def write_simulated_log(path, effects: Sequence, road: MagicFormula, driver: str = "abs", seed=None,
                        duration: float = 5.0, write_v: bool = True, write_ax: bool = True,
                        comments: bool = True, **kwargs) -> dict:
    """:func:`simulate_log` and write the log atomically to ``path``; returns the truth.

    :param comments: write the provenance comment lines (they name the true effects; off for blind tests).
    """
    log, truth = simulate_log(effects, road, driver, seed, duration, write_v=write_v, write_ax=write_ax, **kwargs)
    write_log(path, log, comments=log.comments if comments else ("fricenv gap simulate",))
    return truth
