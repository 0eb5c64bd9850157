"""Candidate fits: the road plus one or more effects fitted per fold by the effect's registry strategy, in worker
processes, and tested against the nominal model on held-out windows."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np

from fricenv.effects import registry
from fricenv.gap.core.pool import start_tasks
from fricenv.gap.quarter_car.changepoint import fit_change_point
from fricenv.gap.quarter_car.config import DiagnoseConfig
from fricenv.gap.quarter_car.data import Data
from fricenv.gap.quarter_car.fitting import effect_start_matrix, fit, score
from fricenv.gap.quarter_car.params import ROAD_NAMES, param_names
from fricenv.gap.quarter_car.stats import (
    CandidateFit,
    cross_fitted,
    fold_data,
    improvement_z,
    paired_t,
    paired_z,
)
from fricenv.gap.quarter_car.windows import window_nuisances

__all__ = ["FIT_STRATEGIES", "fit_candidate", "nested_nominal", "run_fits", "start_fits", "test_against",
           "without_effects"]


def _least_squares(effects: Sequence[str], road: np.ndarray, d: Data, cfg: DiagnoseConfig,
                   seeds: dict | None = None) -> np.ndarray:
    """Multi-start least squares from the roads times the effects' start lists (``seeds`` replace a list)."""
    return fit(effects, param_names(effects), effect_start_matrix(effects, road, d, seeds), d, cfg,
               runs=int(cfg.fit_starts))


# The registry's fit strategies: (effects, nominal road, data, settings, seeds) -> fitted parameter vector.
FIT_STRATEGIES = {"least_squares": _least_squares, "change_point": fit_change_point}


def fit_candidate(effects: Sequence[str], road: np.ndarray, d: Data, cfg: DiagnoseConfig,
                  seeds: dict | None = None) -> CandidateFit:
    """Fit road + the effects' parameters on the training windows; score on all windows. A single effect is fitted
    by its registry strategy, a joint fit by least squares."""
    t = time.perf_counter()
    effects = list(effects)
    strategy = registry.get(effects[0]).fit if len(effects) == 1 else "least_squares"
    x = FIT_STRATEGIES[strategy](effects, road, d, cfg, seeds)
    return score("+".join(effects), effects, param_names(effects), x, d, time.perf_counter() - t)


def _fit_cost(effects: Sequence[str], d: Data) -> int:
    """Relative cost of a candidate fit: each evaluation simulates (fitted parameters + 1) parameter sets, each with
    one replica per fitted window state (a searched parameter is held during the least squares)."""
    fitted = len(ROAD_NAMES) + sum(len(registry.get(e).param_names) for e in effects)
    if len(effects) == 1:
        fitted -= len(registry.get(effects[0]).searched)
    # a change-point fit searches its switching time, then runs a least squares from each of 2 * fit_starts searched
    # places (measured on clean seed 3104, logs 0-2: 3-5 times a brake gain's fit)
    searched = 4 if len(effects) == 1 and registry.get(effects[0]).fit == "change_point" else 1
    return (fitted + 1) * (1 + window_nuisances(effects, d)) * searched


def start_fits(tasks: list, jobs: int, label: str = "fit candidates") -> Callable[[], list]:
    """Start candidate fits (:func:`fit_candidate` argument tuples) in the worker processes
    (:func:`fricenv.gap.core.pool.start_tasks`), the longest first, which keeps the workers busy; returns ``collect()``,
    which gives the results in task order."""
    order = sorted(range(len(tasks)), key=lambda i: -_fit_cost(tasks[i][0], tasks[i][2]))
    collect = start_tasks(fit_candidate, [tasks[i] for i in order], jobs, label)

    def in_task_order() -> list:
        done = dict(zip(order, collect()))
        return [done[i] for i in range(len(tasks))]

    return in_task_order


def run_fits(tasks: list, jobs: int, label: str = "fit candidates") -> list:
    """Candidate fits (:func:`fit_candidate` argument tuples), in worker processes when there are several, the
    longest first; results in task order."""
    return start_fits(tasks, jobs, label)()


def nested_nominal(nominal: CandidateFit, fits: Sequence[CandidateFit], d: Data, cfg: DiagnoseConfig) \
        -> CandidateFit:
    """The nominal fit, refitted from the candidates' roads when one of them fits the training windows better.

    The nominal model is every candidate with its effect switched off, so its best road is at least as good as any
    candidate's road; a candidate whose multi-start found a better road optimum than the nominal fit would
    otherwise look like an effect (a ``brake_gain`` of 1.000 beating the nominal model).
    """
    starts = np.vstack([nominal.x[None]] + [f.road_x()[None] for f in fits])
    x = fit([], nominal.names, starts, d, cfg)
    better = score("nominal", [], nominal.names, x, d, nominal.seconds)
    return better if better.train_mse < nominal.train_mse else nominal


def without_effects(f: CandidateFit, d: Data, keep: Sequence[str] = ()) -> CandidateFit:
    """``f`` with its effects switched off but ``keep``, at ``f``'s own per-fold values (nothing refitted),
    cross-fitted like ``f``: what ``f``'s road alone (the nominal model) or ``f``'s values of the effects ``keep``
    do on the held-out windows.

    :param keep: effects of ``f`` left on, in ``f``'s order (a forward selection's set before its addition).
    """
    names = param_names(keep)
    idx = [f.names.index(n) for n in names]
    effect = "+".join(keep) or "nominal"
    if not f.x_folds:
        return score(effect, list(keep), names, f.x[idx], d, 0.0)
    return cross_fitted([score(effect, list(keep), names, np.asarray(x)[idx], fold_data(d, j), 0.0)
                         for j, x in enumerate(f.x_folds)], d)


def test_against(nominal: CandidateFit, f: CandidateFit, d: Data) -> None:
    """Store ``f``'s held-out tests in ``f``: against the nominal model (t, z and paired z), and the paired z
    against ``f`` with its effects switched off at its own roads (:func:`without_effects`).

    The second test is the nested one: the nominal model is every candidate with its effect off, so a candidate
    whose road generalises better than the calibrated nominal road (a multi-start that found a road the nominal
    fit's lower training error passed over) beats the nominal model without its effect doing anything. Only the
    effect's own share of the improvement counts (:func:`fricenv.gap.quarter_car.verdict.significant`).
    """
    f.t_stat = paired_t(nominal, f, d)
    f.z = improvement_z(nominal, f, d)
    f.z_paired = paired_z(nominal, f, d)
    f.z_without = paired_z(without_effects(f, d), f, d) if f.effect != "nominal" else None
