"""Least-squares fits of the quarter-car models on the training windows (named parameter vectors, see
:mod:`fricenv.gap.quarter_car.params`): the robust loss, multi-start from distinct road shapes, the scoring of a fit on all
windows, the nominal calibration and the noise refinement."""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np
from scipy.optimize import least_squares

from fricenv.effects import registry
from fricenv.effects.registry import FitContext
from fricenv.gap.quarter_car.config import FIT_LOSSES, DiagnoseConfig
from fricenv.gap.quarter_car.params import fd_steps, param_bounds, param_names, road_of, x_scales
from fricenv.gap.quarter_car.stats import CandidateFit, window_counts, window_mse
from fricenv.gap.quarter_car.windows import (
    NOISE_FLOOR,
    Data,
    projected_jacobian_available,
    window_jacobian,
    window_nuisances,
    window_residuals,
)
from fricenv.gap.signals.sensors import correlation_time
from fricenv.plants.tire import ROADS

__all__ = ["FIT_LOSS_SCALE", "bounds", "distinct_starts", "effect_start_matrix", "fit", "fit_loss", "fit_nominal",
           "refine_noise", "road_starts", "score"]

# Residual scale (noise std) of the fits' robust loss; the change-point search bounds a sample's squared residual
# at (2 FIT_LOSS_SCALE)^2. Either way one lock-up cannot place the road or the change.
FIT_LOSS_SCALE = 3.0
CHI2_1_MEDIAN = 0.4549364231195724  # median of a chi-squared variable with one degree of freedom [-]


def bounds(names: Sequence[str], d: Data):
    """Lower and upper bounds of the parameters ``names`` for a fit on ``d``'s training windows."""
    return param_bounds(names, d.starts[~d.test], d.t0, d.dt, d.horizon)


def fit_loss(r: np.ndarray, loss: str) -> np.ndarray:
    """Per-sample loss of normalised residuals ``r``, as ``scipy.optimize.least_squares`` scales it with
    ``f_scale = FIT_LOSS_SCALE`` (used to pick the best start on the same loss the fit minimises)."""
    z = (r / FIT_LOSS_SCALE) ** 2
    if loss == "linear":
        rho = z
    elif loss == "soft_l1":
        rho = 2.0 * (np.sqrt(1.0 + z) - 1.0)
    elif loss == "cauchy":
        rho = np.log1p(z)
    else:
        raise ValueError(f"DiagnoseConfig.fit_loss must be one of {', '.join(FIT_LOSSES)}, got {loss!r}")
    return FIT_LOSS_SCALE**2 * rho


def distinct_starts(starts: np.ndarray, cost: np.ndarray, k: int) -> list[np.ndarray]:
    """The ``k`` best of ``starts`` by ``cost`` whose road parts (B, C, E, theta) differ: a fit started from the
    nominal model's road can stay in that road's basin, so the further starts come from other road shapes."""
    return [starts[i].copy() for i in _distinct_rows(starts, cost, k)]


def _distinct_rows(starts: np.ndarray, cost: np.ndarray, k: int) -> list[int]:
    """The rows of ``starts`` that :func:`distinct_starts` returns, in its order."""
    chosen: list[int] = []
    for i in np.argsort(cost, kind="stable"):
        if not np.isfinite(cost[i]) or len(chosen) == k:
            break
        if all(not np.allclose(road_of(starts[i]), road_of(starts[c])) for c in chosen):
            chosen.append(int(i))
    return chosen or [0]


def fit(effects: Sequence[str], names: Sequence[str], starts: np.ndarray, d: Data, cfg: DiagnoseConfig,
         fixed: dict | None = None, runs: int = 1) -> np.ndarray:
    """Least squares on the training windows from the best ``runs`` of ``starts`` (K, len(names)) with distinct
    roads; the lowest final loss wins. ``fixed`` params are held."""
    train = np.flatnonzero(~d.test)
    lo, hi = bounds(names, d)
    starts = np.clip(np.atleast_2d(starts), lo, hi)
    fixed = fixed or {}
    for k, v in fixed.items():
        starts[:, names.index(k)] = v
    r = window_residuals(effects, names, starts, d, train)
    cost = np.sum(fit_loss(r.reshape(len(starts), -1), cfg.fit_loss), axis=1)
    cost = np.where(np.isfinite(cost), cost, np.inf)
    fidx = np.flatnonzero([n not in fixed for n in names])
    if fidx.size == 0:
        return starts[int(np.argmin(cost))].copy()
    # each run starts with the residuals at its start, already evaluated above (a row of a batch equals the same
    # parameter set evaluated alone: the windows are simulated element by element)
    results = [least_squares_run(effects, names, starts[i].copy(), fidx, lo, hi, train, d, cfg, r[i].ravel())
               for i in _distinct_rows(starts, cost, runs)]
    return min(results, key=lambda res: res[1])[0]


