"""Statistics of the gap diagnosis: noise level, the gap in noise units, held-out tests between two models,
and cross-fitting (per-fold fits combined into one candidate held out on every window)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from fricenv.gap.core.noise import gap_of
from fricenv.gap.quarter_car.params import ROAD_NAMES

if TYPE_CHECKING:
    from fricenv.gap.quarter_car.data import Data

__all__ = [
    "TRIM_SHARE",
    "WINDOW_MSE_CAP",
    "CandidateFit",
    "cross_fitted",
    "fold_data",
    "improvement_z",
    "paired_t",
    "paired_z",
    "robust_gap",
    "soft_cap",
    "trimmed",
    "window_counts",
    "window_mse",
]

# Beyond this mean squared normalised error (RMS 5 noise std) a window's error counts only logarithmically
# (:func:`soft_cap`): a wheel lock-up predicted a few milliseconds early or late is wrong whatever the size of its
# error and must not decide alone, yet the windows still rank (a hard cap tied every bad window at one value).
WINDOW_MSE_CAP = 25.0
# Share of the held-out windows (the worst) left out when judging how much of the gap a candidate closes.
TRIM_SHARE = 0.05
# Smallest squared prediction difference between two models (normalised, summed over the held-out samples) that
# the paired test divides by: one noise variance (:func:`paired_z`).
MIN_PREDICTION_DIFF = 1.0


@dataclass
class CandidateFit:
    """One fitted model: name, full parameter vector, held-out figures."""

    effect: str  # effect name, "nominal", or "a+b" for a joint fit
    names: tuple[str, ...]  # parameter names of x (road first)
    x: np.ndarray  # fitted parameters
    train_mse: float
    test_mse: float
    window_mse: np.ndarray  # per window (all windows), mean squared normalised residual
    gap: float = 0.0  # held-out gap, noise units
    t_stat: float = 0.0  # paired test against the nominal model on held-out windows
    z: float = 0.0  # robust held-out improvement in noise standard deviations
    z_paired: float = 0.0  # the same improvement over its noise spread given the two models' prediction difference
    z_without: float | None = None  # paired z against itself with its effects switched off (candidates.test_against)
    seconds: float = 0.0
    resid: np.ndarray | None = None  # (windows, samples) normalised residuals of all windows
    x_folds: tuple = ()  # the per-fold fits of a cross-fitted candidate (x is their mean)
    nuisances: int = 1  # states fitted per window on the window's own samples (window_nuisances)
    samples: float = 1.0  # fresh normalised residuals per window, mean over the windows

    @property
    def adjusted_mse(self) -> float:
        """Held-out mean squared normalised residual plus what the per-window nuisance states win on pure noise:
        the figure models with different nuisances are ranked by."""
        return self.test_mse + self.nuisances / self.samples

    def effect_params(self) -> dict[str, float]:
        return {k: float(v) for k, v in zip(self.names, self.x) if k not in ROAD_NAMES}

    def road(self) -> dict[str, float]:
        return {k: float(v) for k, v in zip(self.names, self.x) if k in ROAD_NAMES}

    def road_x(self) -> np.ndarray:
        """The fitted road ``(B, C, E, theta)`` as an array."""
        return np.array([self.x[self.names.index(k)] for k in ROAD_NAMES])



def soft_cap(x: np.ndarray, cap: float = WINDOW_MSE_CAP) -> np.ndarray:
    """``x`` below ``cap``, ``cap + log(1 + x - cap)`` above: bounded growth that keeps the order."""
    x = np.asarray(x, dtype=float)
    return np.where(x <= cap, x, cap + np.log1p(np.maximum(x - cap, 0.0)))


def window_counts(d: Data) -> np.ndarray | int:
    """Residual samples per window that carry a fresh measurement ((windows,) array, or horizon times channels for
    data without missing-sample bookkeeping)."""
    counts = getattr(d, "counts", None)
    return d.horizon * len(d.channels) if counts is None else counts


def window_mse(r: np.ndarray, counts) -> np.ndarray:
    """Per-window mean squared normalised residual over the fresh samples (``r`` is 0 where none exists), soft-capped;
    a window without any fresh sample counts as pure noise (1)."""
    c = np.asarray(counts, dtype=float)
    mse = np.sum(r**2, axis=-1) / np.maximum(c, 1.0)
    return soft_cap(np.where(c > 0, mse, 1.0))


def paired_t(base: CandidateFit, cand: CandidateFit, d: Data) -> float:
    """t statistic of the held-out per-window improvement of ``cand`` over ``base``.

    The per-window statistic is the log ratio of the mean squared normalised residuals, which keeps the test robust
    to the few windows whose error is dominated by a wheel lock-up predicted slightly early or late.
    """
    diff = np.log(base.window_mse) - np.log(cand.window_mse)
    if diff.size < 2:
        return 0.0
    sd = float(np.std(diff, ddof=1))
    mean = float(np.mean(diff))
    if sd <= 0:
        return float(np.sign(mean) * np.inf) if mean != 0 else 0.0
    return mean / (sd / np.sqrt(diff.size))



def _window_gain(base: CandidateFit, cand: CandidateFit, m) -> np.ndarray:
    """Per-window held-out gain of the sum of squared normalised residuals (``m`` samples per window), less what
    ``cand``'s extra per-window nuisance states win on pure noise (one noise variance each)."""
    return (base.window_mse - cand.window_mse) * m - (cand.nuisances - base.nuisances)


