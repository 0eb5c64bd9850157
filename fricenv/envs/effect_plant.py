"""The quarter car with unmodelled effects as a :class:`~fricenv.plants.braking_plant.BrakingPlant`: the corrected
simulator under the braking episode (``gymnasium.make("fricenv/Braking-v0", effects=...)``).

The cars are the elements of one :class:`fricenv.effects.quarter_car.EffectSimulator` (its public API:
``ModelBatch.from_effects``, ``replace_element``, ``reset_elements``, ``step``, ``tire_force``, ``accel``) run with
a sample time of one physics substep and one substep per sample, so the episode sees every substep (the stop and a
friction change are located inside it, as on the nominal plant). The actuator effects are exact over a zero-order-held substep (the lag's exact solution, the delay's exact
average), so this equals the effect simulator's own 10 ms samples of 5 substeps. A car's element is replaced at
each of its episodes, with the episode's effects (fixed, or drawn from the car's generator by an
:class:`~fricenv.envs.effect_spec.EffectRandomization`).

Conventions: time 0 of ``mu_change``'s ``t_change`` is the episode start; the plant's ``r_eff`` (``radius_error``)
sets free rolling at reset, the slip and the lock test, while the ECU's wheel deceleration keeps the nominal radius.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fricenv.effects.quarter_car import EffectSimulator, ModelBatch
from fricenv.envs.effect_spec import EffectRandomization, parse_randomization, resolve_effects
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import DRY, longitudinal_slip

__all__ = ["EffectPlant", "effect_plant_or_none"]


class EffectPlant:
    """``n`` quarter cars with effects (see the module docstring); members of
    :class:`~fricenv.plants.braking_plant.BrakingPlant` on arrays of shape (n,).

    The cars are the elements of one :class:`~fricenv.effects.quarter_car.EffectSimulator`; a car beginning an
    episode gets its new effects by :meth:`~fricenv.effects.quarter_car.EffectSimulator.replace_element`, so every
    substep is one numpy call over all cars.

    :param n: number of cars.
    :param h: physics substep [s].
    :param p: nominal quarter-car parameters.
    :param effects: effect specs of every car (:func:`fricenv.effects.quarter_car.make_effect`).
    :param randomization: per-episode draws (replace ``effects`` when given; built with the fixed ones).
    :param max_substeps: substeps of the longest episode (the command history's length).
    """

    def __init__(self, n: int, h: float, p: qc.QuarterCarParams = qc.PAPER_PARAMS, effects: Sequence = (),
                 randomization: EffectRandomization | None = None, max_substeps: int = 30000):
        self.n, self.h, self.p = int(n), float(h), p
        self.fixed, self.randomization = tuple(effects), randomization
        self.effects: list[tuple] = [self.fixed] * self.n  # the effects of each car's current episode
        self.road = np.tile(DRY.as_array(), (self.n, 1))
        element = ModelBatch.from_effects(self.road[0], self.fixed, p)
        self.sim = EffectSimulator(ModelBatch.stack([element] * self.n), self.h, int(max_substeps) + 2, p, 1, t0=0.0)
        self._started = np.zeros(self.n, dtype=bool)
        self.v, self.omega, self.Tb = np.zeros(self.n), np.zeros(self.n), np.zeros(self.n)

    def new_episode(self, i: int, rng: np.random.Generator) -> None:
        """Car ``i``'s effects for its next episode (drawn from ``rng`` if randomised), its simulator state afresh."""
        effects = self.randomization.draw(rng) if self.randomization is not None else self.fixed
        self.effects[i] = effects
        self.sim.replace_element(i, ModelBatch.from_effects(self.road[i], effects, self.p))
        self._started[i] = True

    @property
    def r_eff(self) -> np.ndarray:
        """Rolling radius of every car [m] (its episode's ``radius_error``, else the nominal radius)."""
        return self.sim.batch.r_eff

    def reset(self, idx, v, omega) -> None:
        """Set the speeds of cars ``idx`` (lag state 0, transient slip at the slip of the state)."""
        idx = np.atleast_1d(np.arange(self.n)[idx])
        if not np.all(self._started[idx]):
            raise RuntimeError("EffectPlant: reset the car (new_episode) before stepping it")
        v, omega = np.broadcast_to(v, idx.shape), np.broadcast_to(omega, idx.shape)
        self.sim.reset_elements(idx, v, omega)
        self.v, self.omega = self.v.copy(), self.omega.copy()
        self.v[idx], self.omega[idx] = v, omega

    def set_road(self, idx, road) -> None:
        """Road rows (B, C, E, theta) of cars ``idx`` (a friction change at a distance switches it)."""
        self.road[idx] = road
        self.sim.batch.road[idx] = self.road[idx]

    def set_torque(self, Tb) -> None:
        """Commanded brake torques [N m]; the effects act on them (lag, delay, gain)."""
        self.Tb = np.array(np.broadcast_to(np.asarray(Tb, dtype=float), (self.n,)))

    def substep(self) -> tuple[np.ndarray, np.ndarray]:
        """One substep of every car (each reset first, which :meth:`reset` checks); new state arrays."""
        v, w = self.sim.step(self.Tb)
        self.v, self.omega = v.copy(), w.copy()
        return self.v, self.omega

    def slip(self) -> np.ndarray:
        return longitudinal_slip(self.v, self.omega, self.r_eff)

    def tire_force(self) -> np.ndarray:
        """F_x [N] of every car (through the transient slip with ``relaxation_length``, the changed theta...)."""
        return self.sim.tire_force()

    def friction(self, slip: np.ndarray | None = None) -> np.ndarray:
        """F_x / F_z (``slip`` is not needed: with ``relaxation_length`` the force follows the transient slip)."""
        return self.tire_force() / self.p.Fz

    def accel(self) -> np.ndarray:
        return self.sim.accel()

    def limit_terms(self, i: int) -> dict[str, float] | None:
        """What in car ``i``'s episode moves the physical limit: a friction change in time (``t_change``,
        ``theta_after``) and drag (``c0``, ``c2``); None without them. The other library effects (the brake's lag,
        delay and gain, the rolling radius, a relaxation length) leave the tire's peak and the forces on the car
        as they are."""
        b = self.sim.batch
        terms = {"t_change": float(b.t_change[i]), "theta_after": float(b.theta_after[i]),
                 "c0": float(b.c0[i]), "c2": float(b.c2[i])}
        if not np.isfinite(terms["t_change"]) and terms["c0"] == 0.0 and terms["c2"] == 0.0:
            return None
        return terms


def effect_plant_or_none(n: int, config, effects=None, effects_randomization=None) -> EffectPlant | None:
    """The plant for a braking env's ``effects``/``effects_randomization`` arguments: None (the nominal plant,
    exactly the plain env) when both give no effect, else an :class:`EffectPlant`.

    :param n: number of cars.
    :param config: the env's :class:`~fricenv.envs.config.BrakingConfig`.
    :param effects: see :func:`fricenv.envs.effect_spec.resolve_effects`.
    :param effects_randomization: see :func:`fricenv.envs.effect_spec.parse_randomization`.
    :raises fricenv.envs.effect_spec.EffectSpecError: unknown or malformed effects.
    """
    fixed = resolve_effects(effects)
    randomization = parse_randomization(effects_randomization, fixed)
    if not fixed and randomization is None:
        return None
    return EffectPlant(n, config.dt / config.substeps, config.params, fixed, randomization,
                       config.max_steps * config.substeps)
