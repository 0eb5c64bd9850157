"""Braking scenarios: the road (a preset, a friction change between two presets, or a random draw), where it changes,
the initial speed, and the physical-limit stopping distance of each scenario (of the plant with its effects, when
they move the limit)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import ROADS, MagicFormula, get_road

__all__ = [
    "RESET_OPTION_KEYS",
    "SCENARIO_SEPARATOR",
    "V0_DEFAULT",
    "Scenario",
    "effect_limit_distance",
    "episode_limits",
    "limit_distance",
    "resolve_scenario",
    "valid_road_names",
]

V0_DEFAULT = 20.0  # [m/s]
CHANGE_DISTANCE_DEFAULT = 15.0  # where a friction-change scenario switches road [m]
RANDOM_CHANGE_RANGE = (5.0, 30.0)  # change distance drawn for road="random-change" [m]
RESET_OPTION_KEYS = ("road", "v0", "change_distance")
SCENARIO_SEPARATOR = "->"
RANDOM_ROADS = ("random", "random-change")


@dataclass(frozen=True)
class Scenario:
    """One car's episode set-up: road before/after the friction change, where it changes, initial speed."""

    name: str  # e.g. "dry", "dry->ice"
    road_a: MagicFormula  # road from the start
    road_b: MagicFormula  # road after change_distance (= road_a if no change)
    change_distance: float  # [m]; inf if the road does not change
    v0: float  # initial speed [m/s]


def valid_road_names() -> list[str]:
    """Every road name accepted by :func:`resolve_scenario` (presets, random draws, preset pairs ``a->b``)."""
    pairs = [f"{a}{SCENARIO_SEPARATOR}{b}" for a in ROADS for b in ROADS if a != b]
    return [*ROADS, *RANDOM_ROADS, *pairs]


def _parse_range(value, name: str, low_bound: float) -> tuple[float, float]:
    """A number or a (low, high) pair as a range; raises ValueError naming ``name``."""
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool):
        lo = hi = float(value)
    elif isinstance(value, (tuple, list, np.ndarray)) and len(value) == 2:
        lo, hi = (float(value[0]), float(value[1]))
    else:
        raise ValueError(f"{name} must be a number or a (low, high) pair, got {value!r}")
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi or lo <= low_bound:
        raise ValueError(f"{name} must be finite, with low <= high and > {low_bound}, got {value!r}")
    return lo, hi


def _draw(rng: np.random.Generator, lo: float, hi: float) -> float:
    """A uniform draw on [lo, hi]; no draw (and no generator use) if the range is a single value."""
    return lo if lo == hi else float(rng.uniform(lo, hi))


def resolve_scenario(road: str | MagicFormula, v0, change_distance, v_stop: float,
                     rng: np.random.Generator) -> Scenario:
    """Turn a road spec, an initial-speed spec and a change-distance spec into a :class:`Scenario`.

    Draws come from ``rng`` in a fixed order (road, then change distance, then v0), only for the parts that are
    random, so the same generator state gives the same scenario.

    :param road: a preset name (``dry``, ``wet``, ``snow``, ``ice``), ``"a->b"`` for a friction change from preset
        ``a`` to preset ``b`` at ``change_distance``, ``"random"`` (a preset drawn uniformly), ``"random-change"``
        (two different presets drawn uniformly, change distance drawn on :data:`RANDOM_CHANGE_RANGE` unless
        given as a range), or a :class:`~fricenv.plants.tire.MagicFormula`.
    :param v0: initial speed [m/s], a number or a (low, high) range drawn uniformly.
    :param change_distance: distance of the friction change [m], a number or a (low, high) range.
    :param v_stop: stop speed [m/s]; v0 must exceed it.
    :param rng: the car's generator.
    :return: the scenario.
    """
    names = list(ROADS)
    road_b = None
    if isinstance(road, MagicFormula):
        road_a, name = road, road.name
    elif not isinstance(road, str):
        raise TypeError(f"road must be a road name or a MagicFormula, got {type(road).__name__}; "
                         f"valid names: {', '.join(valid_road_names())}")
    elif road == "random":
        road_a = ROADS[names[int(rng.integers(len(names)))]]
        name = road_a.name
    elif road == "random-change":
        i = int(rng.integers(len(names)))
        j = int(rng.integers(len(names) - 1))
        j = j + 1 if j >= i else j
        road_a, road_b = ROADS[names[i]], ROADS[names[j]]
        name = f"{road_a.name}{SCENARIO_SEPARATOR}{road_b.name}"
    elif SCENARIO_SEPARATOR in road:
        parts = road.split(SCENARIO_SEPARATOR)
        if len(parts) != 2 or parts[0] not in ROADS or parts[1] not in ROADS:
            raise ValueError(f"unknown road {road!r}; valid: {', '.join(valid_road_names())}")
        road_a, road_b = ROADS[parts[0]], ROADS[parts[1]]
        name = road
    elif road in ROADS:
        road_a, name = get_road(road), road
    else:
        raise ValueError(f"unknown road {road!r}; valid: {', '.join(valid_road_names())}")

    if road_b is None:
        distance = math.inf
        road_b = road_a
    else:
        if change_distance is None:
            change_distance = RANDOM_CHANGE_RANGE if road == "random-change" else CHANGE_DISTANCE_DEFAULT
        lo, hi = _parse_range(change_distance, "change_distance", 0.0)
        distance = _draw(rng, lo, hi)
    lo, hi = _parse_range(V0_DEFAULT if v0 is None else v0, "v0", v_stop)
    return Scenario(name=name, road_a=road_a, road_b=road_b, change_distance=distance, v0=_draw(rng, lo, hi))


