"""Braking set-up: the constants shared by all cars (:class:`BrakingConfig`) and the observation layout of the
``fricenv/Braking-v0`` family.

Measurement model (what an ABS ECU has), per control step of ``dt`` (10 ms):

=================  ==========================================================================================
channel            model
=================  ==========================================================================================
wheel speed        ``omega + e``, ``e ~ N(0, 0.2 (rad/s)^2)`` (Sui & Johansen, Section V)
wheel decel        ``-r (omega_k - omega_{k-1}) / dt + e``, ``e ~ N(0, decel_noise_std^2)``: the ECU's wheel
                   deceleration (from sensor tooth timing), positive when the wheel slows down [m/s^2]
longitudinal acc.  ``(v_k - v_{k-1}) / dt + e``, ``e ~ N(0, ax_noise_std^2)`` [m/s^2], negative when braking
=================  ==========================================================================================
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from fricenv.plants import quarter_car as qc
from fricenv.plants import sui_johansen as sj

__all__ = [
    "ACTION_MODES",
    "NOISE_BLOCK",
    "N_NOISE",
    "OBSERVATION_MODES",
    "BrakingConfig",
    "ObsField",
    "decode_observation",
    "observation_layout",
]

# Control step of the ECU [s] and default physics substep [s] (5 substeps per control step).
CONTROL_DT = sj.SAMPLE_TIME
PHYSICS_DT = 0.002
# Brake torque at action +1 [N m]: locks the wheel on dry asphalt (r F_z mu_max = 1100 N m) with a wide margin.
T_MAX = 2500.0
# Torque-rate mode: brake modulator rate at action +-1 [N m/s] (full range in 0.1 s).
TORQUE_RATE_MAX = 25000.0
V_STOP = 2.0  # episode ends when the vehicle is this slow [m/s]
TIME_LIMIT = 60.0  # truncation [s]; a locked wheel on ice stops from 40 m/s in ~42 s
OMEGA_NOISE_VAR = sj.OMEGA_NOISE_VAR  # wheel-speed noise variance [(rad/s)^2], Sui & Johansen Section V
DECEL_NOISE_STD = 1.0  # wheel-deceleration noise [m/s^2]
AX_NOISE_STD = 0.1  # longitudinal accelerometer noise [m/s^2]
LOCK_SPEED_RATIO = 0.05  # wheel counts as locked while omega r < 0.05 v ...
LOCK_TIME = 0.1  # ... for longer than this [s], above v_stop
LOCK_PENALTY = 0.01  # reward subtracted per control step while locked [-]
NOISE_BLOCK = 512  # control steps of noise drawn at once per car
N_NOISE = 3  # noisy channels: wheel speed, wheel deceleration, a_x

ACTION_MODES = ("torque", "torque_rate")
OBSERVATION_MODES = ("default", "oracle")


@dataclass(frozen=True)
class BrakingConfig:
    """Constants of one braking set-up (shared by all cars of a :class:`~fricenv.envs.braking_sim.BrakingSim`)."""

    dt: float = CONTROL_DT  # control step [s]
    physics_dt: float = PHYSICS_DT  # physics substep [s]; must divide dt
    t_max: float = T_MAX  # brake torque at action +1 [N m]
    torque_rate_max: float = TORQUE_RATE_MAX  # torque rate at action +-1 in torque_rate mode [N m/s]
    v_stop: float = V_STOP  # stop speed [m/s]
    time_limit: float = TIME_LIMIT  # episode truncation [s]
    omega_noise_var: float = OMEGA_NOISE_VAR  # [(rad/s)^2]
    decel_noise_std: float = DECEL_NOISE_STD  # [m/s^2]
    ax_noise_std: float = AX_NOISE_STD  # [m/s^2]
    lock_speed_ratio: float = LOCK_SPEED_RATIO  # [-]
    lock_time: float = LOCK_TIME  # [s]
    lock_penalty: float = LOCK_PENALTY  # per control step [-]
    action_mode: str = "torque"  # "torque" | "torque_rate"
    observation: str = "default"  # "default" | "oracle"
    params: qc.QuarterCarParams = field(default=qc.PAPER_PARAMS)  # quarter-car parameters

    def __post_init__(self):
        for name in ("dt", "physics_dt", "t_max", "torque_rate_max", "v_stop", "time_limit", "lock_time"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
        for name in ("omega_noise_var", "decel_noise_std", "ax_noise_std", "lock_speed_ratio", "lock_penalty"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        ratio = self.dt / self.physics_dt
        if abs(ratio - round(ratio)) > 1e-9 * ratio or round(ratio) < 1:
            raise ValueError(f"physics_dt={self.physics_dt} must divide the control step dt={self.dt} "
                             f"a whole number of times")
        if self.action_mode not in ACTION_MODES:
            raise ValueError(f"unknown action_mode {self.action_mode!r}; valid: {', '.join(ACTION_MODES)}")
        if self.observation not in OBSERVATION_MODES:
            raise ValueError(f"unknown observation {self.observation!r}; valid: {', '.join(OBSERVATION_MODES)}")
        if not isinstance(self.params, qc.QuarterCarParams):
            raise TypeError(f"params must be a QuarterCarParams, got {type(self.params).__name__}")

    @property
    def substeps(self) -> int:
        """Physics substeps per control step."""
        return round(self.dt / self.physics_dt)

    @property
    def max_steps(self) -> int:
        """Control steps before truncation."""
        return math.ceil(self.time_limit / self.dt - 1e-9)

    @property
    def lock_steps(self) -> int:
        """A wheel is locked after more than this many consecutive lock-condition steps."""
        return round(self.lock_time / self.dt)


@dataclass(frozen=True)
class ObsField:
    """One entry of the observation vector: ``obs = clip(value / scale, low, high)``."""

    name: str
    unit: str  # unit of the physical value
    scale: float  # physical value per observation unit
    low: float  # bound of the scaled entry
    high: float  # bound of the scaled entry
    description: str

    def decode(self, x):
        """Physical value [unit] of a scaled observation entry."""
        return np.asarray(x, dtype=float) * self.scale


def decode_observation(fields: Sequence[ObsField], obs) -> dict[str, float]:
    """Physical values (units of ``fields``) of an observation vector, by name."""
    obs = np.asarray(obs, dtype=float)
    return {f.name: float(obs[j] * f.scale) for j, f in enumerate(fields)}


G_STD = 9.81  # scaling of accelerations [m/s^2 per observation unit]
_DEFAULT_FIELDS = (
    ObsField("wheel_speed", "rad/s", 100.0, -1.0, 2.0, "measured wheel speed omega_m"),
    ObsField("wheel_decel", "m/s^2", G_STD, -50.0, 50.0,
             "measured wheel deceleration -r omega', positive when the wheel slows"),
    ObsField("torque", "-", 1.0, 0.0, 1.0, "last brake-torque command T_b / T_max"),
    ObsField("a_x", "m/s^2", G_STD, -5.0, 5.0, "measured longitudinal acceleration, negative when braking"),
)
_ORACLE_FIELDS = (
    ObsField("v", "m/s", 50.0, 0.0, 2.0, "true vehicle speed"),
    ObsField("slip", "-", 1.0, -1.0, 1.0, "true wheel slip"),
    ObsField("mu", "-", 1.0, -2.0, 2.0, "true friction coefficient in use"),
)


def observation_layout(observation: str = "default") -> tuple[ObsField, ...]:
    """The observation entries, in order, for an observation mode."""
    if observation not in OBSERVATION_MODES:
        raise ValueError(f"unknown observation {observation!r}; valid: {', '.join(OBSERVATION_MODES)}")
    return _DEFAULT_FIELDS + (_ORACLE_FIELDS if observation == "oracle" else ())
