"""The braking plant protocol: what one episode of the braking env needs from a quarter-car plant.

An episode (:class:`fricenv.envs.braking_sim.BrakingSim`) holds the brake torque over a control step, advances the
plant substep by substep (to locate the stop and a friction change inside the substep), and reads the tire force
and the slip for the truth it reports. Any object with these members can be that plant:

=====================  =====================================================================================
member                 meaning
=====================  =====================================================================================
``n``, ``h``           number of cars, physics substep [s]
``v``, ``omega``       vehicle speed [m/s] and wheel speed [rad/s] of every car (state after the last substep)
``r_eff``              rolling radius of every car [m] (slip, free rolling and the lock test use it)
``reset(idx, v, w)``   set the state of cars ``idx``
``new_episode(i, g)``  per-episode draws of car ``i`` from its generator ``g`` (after the scenario's draws)
``set_road(idx, r)``   road rows (B, C, E, theta) of cars ``idx``
``set_torque(Tb)``     brake torque of every car [N m], held over the following substeps
``substep()``          advance every car by ``h``; returns the new (v, omega)
``friction(slip)``     friction coefficient in use of every car now, mu = F_x / F_z (eq. (2)); ``slip``, if
                       given, is :meth:`slip`'s value now (a plant may reuse it)
``tire_force()``       longitudinal tire force F_x [N] of every car now
``slip()``             wheel slip of every car now (:func:`fricenv.plants.tire.longitudinal_slip`)
``accel()``            longitudinal acceleration [m/s^2] of every car now, as an accelerometer reads it
=====================  =====================================================================================

Implementations: :class:`BatchPlant` (``n`` cars, numpy, :class:`~fricenv.plants.quarter_car_fast.Ros2Batch`),
:class:`ScalarPlant` (one car in Python floats: its members take and return floats, for the single env's speed)
and :class:`fricenv.envs.effect_plant.EffectPlant` (the quarter car with unmodelled effects). The physics is
:func:`fricenv.plants.quarter_car.step`'s ROS2 substep in each (the fast kernels are tested against it to 1e-12).
"""

from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

import numpy as np

from fricenv.plants import quarter_car as qc
from fricenv.plants.quarter_car_fast import Ros2Batch, make_scalar_substep, scalar_road
from fricenv.plants.tire import SLIP_SPEED_FLOOR, longitudinal_slip, magic_formula

__all__ = ["BatchPlant", "BrakingPlant", "ScalarPlant"]


@runtime_checkable
class BrakingPlant(Protocol):
    """What an episode needs from a quarter-car plant (see the module docstring)."""

    n: int
    h: float

    def reset(self, idx, v, omega) -> None: ...

    def new_episode(self, i: int, rng: np.random.Generator) -> None: ...

    def set_road(self, idx, road) -> None: ...

    def set_torque(self, Tb) -> None: ...

    def substep(self): ...

    def friction(self, slip=None): ...

    def tire_force(self): ...

    def slip(self): ...

    def accel(self): ...


class BatchPlant:
    """``n`` nominal quarter cars (eq. (1)), one ROS2 substep of all of them per :meth:`substep` call.

    :param n: number of cars.
    :param h: physics substep [s].
    :param p: quarter-car parameters.
    """

    def __init__(self, n: int, h: float, p: qc.QuarterCarParams = qc.PAPER_PARAMS):
        self.n, self.h, self.p = int(n), float(h), p
        self.kernel = Ros2Batch(self.n, self.h, p)
        self.road = np.zeros((self.n, 4))
        self.r_eff = np.full(self.n, p.r)
        self.v, self.omega = np.zeros(self.n), np.zeros(self.n)

    def reset(self, idx, v, omega) -> None:
        """Set the speeds of cars ``idx``."""
        self.v[idx], self.omega[idx] = v, omega

    def new_episode(self, i: int, rng: np.random.Generator) -> None:
        """Nothing to draw: the nominal plant has no random parameters."""

    def set_road(self, idx, road) -> None:
        """Road rows (B, C, E, theta) of cars ``idx``."""
        self.road[idx] = road
        self.kernel.set_road(idx, self.road[idx])

    def set_torque(self, Tb) -> None:
        """Brake torques [N m] of all cars for the following substeps."""
        self.kernel.set_torque(Tb)

    def substep(self) -> tuple[np.ndarray, np.ndarray]:
        """One ROS2 substep of every car; the state arrays are replaced (callers may keep the old ones)."""
        self.v, self.omega = self.kernel.substep(self.v, self.omega)
        return self.v, self.omega

    def slip(self) -> np.ndarray:
        return longitudinal_slip(self.v, self.omega, self.p.r)

    def friction(self, slip: np.ndarray | None = None) -> np.ndarray:
        """:func:`fricenv.plants.tire.magic_formula` of the slip now (``slip`` if given: the caller's copy)."""
        k = self.kernel
        return magic_formula(self.slip() if slip is None else slip, k.B, k.C, k.E, k.theta)

    def tire_force(self) -> np.ndarray:
        return self.p.Fz * self.friction()

    def accel(self) -> np.ndarray:
        return -self.tire_force() / self.p.m


