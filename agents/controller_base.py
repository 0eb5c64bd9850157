"""The controller interface of :mod:`agents.controllers`: reading the observation by entry name
(:class:`ObsReader`), turning a desired brake torque into the env's action (:class:`ControlSpec`), and the
:class:`Controller` base class (``reset()``, ``act(obs) -> action``)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fricenv.envs.braking_sim import BrakingSim
from fricenv.envs.config import ObsField
from fricenv.plants.quarter_car import PAPER_PARAMS, QuarterCarParams

__all__ = [
    "CONTROL_SPEED_FLOOR",
    "FIELD_AX",
    "FIELD_SLIP",
    "FIELD_TORQUE",
    "FIELD_V",
    "FIELD_WHEEL_DECEL",
    "FIELD_WHEEL_SPEED",
    "ControlSpec",
    "Controller",
    "ObsReader",
]

FIELD_WHEEL_SPEED = "wheel_speed"
FIELD_WHEEL_DECEL = "wheel_decel"
FIELD_TORQUE = "torque"
FIELD_AX = "a_x"
FIELD_V = "v"
FIELD_SLIP = "slip"
CONTROL_SPEED_FLOOR = 0.5  # smallest reference speed a controller divides by (ECU slip) or schedules on [m/s]


class ObsReader:
    """Decode observations by entry name into physical units.

    :param fields: the observation layout (``env.unwrapped.observation_fields`` or ``BrakingSim.layout``).
    """

    def __init__(self, fields: Sequence[ObsField]):
        self.fields = tuple(fields)
        self.index = {f.name: j for j, f in enumerate(self.fields)}

    def has(self, name: str) -> bool:
        """Whether the layout has the entry ``name``."""
        return name in self.index

    def require(self, names: Sequence[str], who: str) -> None:
        """Raise ValueError if any of ``names`` is missing, naming the controller ``who`` and the layout."""
        missing = [n for n in names if n not in self.index]
        if missing:
            raise ValueError(f"{who} needs observation entries {missing}, the env observation has "
                             f"{list(self.index)}; use observation='oracle' for v/slip/mu")

    def get(self, obs: np.ndarray, name: str) -> np.ndarray:
        """Physical value of entry ``name`` (shape ``obs.shape[:-1]``)."""
        j = self.index[name]
        return np.asarray(obs[..., j], dtype=float) * self.fields[j].scale

    def decode(self, obs: np.ndarray) -> dict[str, np.ndarray]:
        """All entries by name, in physical units."""
        return {f.name: self.get(obs, f.name) for f in self.fields}


@dataclass(frozen=True)
class ControlSpec:
    """What a controller needs to know about the env: observation layout, actuator, sample time, vehicle."""

    fields: tuple[ObsField, ...]
    t_max: float  # brake torque at action +1 [N m]
    dt: float  # control step [s]
    action_mode: str = "torque"  # "torque" | "torque_rate"
    torque_rate_max: float = 25000.0  # [N m/s], torque_rate mode
    params: QuarterCarParams = PAPER_PARAMS  # vehicle parameters known to the ECU

    @classmethod
    def from_env(cls, env) -> ControlSpec:
        """The spec of a ``Braking-v0`` env (wrapped or not)."""
        base = env.unwrapped
        return cls.from_sim(base.sim)

    @classmethod
    def from_sim(cls, sim: BrakingSim) -> ControlSpec:
        """The spec of a batched :class:`BrakingSim`."""
        c = sim.config
        return cls(fields=tuple(sim.layout), t_max=c.t_max, dt=c.dt, action_mode=c.action_mode,
                   torque_rate_max=c.torque_rate_max, params=c.params)

    def to_action(self, torque_des: np.ndarray, torque_now: np.ndarray) -> np.ndarray:
        """Normalised action that asks for ``torque_des`` [N m], given the torque applied now [N m]."""
        if self.action_mode == "torque":
            a = 2.0 * np.asarray(torque_des, dtype=float) / self.t_max - 1.0
        else:
            a = (np.asarray(torque_des, dtype=float) - torque_now) / (self.torque_rate_max * self.dt)
        return np.clip(a, -1.0, 1.0)


def _spec(env_or_spec) -> ControlSpec:
    if isinstance(env_or_spec, ControlSpec):
        return env_or_spec
    if isinstance(env_or_spec, BrakingSim):
        return ControlSpec.from_sim(env_or_spec)
    if hasattr(env_or_spec, "unwrapped") and hasattr(env_or_spec.unwrapped, "sim"):
        return ControlSpec.from_env(env_or_spec)
    raise TypeError(f"expected a Braking env, a BrakingSim or a ControlSpec, got {type(env_or_spec).__name__}")


class Controller(ABC):
    """Base class: ``reset()`` then ``act(obs)`` every control step.

    :param env_or_spec: a ``Braking-v0`` env (wrapped or not), a :class:`BrakingSim`, or a :class:`ControlSpec`.
    """

    name = "controller"
    needs: tuple[str, ...] = ()

    def __init__(self, env_or_spec):
        self.spec = _spec(env_or_spec)
        self.reader = ObsReader(self.spec.fields)
        self.reader.require(self.needs, type(self).__name__)
        self._state: dict[str, np.ndarray] | None = None

    def reset(self) -> None:
        """Forget the episode (call at every env reset)."""
        self._state = None

    def act(self, obs) -> np.ndarray:
        """Normalised action for one observation (returns shape (1,)) or a batch (returns shape (n,))."""
        obs = np.asarray(obs, dtype=float)
        if obs.ndim not in (1, 2) or obs.shape[-1] != len(self.spec.fields):
            raise ValueError(f"obs must have shape ({len(self.spec.fields)},) or (n, {len(self.spec.fields)}), "
                             f"got {obs.shape}")
        single = obs.ndim == 1
        batch = obs[None] if single else obs
        if self._state is None:
            self._state = self._init_state(batch)
        torque_now = self.reader.get(batch, FIELD_TORQUE) * self.spec.t_max if self.reader.has(FIELD_TORQUE) \
            else np.zeros(batch.shape[0])
        torque_des = self._torque(batch, torque_now)
        return self.spec.to_action(torque_des, torque_now).astype(np.float32)

    def reset_some(self, mask: np.ndarray) -> None:
        """Forget the episode of some cars of a batch (for vector envs with autoreset)."""
        if self._state is not None:
            mask = np.asarray(mask, dtype=bool)
            for key, value in self._init_state(None, size=int(mask.size)).items():
                self._state[key][mask] = value[mask]

    def _init_state(self, batch: np.ndarray | None, size: int | None = None) -> dict[str, np.ndarray]:
        """Per-car controller state at the start of an episode."""
        return {}

    @abstractmethod
    def _torque(self, obs: np.ndarray, torque_now: np.ndarray) -> np.ndarray:
        """Desired brake torque [N m] for a batch of observations (n, obs_dim)."""
