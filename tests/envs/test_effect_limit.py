"""The physical limit of a plant whose effects move it (a friction change in time, drag), against solve_ivp."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import fricenv  # noqa: F401  (registers the envs)
from agents.controllers import make_controller, rollout
from fricenv.effects.grid import grid_effect
from fricenv.envs.scenario import effect_limit_distance, limit_distance
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import DRY, ICE, WET

G, M = qc.PAPER_PARAMS.g, qc.PAPER_PARAMS.m


def _limit_ivp(v0, v_stop, mu_a, mu_b, change_distance, t_change, factor_a, factor_b, c0, c2) -> float:
    """The limit car integrated: m v' = -(m g mu_peak(t, x) + c0 + c2 v^2), x' = v, to v_stop."""

    def rhs(t, y):
        v, x = y
        on_b, after = x >= change_distance, t >= t_change
        mu = mu_b * (factor_b if after else 1.0) if on_b else mu_a * (factor_a if after else 1.0)
        return [-(G * mu + (c0 + c2 * v * v) / M), v]

    def stopped(t, y):
        return y[0] - v_stop

    stopped.terminal = True
    sol = solve_ivp(rhs, (0.0, 120.0), [v0, 0.0], events=stopped, rtol=1e-11, atol=1e-11, max_step=1e-3)
    return float(sol.y_events[0][0][1])


CASES = [  # v0, v_stop, mu_a, mu_b, change distance, t_change, factor a, factor b, c0, c2
    (20.0, 2.0, DRY.mu_max, DRY.mu_max, math.inf, 1.0, 0.6, 1.0, 0.0, 0.0),  # friction drop in mid-stop
    (20.0, 2.0, WET.mu_max, WET.mu_max, math.inf, math.inf, 1.0, 1.0, 150.0, 0.6),  # drag alone
    (30.0, 2.0, DRY.mu_max, ICE.mu_max, 15.0, 0.5, 1.3, 1.3, 60.0, 0.3),  # all: time event before the road's
    (30.0, 2.0, ICE.mu_max, DRY.mu_max, 40.0, 3.0, 0.6, 0.6, 150.0, 0.6),  # road's change before the time's
]


@pytest.mark.parametrize("case", CASES)
def test_effect_limit_equals_the_integrated_limit_car(case):
    v0, v_stop, mu_a, mu_b, d, t_change, fa, fb, c0, c2 = case
    got = effect_limit_distance(v0, v_stop, mu_a, mu_b, d, t_change=t_change, mu_factor_a=fa, mu_factor_b=fb,
                                c0=c0, c2=c2)
    assert got == pytest.approx(_limit_ivp(*case), rel=1e-7)


def test_without_effects_the_limit_is_the_roads():
    for d in (math.inf, 15.0):
        plain = float(limit_distance(30.0, 2.0, DRY.mu_max, ICE.mu_max, d))
        assert effect_limit_distance(30.0, 2.0, DRY.mu_max, ICE.mu_max, d) == pytest.approx(plain, rel=1e-12)
    # a friction change after the limit car has stopped does not move it
    late = effect_limit_distance(20.0, 2.0, DRY.mu_max, DRY.mu_max, math.inf, t_change=5.0, mu_factor_a=0.6)
    assert late == pytest.approx(float(limit_distance(20.0, 2.0, DRY.mu_max, DRY.mu_max, math.inf)), rel=1e-12)


def test_a_car_nothing_decelerates_is_rejected():
    with pytest.raises(ValueError, match="nothing decelerates"):
        effect_limit_distance(20.0, 2.0, DRY.mu_max, DRY.mu_max, math.inf, t_change=0.5, mu_factor_a=0.0)


@pytest.mark.parametrize("road", ["dry", "wet"])
def test_slip_control_on_the_true_slip_is_near_the_limit_of_a_friction_drop(road):
    """The ratio's limit is the plant's: through a drop to 0.6 theta in mid-stop the controller that reads the
    true slip stops within 5 % of it (against the road's limit it read 1.20)."""
    effect = grid_effect("mu_change", "low", road, 20.0)
    env = gym.make("fricenv/Braking-v0", road=road, v0=20.0, observation="oracle", effects=[effect]).unwrapped
    info = rollout(env, make_controller("oracle-slip", env), seed=0).info
    p = effect["params"]
    mu = env.road.mu_max
    expected = effect_limit_distance(20.0, 2.0, mu, mu, math.inf, t_change=p["t_change"],
                                     mu_factor_a=p["theta_after"] / env.road.theta)
    assert info["limit_distance"] == pytest.approx(expected, rel=1e-12)
    assert info["limit_distance"] > float(limit_distance(20.0, 2.0, mu, mu, math.inf)) * 1.1
    assert 1.0 <= info["ratio"] < 1.05


def test_drag_shortens_the_limit_and_the_nominal_plant_keeps_the_roads():
    drag = [{"effect": "drag", "params": {"c0": 150.0, "c2": 0.6}}]
    limits = []
    for effects in (None, drag):
        env = gym.make("fricenv/Braking-v0", road="wet", v0=20.0, effects=effects).unwrapped
        env.reset(seed=0)
        env.step(np.zeros(1, dtype=np.float32))
        limits.append(env.sim.limit[0])
    assert limits[0] == pytest.approx(float(limit_distance(20.0, 2.0, WET.mu_max, WET.mu_max, math.inf)), rel=1e-12)
    assert limits[1] == pytest.approx(effect_limit_distance(20.0, 2.0, WET.mu_max, WET.mu_max, math.inf, c0=150.0,
                                                            c2=0.6), rel=1e-12)
    assert limits[1] < limits[0]
