"""The change-point fit strategy (registry ``fit="change_point"``, the ``mu_change`` effect): the road's peak factor
switches from ``theta`` to the effect's level parameter at a log time. The time only moves the windows it falls in,
so it is searched, not differentiated; the other parameters are fitted by least squares with the time held."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fricenv.effects import registry
from fricenv.gap.quarter_car.config import DiagnoseConfig
from fricenv.gap.quarter_car.data import Data
from fricenv.gap.quarter_car.fitting import FIT_LOSS_SCALE, bounds, fit, fit_loss, road_starts
from fricenv.gap.quarter_car.params import ROAD_BOUNDS, param_names
from fricenv.gap.quarter_car.windows import window_residuals

__all__ = ["MU_CHANGE_FACTORS", "change_point_starts", "fit_change_point"]

MU_CHANGE_FACTORS = np.geomspace(0.35, 2.0, 16)  # theta grid of the change-point search, times the nominal theta
THETA = 3  # index of theta in the road (B, C, E, theta)
STARTS_PER_RUN = 2  # change-point starts per ``cfg.fit_starts``: the best local minima of the search [-]


def _named(effect: str) -> tuple[tuple[str, ...], int, int]:
    """The parameter names of the road plus ``effect``, the index of its switching time and of its level after."""
    entry = registry.get(effect)
    names = param_names([effect])
    (time_name,) = entry.searched
    (level_name,) = [q for q in entry.param_names if q != time_name]
    return names, names.index(time_name), names.index(level_name)


def _capped_cost(r: np.ndarray, n: int) -> np.ndarray:
    """Per parameter set, the sum of squared residuals each bounded at ``(2 FIT_LOSS_SCALE)^2`` (one lock-up cannot
    place the change); not-finite sums are infinite."""
    c = np.sum(np.minimum(r.reshape(n, -1) ** 2, FIT_LOSS_SCALE**2 * 4), axis=1)
    return np.where(np.isfinite(c), c, np.inf)


def change_point_starts(effect: str, road: np.ndarray, d: Data, k: int) -> list[np.ndarray]:
    """Starts of the change-point fit by a search: the ``k`` best distinct places of the change.

    Every training window is scored at a grid of theta values, for the nominal fit's road shape (B, C, E) and for
    each preset's (the nominal fit's shape has absorbed part of the change, so it can be far from the true one); the
    cost of each split into a before and an after theta (exact over the grid, by cumulative sums) is a profile along
    the log for each shape. Its local minima are the candidate places (:func:`_local_minima`); the ``k`` splits whose
    best shape's minimum costs least are kept, and the switching time is refined at single-sample resolution over
    each split's stretch. Only the global minimum per shape is not enough: a shape fitted over the change can place
    it a few windows off, and the least squares from there stays there (real-like seed 3901 log 35, fold 0: best
    splits at 4.3 s and 1.7 s, the true change at 1.19 s; the splits at 1.08 s and 1.27 s, fitted, cost 3-4 % less).
    """
    train = np.flatnonzero(~d.test)
    lo_t, hi_t = ROAD_BOUNDS["theta"]
    thetas = np.clip(road[THETA] * MU_CHANGE_FACTORS, lo_t, hi_t)
    shapes = np.vstack([road[None], road_starts(d)])
    X = np.repeat(shapes, len(thetas), axis=0)
    X[:, THETA] = np.tile(thetas, len(shapes))
    r = window_residuals([], param_names([]), X, d, train)
    c = np.sum(np.minimum(r**2, FIT_LOSS_SCALE**2 * 4), axis=-1)  # (S F, Wtrain), outliers bounded
    c = np.where(np.isfinite(c), c, np.inf).reshape(len(shapes), len(thetas), -1)
    cum = np.cumsum(c, axis=2)  # (S, F, Wtrain)
    before = cum[:, :, :-1].min(axis=1)  # (S, splits): best theta before each split
    after = (cum[:, :, -1:] - cum[:, :, :-1]).min(axis=1)
    total = before + after  # (S, splits)
    ranked = sorted(_local_minima(total), key=lambda sj: total[sj])
    best_shape: dict[int, int] = {}  # split -> its best shape, best split first
    for s, j in ranked:
        best_shape.setdefault(j, s)
    splits = list(best_shape.items())[:k]
    return [_refine_change_time(effect, shapes[s], thetas, cum[s], j + 1, d) for j, s in splits]


def _local_minima(total: np.ndarray) -> list[tuple[int, int]]:
    """The (shape, split) pairs whose split cost is a local minimum along the log (below the split before, not
    above the one after): each is a distinct place where the change may lie."""
    padded = np.pad(total, ((0, 0), (1, 1)), constant_values=np.inf)
    mid = padded[:, 1:-1]
    keep = np.isfinite(mid) & (mid < padded[:, :-2]) & (mid <= padded[:, 2:])  # one per plateau
    return [(int(s), int(j)) for s, j in zip(*np.nonzero(keep))]


def _refine_change_time(effect: str, shape: np.ndarray, thetas: np.ndarray, cum: np.ndarray, split: int,
                        d: Data) -> np.ndarray:
    """The start for one road shape: its best thetas before and after training window ``split`` (cum: (F, Wtrain)
    cumulative window costs over the theta grid), and the switching time searched sample by sample between the two
    windows around the split."""
    train = np.flatnonzero(~d.test)
    i = int(np.argmin(cum[:, split - 1]))
    j = int(np.argmin(cum[:, -1] - cum[:, split - 1]))
    names, i_time, i_level = _named(effect)
    lo, hi = bounds(names, d)
    t_lo = d.t0 + d.dt * (d.starts[train[split - 1]] + d.horizon // 2)
    t_hi = d.t0 + d.dt * (d.starts[train[split]] + d.horizon // 2)
    fine_t = np.clip(np.arange(t_lo, t_hi + 1e-9, d.dt), lo[i_time], hi[i_time])
    base = np.zeros(len(names))
    base[:len(shape)] = shape
    base[THETA] = thetas[i]
    base[i_level] = thetas[j]
    fine = np.repeat(base[None], len(fine_t), axis=0)
    fine[:, i_time] = fine_t
    r = window_residuals([effect], names, fine, d, train)
    return fine[int(np.argmin(_capped_cost(r, len(fine))))]


def _fit_from(effect: str, start: np.ndarray, d: Data, cfg: DiagnoseConfig) -> np.ndarray:
    """Least squares from ``start`` with the switching time held, then one alternation: re-search the switching
    time with the fitted road, and refit the rest if it moved."""
    effects = [effect]
    names, i_time, _ = _named(effect)
    time_name = names[i_time]
    x = fit(effects, names, start[None], d, cfg, fixed={time_name: float(start[i_time])})
    lo, hi = bounds(names, d)
    fine_t = np.clip(x[i_time] + d.dt * np.arange(-d.horizon * 3 // 2, d.horizon * 3 // 2 + 1), lo[i_time],
                     hi[i_time])
    fine = np.repeat(x[None], len(fine_t), axis=0)
    fine[:, i_time] = fine_t
    r = window_residuals(effects, names, fine, d, np.flatnonzero(~d.test))
    cost = np.sum(r.reshape(len(fine), -1) ** 2, axis=1)
    best = fine[int(np.argmin(np.where(np.isfinite(cost), cost, np.inf)))]
    if best[i_time] != x[i_time]:
        x = fit(effects, names, best[None], d, cfg, fixed={time_name: float(best[i_time])})
    return x


def fit_change_point(effects: Sequence[str], road: np.ndarray, d: Data, cfg: DiagnoseConfig,
                     seeds: dict | None = None) -> np.ndarray:
    """The change-point effect's fit: least squares from the ``STARTS_PER_RUN * fit_starts`` best searched starts;
    the lowest loss on the training windows wins (``seeds`` are not used: the search finds its own starts)."""
    (effect,) = effects
    names = param_names([effect])
    train = np.flatnonzero(~d.test)
    starts = change_point_starts(effect, road, d, STARTS_PER_RUN * int(cfg.fit_starts))
    xs = [_fit_from(effect, start, d, cfg) for start in starts]
    r = window_residuals([effect], names, np.array(xs), d, train)
    cost = np.sum(fit_loss(r.reshape(len(xs), -1), cfg.fit_loss), axis=1)
    return xs[int(np.argmin(np.where(np.isfinite(cost), cost, np.inf)))]