class ScalarPlant:
    """One nominal quarter car in Python floats: the members of :class:`BatchPlant` on floats (``v``, ``omega``,
    ``set_torque``, ``substep``, ``slip``, ``friction``, ``tire_force``, ``accel``), which is several times faster
    for one car than numpy on 1-element arrays; ``advance(v, w)`` is the substep as a pure function of the state
    (the float driver's hot loop). ``set_road`` and ``reset`` take the batched forms (index, rows).

    :param h: physics substep [s].
    :param p: quarter-car parameters.
    """

    n = 1
    __slots__ = ("Tb", "_mf", "_road", "_substep", "advance", "h", "omega", "p", "r_eff", "v")

    def __init__(self, h: float, p: qc.QuarterCarParams = qc.PAPER_PARAMS):
        self.h, self.p = float(h), p
        self.r_eff = np.full(1, p.r)
        self._substep = make_scalar_substep(self.h, p)
        self._road: tuple[float, ...] = ()
        self._mf: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
        self.v = self.omega = self.Tb = 0.0
        self._bind()

    def _bind(self) -> None:
        """``advance(v, w) -> (v, w)``: one substep from a given state under the torque and road set now, without
        touching :attr:`v`/:attr:`omega` (a driver may hold the state through a control step and store it after)."""
        fn, Tb, road = self._substep, self.Tb, self._road
        self.advance = lambda v, w: fn(v, w, Tb, road)

    def __getstate__(self) -> dict:
        state = {k: getattr(self, k) for k in self.__slots__}
        state["_substep"] = state["advance"] = None  # closures do not pickle; rebuilt from (h, p)
        return state

    def __setstate__(self, state: dict) -> None:
        for k, value in state.items():
            setattr(self, k, value)
        self._substep = make_scalar_substep(self.h, self.p)
        self._bind()

    def reset(self, idx, v, omega) -> None:
        self.v, self.omega = float(np.asarray(v).flat[0]), float(np.asarray(omega).flat[0])

    def new_episode(self, i: int, rng: np.random.Generator) -> None:
        """Nothing to draw: the nominal plant has no random parameters."""

    def set_road(self, idx, road) -> None:
        self._mf = tuple(float(q) for q in np.asarray(road, dtype=float).reshape(-1, 4)[0])
        self._road = scalar_road(*self._mf, self.h, self.p)
        self._bind()

    def set_torque(self, Tb: float) -> None:
        self.Tb = Tb
        self._bind()

    def substep(self) -> tuple[float, float]:
        self.v, self.omega = self.advance(self.v, self.omega)
        return self.v, self.omega

    def slip(self) -> float:
        """:func:`fricenv.plants.tire.longitudinal_slip` in floats (tested against it)."""
        v, wr = self.v, self.omega * self.p.r
        vw = v if v >= wr else wr  # noqa: FURB136 (no builtin calls in the hot path)
        return (v - wr) / (vw if vw > SLIP_SPEED_FLOOR else SLIP_SPEED_FLOOR)  # noqa: FURB136

    def friction(self, slip: float | None = None) -> float:
        """:func:`fricenv.plants.tire.magic_formula` of :meth:`slip` (or of ``slip`` if given), in floats (tested
        against it)."""
        B, C, E, theta = self._mf
        bs = B * (self.slip() if slip is None else slip)
        return theta * math.sin(C * math.atan(bs - E * (bs - math.atan(bs))))

    def tire_force(self) -> float:
        return self.p.Fz * self.friction()

    def accel(self) -> float:
        return -self.tire_force() / self.p.m