def least_squares_run(effects: Sequence[str], names: Sequence[str], x0: np.ndarray, fidx: np.ndarray, lo, hi,
                      train: np.ndarray, d: Data, cfg: DiagnoseConfig,
                      r0: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """One trust-region least-squares run from ``x0`` over the parameters ``fidx``: (solution, final loss).

    :param r0: the residuals (flattened, training windows) at ``x0`` when known: the run does not evaluate them
        again.
    """
    steps = fd_steps([names[i] for i in fidx])
    cache: dict = {}

    def full(z):
        x = x0.copy()
        x[fidx] = z
        return x

    def evaluate(Z):
        R = window_residuals(effects, names, np.array([full(z) for z in Z]), d, train).reshape(len(Z), -1)
        return _finite(R)

    def fun(z):
        key = z.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = evaluate([z])[0]
        return cache[key]

    projected = cfg.fit_jacobian == "projected" and projected_jacobian_available(effects, names, x0, d)

    def jac(z):
        # forward differences, stepping inwards at an upper bound
        h = np.where(z + steps > hi[fidx], -steps, steps)
        if projected:  # at the fitted window states, what they absorb projected out (window_jacobian)
            J = window_jacobian(effects, names, full(z), fidx, h, d, train)[1]
            return np.where(np.isfinite(J), J, 0.0).reshape(-1, len(fidx))
        # all perturbations in one batch, with the residuals at z itself from the cache when scipy has just
        # evaluated them (it almost always has)
        Z = [z + h[i] * np.eye(len(z))[i] for i in range(len(z))]
        key = z.tobytes()
        if key in cache:
            R0, R = cache[key], evaluate(Z)
        else:
            R = evaluate([z, *Z])
            R0, R = R[0], R[1:]
        cache.clear()
        cache[key] = R0
        return ((R - R0) / h[:, None]).T

    z0 = np.clip(x0[fidx], lo[fidx] + 1e-12, hi[fidx] - 1e-12)
    if r0 is not None and np.array_equal(z0, x0[fidx]):  # a start inside its bounds is evaluated where it is
        cache[z0.tobytes()] = _finite(r0)
    sol = least_squares(fun, z0, jac=jac, bounds=(lo[fidx], hi[fidx]), x_scale=x_scales([names[i] for i in fidx]),
                        max_nfev=cfg.max_nfev, xtol=cfg.fit_xtol, method="trf", loss=cfg.fit_loss,
                        f_scale=FIT_LOSS_SCALE)
    return full(sol.x), float(sol.cost)


def _finite(R: np.ndarray) -> np.ndarray:
    """Residuals with every non-finite value replaced by a large finite one (a diverged window simulation)."""
    return np.where(np.isfinite(R), R, 1e3)


def score(effect: str, effects: Sequence[str], names, x, d: Data, seconds: float) -> CandidateFit:
    r = window_residuals(effects, names, x, d)[0]
    counts = window_counts(d)
    wm = window_mse(r, counts)
    return CandidateFit(effect=effect, names=tuple(names), x=np.asarray(x, dtype=float),
                        train_mse=float(np.mean(wm[~d.test])), test_mse=float(np.mean(wm[d.test])), window_mse=wm,
                        seconds=seconds, resid=r, nuisances=window_nuisances(effects, d),
                        samples=float(np.mean(counts)))



def road_starts(d: Data) -> np.ndarray:
    return np.array([ROADS[k].as_array() for k in ROADS])


def fit_nominal(d: Data, cfg: DiagnoseConfig) -> CandidateFit:
    """Calibrate the nominal model's road on the training windows."""
    t = time.perf_counter()
    names = param_names([])
    x = fit([], names, road_starts(d), d, cfg)
    return score("nominal", [], names, x, d, time.perf_counter() - t)


def effect_start_matrix(effects: Sequence[str], road: np.ndarray, d: Data, seeds: dict | None = None) -> np.ndarray:
    """Starting points (K, 4 + q) for the effects' fit: the product of the roads (the nominal fit's and the presets)
    and each effect's start list. The nominal road has absorbed part of the effect, so it is not always the best
    start."""
    rows = [road.copy()] + [r for r in road_starts(d)]
    ctx = fit_context(d)
    for e in effects:
        entry = registry.get(e)
        opts = [seeds[e]] if seeds and e in seeds else entry.starts(ctx)
        rows = [np.concatenate([r, [o[k] for k in entry.param_names]]) for r in rows for o in opts]
    return np.array(rows)


def fit_context(d: Data) -> FitContext:
    """What the effects' start rules may use from the log: the vehicle and, when ``v`` is logged, the median ratio
    ``v / omega`` over the free-rolling start (at most 50 samples)."""
    ratio = None
    if d.v_smooth is not None and d.free_end >= 3:
        m = min(d.free_end, 50)
        r = np.median(d.v_smooth[:m] / np.maximum(d.omega[:m], 1e-6))
        ratio = float(r) if np.isfinite(r) else None
    return FitContext(p=d.p, free_roll_ratio=ratio)


def robust_rms(r: np.ndarray) -> float:
    """RMS of zero-mean Gaussian samples ``r`` (NaN and exact zeros, the missing samples, ignored) read from their
    median square (``chi2_1``'s median is 0.4549): a model error confined to a few windows (a brake transition that
    the nominal model times wrong) leaves it where the noise puts it."""
    x = np.asarray(r, dtype=float)
    x = x[np.isfinite(x) & (x != 0.0)]
    return float(np.sqrt(np.median(x * x) / CHI2_1_MEDIAN)) if x.size else float("nan")


def refine_noise(nominal: CandidateFit, d: Data) -> None:
    """Noise level per channel: the smaller of the difference-based estimate and the calibrated nominal model's
    training residual (corrected for the fitted wheel-speed nuisance). Both over-estimate (the first by the signal's
    own curvature, the second by any model error), so the smaller is the better estimate.

    A channel that looks low-pass filtered (:mod:`fricenv.gap.signals.sensors`) has a difference-based estimate far below
    its real noise: it takes the residual's level (:func:`robust_rms` where the filter is certain, so that a model
    error at a few brake transitions does not set it), times the square root of the residual's integrated
    autocorrelation time (its windows hold that many times fewer independent samples), unless its filter is known
    and undone (``white``, :func:`fricenv.gap.signals.filters.undone`): its noise is white again, and read as an
    unfiltered channel's. No channel goes below its quantisation floor ``q / sqrt(12)`` or ``NOISE_FLOOR``."""
    train = np.flatnonzero(~d.test)
    _, r_ch = window_residuals([], nominal.names, nominal.x, d, train, per_channel=True)
    sensors = d.sensors or {}
    for c in d.channels:
        r = r_ch[c][0]
        # one fitted nuisance state per window in this channel
        dof = np.sqrt(d.horizon / (d.horizon - 1.0)) if c in ("omega", "v") else 1.0
        rms = float(np.sqrt(np.nanmean(r ** 2))) * d.sigma[c] * dof
        info = sensors.get(c, {})
        floor = max(NOISE_FLOOR[c], info.get("quantisation_step", 0.0) / np.sqrt(12.0))
        if info.get("filtered") and not info.get("white") and np.isfinite(rms):
            tau = correlation_time(r)
            info["correlation_time"] = tau
            # a filter seen on the quiet start (or stated) is certain: a model error at a few windows must not set it;
            # a filter read from the roll-off alone may be a rough signal's, whose model error the level then holds
            certain = info.get("filter_evidence") in ("quiet start", "column map")
            level = robust_rms(r) * d.sigma[c] * dof if certain else rms
            d.sigma[c] = max(level * np.sqrt(tau), floor)
        else:
            d.sigma[c] = max(min(d.sigma[c], rms), floor)
        if c in sensors:
            info["noise_std"] = d.sigma[c]