def trimmed(gain: np.ndarray) -> np.ndarray:
    """The windows a paired test between two models keeps: all but the one of largest gain and the one of largest
    loss. A wheel lock-up predicted a few milliseconds early or late by one model and not the other wins or costs
    a window its whole error, whatever the models' merit elsewhere. A model fitted to a road whose friction peak the
    log never reached can lock the wheel in one held-out window: on a tuning log with a radius error nine times its
    detectable size, one such window cost 693 and held the paired z at 1.6 (14 without it). So one window decides
    neither way."""
    keep = np.ones(gain.size, dtype=bool)
    if gain.size >= 3:
        keep[int(np.argmax(gain))] = False
        keep[int(np.argmin(np.where(keep, gain, np.inf)))] = False
    return keep


def improvement_z(base: CandidateFit, cand: CandidateFit, d: Data) -> float:
    """Held-out improvement of the sum of squared normalised residuals (less the nuisance discount of
    :func:`_window_gain`), without its single largest window, in units of that sum's standard deviation under pure
    noise (sqrt(2 n)); one lucky window cannot make it large."""
    m = window_counts(d)
    gain = _window_gain(base, cand, m)
    if gain.size == 0:
        return 0.0
    robust = float(np.sum(gain) - max(float(np.max(gain)), 0.0))
    return robust / np.sqrt(2.0 * float(np.sum(np.broadcast_to(m, gain.shape))))


def paired_z(base: CandidateFit, cand: CandidateFit, d: Data) -> float:
    """Held-out improvement of ``cand`` over ``base`` in units of its spread under the measurement noise.

    With normalised residuals ``r_b = e + a`` and ``r_c = e + b`` (``e`` unit white noise, ``a``, ``b`` the models'
    errors), the per-sample gain ``r_b^2 - r_c^2 = a^2 - b^2 + 2 e (a - b)`` has noise spread ``2 |a - b|``, and
    ``a - b = r_b - r_c`` is the difference of the two predictions, known exactly. The statistic is the held-out gain
    over ``2 ||r_b - r_c||``: a z score that is large when the data prefer the candidate however few windows carry the
    difference, and about ``-||a - b|| / 2 + N(0, 1)`` when the base model is right. Per window the gain and the
    squared difference are soft-capped (:func:`soft_cap`), the windows of largest gain and of largest loss are left
    out (:func:`trimmed`), and the gain is less what ``cand``'s extra per-window nuisance states win on pure noise
    (:func:`_window_gain`). Two models whose predictions differ by less than one noise std over all the held-out
    samples (``||r_b - r_c||^2 < MIN_PREDICTION_DIFF``) cannot be told apart: the spread is held at that floor, so
    the ratio of two vanishing numbers (a candidate fitted back to the nominal model, its gain the start-state
    fit's round-off) cannot pass a test. A real difference passes only if ``||a - b|| > 2 sig_z`` (the expected
    gain ``||a - b||^2`` over its spread), far above the floor.
    """
    if base.resid is None or cand.resid is None:
        return 0.0
    m = window_counts(d)
    gain = _window_gain(base, cand, m)
    mm = np.maximum(m, 1)
    diff2 = mm * soft_cap(np.sum((base.resid - cand.resid) ** 2, axis=-1) / mm)
    if gain.size < 3:
        return 0.0
    keep = trimmed(gain)
    spread = 2.0 * np.sqrt(max(float(np.sum(diff2[keep])), MIN_PREDICTION_DIFF))
    return float(np.sum(gain[keep]) / spread)



def robust_gap(f: CandidateFit) -> float:
    """Held-out gap with the worst ``TRIM_SHARE`` of the windows left out: a wheel lock-up that starts a few
    milliseconds earlier or later than any model predicts costs a window its whole error whatever the model, so the
    share of the gap a candidate closes is judged without those few windows."""
    wm = np.sort(f.window_mse)
    keep = wm.size - int(np.ceil(TRIM_SHARE * wm.size))
    return gap_of(float(np.mean(wm[:max(keep, 1)])))



def fold_data(d: Data, j: int) -> Data:
    """The data with fold ``j`` held out and the other folds as training windows."""
    return replace(d, test=d.fold == j)


def cross_fitted(fits: Sequence[CandidateFit], d: Data) -> CandidateFit:
    """Combine per-fold fits (fit ``j`` trained without fold ``j``) into one candidate whose window errors and
    residuals are held out on every window; its parameters are the mean of the folds'."""
    f0 = fits[0]
    wm = np.empty_like(f0.window_mse)
    resid = np.empty_like(f0.resid)
    for j, f in enumerate(fits):
        held = d.fold == j
        wm[held] = f.window_mse[held]
        resid[held] = f.resid[held]
    return CandidateFit(effect=f0.effect, names=f0.names, x=np.mean([f.x for f in fits], axis=0),
                        train_mse=float(np.mean([f.train_mse for f in fits])), test_mse=float(np.mean(wm)),
                        window_mse=wm, gap=gap_of(float(np.mean(wm))), seconds=float(sum(f.seconds for f in fits)),
                        resid=resid, x_folds=tuple(f.x for f in fits), nuisances=f0.nuisances,
                        samples=f0.samples)