def limit_distance(v0, v_stop, mu_a, mu_b, change_distance, g: float = qc.PAPER_PARAMS.g):
    """Physical-limit stopping distance [m] with peak friction held the whole way, piecewise over a change.

    On one road this is ``(v0^2 - v_stop^2) / (2 g mu_max)`` (:func:`~fricenv.plants.quarter_car.
    physical_limit_distance`). With a change from ``mu_a`` to ``mu_b`` at distance ``d``: if the limit stop on road
    a ends before ``d`` that is the answer; otherwise the car reaches ``d`` at ``v_d^2 = v0^2 - 2 g mu_a d`` and
    stops on road b, ``d + (v_d^2 - v_stop^2) / (2 g mu_b)``. Broadcasts over arrays.
    """
    v0, mu_a, mu_b, d = (np.asarray(x, dtype=float) for x in (v0, mu_a, mu_b, change_distance))
    first = (v0**2 - v_stop**2) / (2.0 * g * mu_a)
    d_fin = np.where(np.isfinite(d), d, 0.0)
    vd2 = v0**2 - 2.0 * g * mu_a * d_fin
    second = d_fin + (vd2 - v_stop**2) / (2.0 * g * mu_b)
    return np.where(first <= d, first, second)


def effect_limit_distance(v0: float, v_stop: float, mu_a: float, mu_b: float, change_distance: float, *,
                          t_change: float = math.inf, mu_factor_a: float = 1.0, mu_factor_b: float = 1.0,
                          c0: float = 0.0, c2: float = 0.0, m: float = qc.PAPER_PARAMS.m,
                          g: float = qc.PAPER_PARAMS.g) -> float:
    """Physical-limit stopping distance [m] of a plant whose effects move the limit: a friction change in time and
    drag. The limit car brakes at the peak friction of the road under it the whole way, and drag helps it:

    ``m v' = -(m g mu_peak(t, x) + c0 + c2 v^2)``                                                     (L1)

    with ``mu_peak`` = ``mu_a`` before ``change_distance`` and ``mu_b`` after it, each times its factor
    (``mu_factor_a``, ``mu_factor_b``: ``theta_after / theta`` of that road) from ``t_change`` on (time 0 at the start
    of the stop). Between the two events (L1) has constant coefficients, ``v' = -(a + b v^2)`` with
    ``a = g mu_peak + c0 / m``, ``b = c2 / m``, solved in closed form:

    ``x(v1 -> v2) = ln((a + b v1^2) / (a + b v2^2)) / (2 b)``,
    ``t(v1 -> v2) = (atan(k v1) - atan(k v2)) / sqrt(a b)``, ``k = sqrt(b / a)``                     (L2)

    (``(v1^2 - v2^2) / (2 a)`` and ``(v1 - v2) / a`` without drag). With neither effect this is
    :func:`limit_distance`. Drag's ``c0`` acts while the car moves, as :func:`fricenv.effects.library.drag_force`.

    :param v0: initial speed [m/s]; :param v_stop: stop speed [m/s].
    :param mu_a: peak friction before the road's change; :param mu_b: after it.
    :param change_distance: where the road changes [m] (inf: never).
    :param t_change: when the friction changes [s] (inf: never).
    :param mu_factor_a: factor on ``mu_a`` from ``t_change``; :param mu_factor_b: on ``mu_b``.
    :param c0: constant drag [N]; :param c2: quadratic drag [N s^2/m^2]; :param m: vehicle mass [kg].
    :raises ValueError: a phase in which nothing decelerates the car (the limit is infinite).
    """
    b = c2 / m
    t, x, v = 0.0, 0.0, float(v0)
    on_b, after = change_distance <= 0.0, t_change <= 0.0
    while True:
        mu = (mu_b * mu_factor_b if after else mu_b) if on_b else (mu_a * mu_factor_a if after else mu_a)
        a = g * mu + c0 / m
        if not a > 0.0:
            raise ValueError(f"no limit stop: nothing decelerates the car (peak friction {mu}, drag c0 {c0} N)")
        d_end = _phase_distance(a, b, v, v_stop)
        d_road = math.inf if on_b else change_distance - x
        t_left = math.inf if after else t_change - t
        v_time = _speed_after_time(a, b, v, t_left) if t_left < _phase_time(a, b, v, v_stop) else -math.inf
        d_time = _phase_distance(a, b, v, v_time) if v_time > v_stop else math.inf
        if d_end <= min(d_road, d_time):
            return x + d_end
        if d_road <= d_time:  # the road changes first
            v_road = _speed_after_distance(a, b, v, d_road)
            t, x, v, on_b = t + _phase_time(a, b, v, v_road), change_distance, v_road, True
        else:  # the friction changes first
            t, x, v, after = t_change, x + d_time, v_time, True


