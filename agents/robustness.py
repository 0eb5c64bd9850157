"""The estimators under the effect grid: speed, slip and friction errors on stops of a plant with effects.

One stop (:func:`simulate_stop`) is the gap tool's stand-in driven by its ``abs`` or ``open-loop`` driver
(:func:`fricenv.gap.quarter_car.simulate.make_driver`) on a preset road, with one cell of the effect grid
(:mod:`fricenv.effects.grid`) switched on: the quarter car with effects (:class:`fricenv.effects.EffectSimulator`,
:data:`SUBSTEPS` physics substeps per 10 ms sample), an initial speed uniform on 20-32 m/s, a free-rolling stretch
of 0.3-0.6 s, wheel-speed noise of the paper's variance and accelerometer noise (the stand-in's), until the car is
slower than 3 m/s or after :data:`DURATION` seconds. The seed draws the speed, the free roll, the driver and the noise;
every cell of a (driver, road, seed) uses the same draws.

Every estimator of :data:`ESTIMATORS` (the env estimators, built as ``Braking-v0`` builds them) runs over the stop's
measured signals (wheel speed, commanded torque, ``a_x`` where it reads it: as a measurement, or as the input whose
integral is the car's speed for ``ekf-ax`` and ``mhe-ax``), started from the measured free-rolling speed, its
model on the nominal vehicle parameters or, told the radius, on a radius-error cell's rolling radius
(:func:`model_params`). Metrics
per stop (:func:`stop_metrics`), after the first :data:`SETTLE_S` seconds of the stop: rms error of the speed, of
the slip (the true slip with the plant's own rolling radius) and of the friction in use (tire force over wheel
load); the worst speed error over the whole stop; the share of samples with each health value of
:class:`estimators.base.Health`.

:func:`study` maps the stops over a process pool or Ray (:func:`fricenv.gap.core.pool.map_tasks`) and returns one row per
stop and estimator; :func:`summarize` groups them per (estimator, cell) over drivers, roads and seeds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from fricenv.effects.grid import GridCell, cell_effects, grid_cells

if TYPE_CHECKING:
    from fricenv.plants.quarter_car import QuarterCarParams

__all__ = [
    "DRIVERS",
    "ESTIMATORS",
    "MAX_ERROR",
    "MAX_FLAGS",
    "RMS_FACTOR",
    "RMS_MARGIN",
    "ROADS",
    "SETTLE_S",
    "Stop",
    "mark_targets",
    "meets_target",
    "model_params",
    "run_estimator",
    "simulate_stop",
    "stop_metrics",
    "study",
    "summarize",
]

ESTIMATORS = ("ekf", "mhe", "ekf-rls", "ekf-full", "mhe-full", "ekf-ax", "mhe-ax")
DRIVERS = ("abs", "open-loop")
ROADS = ("dry", "wet", "snow")
SETTLE_S = 0.5  # errors count from this long after the brake is first applied [s]
DURATION = 5.0  # longest stop [s]
DT = 0.01  # sample time [s]
SUBSTEPS = 5  # physics substeps per 10 ms sample (the plant's verified setting)
A_X_NOISE_STD = 0.1  # accelerometer noise [m/s^2], as the gap tool's stand-in
# The estimators' target under an effect: rms speed error within RMS_FACTOR x the same stop's error on the nominal
# plant + RMS_MARGIN, never MAX_ERROR off the true speed, OUTLIER and REINITIALISED flags on at most MAX_FLAGS of the
# samples (the flags are false: a stop has no spike).
RMS_FACTOR = 2.0  # [-]
RMS_MARGIN = 0.1  # [m/s]
MAX_ERROR = 1.5  # [m/s]
MAX_FLAGS = 0.01  # [-]


@dataclass(frozen=True)
class Stop:
    """One simulated stop: measured signals and the truth, per 10 ms sample.

    :param t: time [s]; :param omega: measured wheel speed [rad/s]; :param a_x: measured acceleration [m/s^2];
    :param T_b: commanded torque [N m]; :param v: true speed [m/s]; :param slip: true slip [-];
    :param mu: true friction in use (tire force / wheel load) [-]; :param brake_start: first braking sample;
    :param v0: initial speed [m/s]; :param effects: the cell's ``effects`` entries.
    """

    t: np.ndarray
    omega: np.ndarray
    a_x: np.ndarray
    T_b: np.ndarray
    v: np.ndarray
    slip: np.ndarray
    mu: np.ndarray
    brake_start: int
    v0: float
    effects: list


def simulate_stop(cell: GridCell, road: str, driver: str, seed: int, duration: float = DURATION) -> Stop:
    """One stop of the stand-in with the cell's effect (module docstring).

    :param cell: the grid cell.
    :param road: ``dry``, ``wet``, ``snow`` or ``ice``.
    :param driver: ``abs`` or ``open-loop``.
    :param seed: draws the initial speed, the free roll, the driver and the noise.
    :param duration: longest stop [s].
    """
    from fricenv.effects.quarter_car import EffectSimulator, ModelBatch
    from fricenv.envs.effect_spec import resolve_effects
    from fricenv.gap.quarter_car import simulate as gs
    from fricenv.plants import quarter_car as qc
    from fricenv.plants.tire import get_road, longitudinal_slip

    p, dt, tire = qc.PAPER_PARAMS, gs.DT, get_road(road)
    if abs(dt - DT) > 1e-12:
        raise ValueError(f"the stand-in samples at {dt} s, the study at {DT} s")
    rng = np.random.default_rng(seed)
    v0 = float(rng.uniform(*gs.V0_RANGE))
    n = round(duration / dt)
    free = round(rng.uniform(*gs.FREE_ROLL) / dt)
    entries = cell_effects(cell, tire, v0, p)
    drive = gs.make_driver(driver, tire, p, v0, n, free, dt, rng)
    batch = ModelBatch.from_effects(tire, resolve_effects(entries), p)
    sim = EffectSimulator(batch, dt, n, p, SUBSTEPS)
    sim.reset(np.array([v0]), np.array([v0 / batch.r_eff[0]]))
    w_noise = np.sqrt(gs.OMEGA_NOISE_VAR)
    rec: dict[str, list[float]] = {k: [] for k in ("t", "omega", "a_x", "T_b", "v", "slip", "mu")}
    for k in range(n):
        if sim.v[0] < gs.V_END:
            break
        omega = float(sim.omega[0] + w_noise * rng.standard_normal())
        cmd = drive(k, k * dt, omega) if callable(drive) else float(drive[k])
        force = float(sim.tire_force()[0])
        for name, value in (("t", k * dt), ("omega", omega), ("T_b", cmd), ("v", float(sim.v[0])),
                            ("a_x", float(sim.accel()[0] + A_X_NOISE_STD * rng.standard_normal())),
                            ("slip", float(longitudinal_slip(sim.v[0], sim.omega[0], batch.r_eff[0]))),
                            ("mu", force / p.Fz)):
            rec[name].append(value)
        sim.step(np.array([cmd]))
    arr = {k: np.asarray(v) for k, v in rec.items()}
    return Stop(**arr, brake_start=free, v0=v0, effects=entries)


def run_estimator(name: str, stops: Sequence[Stop], p: QuarterCarParams | None = None) -> list[dict[str, np.ndarray]]:
    """Run the env estimator ``name`` over each stop: its speed, slip, friction in use and health per sample.

    An estimator with a batched form (:data:`estimators.batched.BATCHED`, equal to the single one; what the
    native vector env runs) runs every stop in one batch, a stop that has ended holding its last sample; the
    others run one stop after the other.

    :param p: the vehicle parameters the estimator's model uses (default the nominal
        :data:`~fricenv.plants.quarter_car.PAPER_PARAMS`, whatever the stop's plant: the matrix measures the
        estimators as the env builds them; a calibrated radius goes in here).
    """
    from estimators.batched import make_batched
    from estimators.registry import get_estimator
    from fricenv.gap.quarter_car.simulate import OMEGA_NOISE_VAR
    from fricenv.plants import quarter_car as qc

    p = qc.PAPER_PARAMS if p is None else p
    values = dict(get_estimator(name).values)
    keys = {q: values.get(q, q) for q in ("v", "slip", "mu")}
    starts = np.array([float(s.omega[0]) * p.r for s in stops])
    v_std = float(np.sqrt(OMEGA_NOISE_VAR)) * p.r  # one free-rolling wheel sample's spread, as the env says it
    batched = make_batched(name, len(stops), p, DT)
    if batched is None:
        return [_run_single(name, stop, v0, v_std, keys, p) for stop, v0 in zip(stops, starts)]
    lengths = np.array([len(s.t) for s in stops])
    out = {q: np.zeros((len(stops), lengths.max())) for q in (*keys, "health")}
    batched.reset(np.ones(len(stops), dtype=bool), starts)
    for k in range(lengths.max()):
        idx = np.minimum(k, lengths - 1)
        vals, health = batched.update(np.array([s.omega[i] for s, i in zip(stops, idx)]),
                                      np.array([s.a_x[i] for s, i in zip(stops, idx)]),
                                      np.array([s.T_b[i] for s, i in zip(stops, idx)]))
        for q, key in keys.items():
            out[q][:, k] = vals[key]
        out["health"][:, k] = health
    return [{q: (a[j, :n].astype(int) if q == "health" else a[j, :n]) for q, a in out.items()}
            for j, n in enumerate(lengths)]


def _run_single(name: str, stop: Stop, v_start: float, v_std: float, keys: dict[str, str],
                p: QuarterCarParams) -> dict[str, np.ndarray]:
    """One single estimator (its model on the vehicle parameters ``p``) over one stop, started as the env starts it
    from the wheel's ``v_start`` and its spread ``v_std`` (:func:`estimators.base.reset_from_wheel`)."""
    from estimators.base import reset_from_wheel
    from estimators.registry import get_estimator

    est = get_estimator(name).make(p, DT)
    columns = {"omega": stop.omega, "a_x": stop.a_x, "T_b": stop.T_b}
    y = np.column_stack([columns[c] for c in est.measurement_columns])
    u = np.column_stack([columns[c] for c in est.input_columns])
    reset_from_wheel(est, v_start, v_std)
    out: dict[str, list[float]] = {q: [] for q in (*keys, "health")}
    for k in range(len(stop.t)):
        e = est.update(y[k], u[k])
        for q, key in keys.items():
            out[q].append(float(np.asarray(e.values[key], dtype=float)))
        out["health"].append(int(e.health))
    return {q: np.asarray(v) for q, v in out.items()}


