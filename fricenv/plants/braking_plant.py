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
``limit_terms(i)``     what in car ``i``'s episode moves the physical limit (the keywords of
                       :func:`fricenv.envs.scenario.effect_limit_distance` but the road's factors: ``t_change``,
                       ``theta_after``, ``c0``, ``c2``), or None: the road's peak friction alone sets it
=====================  =====================================================================================

Implementations: :class:`BatchPlant` (the nominal quarter car, ``n`` cars, each substep
:func:`fricenv.plants.compiled.substep_cars`: the ROS2 substep of :mod:`fricenv.plants.rosenbrock` compiled) and
:class:`fricenv.envs.effect_plant.EffectPlant` (the quarter car with unmodelled effects).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from fricenv.plants import compiled
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import longitudinal_slip, magic_formula

__all__ = ["BatchPlant", "BrakingPlant"]


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

    def limit_terms(self, i: int) -> dict[str, float] | None: ...


class BatchPlant:
    """``n`` nominal quarter cars (eq. (1)), one ROS2 substep of all of them per :meth:`substep` call (compiled,
    with the refinement of :func:`fricenv.plants.quarter_car.step`).

    :param n: number of cars.
    :param h: physics substep [s].
    :param p: quarter-car parameters.
    """

    def __init__(self, n: int, h: float, p: qc.QuarterCarParams = qc.PAPER_PARAMS):
        self.n, self.h, self.p = int(n), float(h), p
        self.road = np.zeros((self.n, 5))  # (B, C, E, theta, mu(1)) per car
        self.r_eff = np.full(self.n, p.r)
        self.v, self.omega = np.zeros(self.n), np.zeros(self.n)
        self.Tb = np.zeros(self.n)

    def reset(self, idx, v, omega) -> None:
        """Set the speeds of cars ``idx``."""
        self.v[idx], self.omega[idx] = v, omega

    def new_episode(self, i: int, rng: np.random.Generator) -> None:
        """Nothing to draw: the nominal plant has no random parameters."""

    def limit_terms(self, i: int) -> None:
        """The road's peak friction alone sets the nominal car's physical limit."""

    def set_road(self, idx, road) -> None:
        """Road rows (B, C, E, theta) of cars ``idx``."""
        road = np.asarray(road, dtype=float).reshape(-1, 4)
        self.road[idx, :4] = road
        self.road[idx, 4] = magic_formula(1.0, road[:, 0], road[:, 1], road[:, 2], road[:, 3])

    def set_road_constants(self, idx, constants) -> None:
        """Road rows (B, C, E, theta, mu(1)) of cars ``idx``, ``mu(1)`` computed by the caller."""
        self.road[idx] = constants

    def set_torque(self, Tb) -> None:
        """Brake torques [N m] of all cars for the following substeps."""
        np.copyto(self.Tb, Tb)

    def substep(self) -> tuple[np.ndarray, np.ndarray]:
        """One ROS2 substep of every car; the state arrays are replaced (callers may keep the old ones)."""
        v, w, p = np.empty(self.n), np.empty(self.n), self.p
        compiled.substep_cars(self.v, self.omega, self.Tb, self.road, self.h, p.r, p.m, p.J, p.Fz, v, w)
        self.v, self.omega = v, w
        return v, w

    def slip(self) -> np.ndarray:
        return longitudinal_slip(self.v, self.omega, self.p.r)

    def friction(self, slip: np.ndarray | None = None) -> np.ndarray:
        """:func:`fricenv.plants.tire.magic_formula` of the slip now (``slip`` if given: the caller's copy)."""
        road = self.road
        return magic_formula(self.slip() if slip is None else slip, road[:, 0], road[:, 1], road[:, 2], road[:, 3])

    def tire_force(self) -> np.ndarray:
        return self.p.Fz * self.friction()

    def accel(self) -> np.ndarray:
        return -self.tire_force() / self.p.m