def episode_limits(plant, idx, v0, v_stop: float, road_a, road_b, mu_a, mu_b, change_distance,
                   p: qc.QuarterCarParams = qc.PAPER_PARAMS) -> np.ndarray:
    """The physical limit [m] of the episodes of cars ``idx`` of ``plant``: :func:`limit_distance` of their
    scenarios, or :func:`effect_limit_distance` for a car whose effects move it (the plant's ``limit_terms``).

    :param plant: a :class:`~fricenv.plants.braking_plant.BrakingPlant`; :param idx: the cars (array of indices).
    :param v0: their initial speeds [m/s]; :param v_stop: the stop speed [m/s].
    :param road_a: their road rows (B, C, E, theta) before the road's change, (k, 4); :param road_b: after it.
    :param mu_a: their peak friction before the change; :param mu_b: after it.
    :param change_distance: where their roads change [m]; :param p: vehicle parameters (m, g).
    """
    limits = np.array(limit_distance(v0, v_stop, mu_a, mu_b, change_distance, p.g), dtype=float, ndmin=1)
    for j, i in enumerate(np.atleast_1d(idx)):
        terms = plant.limit_terms(int(i))
        if terms is not None:
            theta_after = terms["theta_after"]
            limits[j] = effect_limit_distance(
                float(v0[j]), v_stop, float(mu_a[j]), float(mu_b[j]), float(change_distance[j]),
                mu_factor_a=theta_after / road_a[j, 3], mu_factor_b=theta_after / road_b[j, 3], m=p.m, g=p.g,
                t_change=terms["t_change"], c0=terms["c0"], c2=terms["c2"])
    return limits


def _phase_distance(a: float, b: float, v1: float, v2: float) -> float:
    """Distance of ``v' = -(a + b v^2)`` from speed v1 down to v2 (L2) [m]."""
    if b > 0.0:
        return math.log((a + b * v1 * v1) / (a + b * v2 * v2)) / (2.0 * b)
    return (v1 * v1 - v2 * v2) / (2.0 * a)


def _phase_time(a: float, b: float, v1: float, v2: float) -> float:
    """Time of ``v' = -(a + b v^2)`` from speed v1 down to v2 (L2) [s]."""
    if b > 0.0:
        k = math.sqrt(b / a)
        return (math.atan(k * v1) - math.atan(k * v2)) / math.sqrt(a * b)
    return (v1 - v2) / a


def _speed_after_time(a: float, b: float, v1: float, dt: float) -> float:
    """Speed of ``v' = -(a + b v^2)`` ``dt`` after speed v1 (before it reaches 0) [m/s]."""
    if b > 0.0:
        k = math.sqrt(b / a)
        return math.tan(math.atan(k * v1) - math.sqrt(a * b) * dt) / k
    return v1 - a * dt


def _speed_after_distance(a: float, b: float, v1: float, d: float) -> float:
    """Speed of ``v' = -(a + b v^2)`` ``d`` metres after speed v1 (0 if it stops before) [m/s]."""
    if b > 0.0:
        return math.sqrt(max(((a + b * v1 * v1) * math.exp(-2.0 * b * d) - a) / b, 0.0))
    return math.sqrt(max(v1 * v1 - 2.0 * a * d, 0.0))
