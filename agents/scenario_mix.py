"""The training road curriculum of the ABS task: one scenario draw per episode, for single and vector envs.

:class:`ScenarioSampler` is the draw, ``rng -> reset options``: either a preset road (dry, wet, snow, ice;
probability ``1 - change_probability``) or a friction change between two different presets at a distance drawn on
:data:`CHANGE_RANGE`, and an initial speed uniform on :data:`V0_RANGE`. A stop lasts about ``1 / mu_max`` as long
on one road as on another (ice: 10 times dry), so drawing roads uniformly would fill the rollouts with ice. With
``step_balanced`` (default) a preset road is drawn with probability proportional to its peak friction, which gives
every road about the same share of *steps*. A friction change is uniform over the ordered pairs of different
presets (a first version weighted its first road too, and then almost never showed ice->dry: that policy braked
ice->dry at 1.5-1.6 times the limit). Wet's early peak (slip 0.088) and both jump directions are in the mix.

:class:`ScenarioMix` applies it to a single env (a generator seeded by ``reset(seed=...)``); the native vector env
takes the same sampler (``BrakingVectorEnv(scenarios=...)``, one generator per sub-env seeded with its seed), so
both draw the same scenarios from the same seeds.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from fricenv.envs.scenario import SCENARIO_SEPARATOR

__all__ = ["CHANGE_PROBABILITY", "CHANGE_RANGE", "V0_RANGE", "ScenarioMix", "ScenarioSampler"]

V0_RANGE = (15.0, 32.0)  # initial speeds drawn for training [m/s] (evaluation uses 20 and 30 m/s)
CHANGE_PROBABILITY = 0.4  # share of training episodes with a friction change during the stop
CHANGE_RANGE = (5.0, 30.0)  # distance of a training friction change [m]


@dataclass(frozen=True)
class ScenarioSampler:
    """Reset options of one training scenario per call (module docstring).

    :param change_probability: share of episodes with a friction change [-].
    :param v0_range: initial speed range [m/s].
    :param step_balanced: weight roads by their peak friction (else uniform per episode).
    """

    change_probability: float = CHANGE_PROBABILITY
    v0_range: tuple[float, float] = V0_RANGE
    step_balanced: bool = True
    roads: tuple[str, ...] = field(init=False)
    road_probabilities: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        from fricenv.plants.tire import ROADS

        if not 0.0 <= self.change_probability <= 1.0:
            raise ValueError(f"change_probability must be in [0, 1], got {self.change_probability!r}")
        object.__setattr__(self, "v0_range", (float(self.v0_range[0]), float(self.v0_range[1])))
        object.__setattr__(self, "roads", tuple(ROADS))
        weights = np.array([ROADS[r].mu_max if self.step_balanced else 1.0 for r in self.roads])
        object.__setattr__(self, "road_probabilities", weights / weights.sum())

    def __call__(self, rng: np.random.Generator) -> dict[str, Any]:
        drawn: dict[str, Any] = {"v0": self.v0_range}
        if rng.random() < self.change_probability:
            # uniform over ordered pairs: ice->dry must be seen as often as dry->ice
            i = int(rng.integers(len(self.roads)))
            j = int(rng.integers(len(self.roads) - 1))
            j = j + 1 if j >= i else j
            drawn["road"] = f"{self.roads[i]}{SCENARIO_SEPARATOR}{self.roads[j]}"
            drawn["change_distance"] = float(rng.uniform(*CHANGE_RANGE))
        else:
            drawn["road"] = self.roads[int(rng.choice(len(self.roads), p=self.road_probabilities))]
        return drawn


class ScenarioMix(gym.Wrapper):
    """Draw a training scenario per episode (:class:`ScenarioSampler`); reset options given explicitly win.

    :param env: a ``Braking-v0`` env (possibly wrapped).
    :param change_probability: share of episodes with a friction change [-].
    :param v0_range: initial speed range [m/s].
    :param step_balanced: weight roads by their peak friction (else uniform per episode).
    """

    def __init__(self, env: gym.Env, change_probability: float = CHANGE_PROBABILITY,
                 v0_range: tuple[float, float] = V0_RANGE, step_balanced: bool = True):
        super().__init__(env)
        self.sampler = ScenarioSampler(change_probability, v0_range, step_balanced)
        self._rng = np.random.default_rng()

    def draw(self) -> dict[str, Any]:
        """Reset options of the next scenario."""
        return self.sampler(self._rng)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        return self.env.reset(seed=seed, options={**self.draw(), **(options or {})})