def stop_metrics(stop: Stop, estimate: dict[str, np.ndarray]) -> dict[str, Any]:
    """Errors of one estimator on one stop (module docstring); the health shares by :class:`Health` name."""
    from estimators.base import Health

    start = stop.brake_start + round(SETTLE_S / DT)
    after = slice(min(start, len(stop.t)), None)

    def rms(q: str) -> float:
        err = estimate[q][after] - getattr(stop, q)[after]
        return float(np.sqrt(np.mean(err ** 2))) if err.size else float("nan")

    health = estimate["health"]
    return {"v_rms": rms("v"), "slip_rms": rms("slip"), "mu_rms": rms("mu"),
            "v_worst": float(np.max(np.abs(estimate["v"] - stop.v))) if stop.v.size else float("nan"),
            "health": {h.name.lower(): float(np.mean(health == int(h))) for h in Health},
            "samples": len(stop.t)}


def model_params(stop: Stop, told_radius: bool = False) -> QuarterCarParams:
    """The vehicle parameters of the estimators' model on ``stop``: the nominal ones, or, ``told_radius``, the
    rolling radius of the stop's ``radius_error`` effect (as a calibration, such as the gap tool's ``radius_error``
    verdict, gives it)."""
    from dataclasses import replace

    from fricenv.plants.quarter_car import PAPER_PARAMS

    radius = [e["params"]["r_eff"] for e in stop.effects if e["effect"] == "radius_error"] if told_radius else []
    return replace(PAPER_PARAMS, r=float(radius[0])) if radius else PAPER_PARAMS


def meets_target(rms: float, nominal_rms: float, worst: float, flags: float) -> bool:
    """The estimators' target under an effect (``RMS_FACTOR``, ``RMS_MARGIN``, ``MAX_ERROR``, ``MAX_FLAGS``).

    :param rms: rms speed error of the stop [m/s]; :param nominal_rms: the same estimator's on the same stop of the
        nominal plant; :param worst: largest speed error [m/s]; :param flags: share of samples flagged [-].
    """
    return rms <= RMS_FACTOR * nominal_rms + RMS_MARGIN and worst <= MAX_ERROR and flags <= MAX_FLAGS


def _stops_job(cells: tuple[GridCell, ...], road: str, driver: str, seed: int, estimators: tuple[str, ...],
               told_radius: bool = False) -> list[dict[str, Any]]:
    """The stops of every cell for one (road, driver, seed), every estimator over them (each batch of stops with
    one model, :func:`model_params`): per cell, the stop's effects and speed and one metrics dict per estimator."""
    stops = [simulate_stop(cell, road, driver, seed) for cell in cells]
    params = [model_params(stop, told_radius) for stop in stops]
    metrics: list[list[dict]] = [[] for _ in cells]
    for name in estimators:
        for p in dict.fromkeys(params):
            batch = [j for j, q in enumerate(params) if q == p]
            for j, est in zip(batch, run_estimator(name, [stops[j] for j in batch], p)):
                metrics[j].append({"estimator": name, **stop_metrics(stops[j], est)})
    return [{"effects": stop.effects, "v0": stop.v0, "metrics": m} for stop, m in zip(stops, metrics)]


def study(estimators: Sequence[str] = ESTIMATORS, cells: Sequence[GridCell] | None = None,
          roads: Sequence[str] = ROADS, drivers: Sequence[str] = DRIVERS, seeds: Sequence[int] = (0, 1, 2),
          workers: int | None = None, ray: str | None = None, told_radius: bool = False) -> list[dict[str, Any]]:
    """Every estimator on every (cell, road, driver, seed) stop; one row per stop and estimator.

    :param estimators: env estimator names (:data:`ESTIMATORS` by default).
    :param cells: grid cells (default: the nominal plant and every effect at both sizes).
    :param roads: preset roads; :param drivers: ``abs`` and/or ``open-loop``; :param seeds: stop seeds.
    :param workers: local processes (default min(2, CPUs)); not used with ``ray``.
    :param ray: None, ``"auto"`` or a Ray cluster address.
    :param told_radius: the estimators' model takes a ``radius_error`` cell's rolling radius
        (:func:`model_params`); every other cell, and by default every cell, the nominal parameters.
    :return: rows with ``estimator``, ``cell``, ``effects``, ``road``, ``driver``, ``seed``, the metrics and
        ``meets_target`` (:func:`mark_targets`).
    """
    from fricenv.envs.estimator_observation import check_estimator_name
    from fricenv.gap.core.pool import default_jobs, map_tasks
    from fricenv.plants.tire import get_road

    for name in estimators:
        if check_estimator_name(name) in ("none", "oracle"):
            raise ValueError(f"estimator {name!r} runs no estimator; valid: {', '.join(ESTIMATORS)}")
    for road in roads:
        get_road(road)
    for driver in drivers:
        if driver not in DRIVERS:
            raise ValueError(f"unknown driver {driver!r}; valid: {', '.join(DRIVERS)}")
    if not seeds:
        raise ValueError("seeds must name at least one seed")
    cells = grid_cells() if cells is None else list(cells)
    jobs = [(tuple(cells), r, d, int(s), tuple(estimators), told_radius)
            for d in drivers for r in roads for s in seeds]
    results = map_tasks(_stops_job, jobs, default_jobs(workers), "stops", ray=ray)
    rows = []
    for (_, road, driver, seed, _, _), per_cell in zip(jobs, results):
        for cell, res in zip(cells, per_cell):
            for r in res["metrics"]:
                rows.append({"estimator": r["estimator"], "cell": cell.label, "effects": res["effects"],
                             "road": road, "driver": driver, "seed": seed, "v0": res["v0"],
                             **{k: v for k, v in r.items() if k != "estimator"}})
    return mark_targets(rows)


def mark_targets(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows of :func:`study` with ``meets_target``: :func:`meets_target` against the same estimator's row on the
    same stop (road, driver, seed) of the nominal plant; None on the nominal plant or without its row."""
    nominal = {(r["estimator"], r["road"], r["driver"], r["seed"]): r["v_rms"] for r in rows if r["cell"] == "nominal"}
    out = []
    for r in rows:
        base = nominal.get((r["estimator"], r["road"], r["driver"], r["seed"]))
        flags = r["health"]["outlier"] + r["health"]["reinitialised"]
        met = None if r["cell"] == "nominal" or base is None else meets_target(r["v_rms"], base, r["v_worst"], flags)
        out.append({**r, "meets_target": met})
    return out


def summarize(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (estimator, cell) over drivers, roads and seeds: mean of the rms errors (rms over stops), the worst
    speed error, the mean health shares and the stops missing the target (``missed``; nan on the nominal plant)."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        groups.setdefault((r["estimator"], r["cell"]), []).append(r)
    out = []
    for (est, cell), mine in groups.items():
        health_names = list(mine[0]["health"])
        out.append({"estimator": est, "cell": cell,
                    **{k: float(np.sqrt(np.nanmean([m[k] ** 2 for m in mine]))) for k in
                       ("v_rms", "slip_rms", "mu_rms")},
                    "v_worst": float(np.nanmax([m["v_worst"] for m in mine])),
                    "health": {h: float(np.mean([m["health"][h] for m in mine])) for h in health_names},
                    "missed": (float("nan") if any(m.get("meets_target") is None for m in mine)
                               else float(sum(not m["meets_target"] for m in mine))),
                    "stops": len(mine)})
    return out
