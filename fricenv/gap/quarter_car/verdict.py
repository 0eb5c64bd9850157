"""The verdict rule: which candidates are significant, which explain the gap, whether the gap is real, and the
verdict shared by every plant's diagnosis (docs/contracts.md: none / an effect / unexplained)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fricenv.effects.quarter_car import ModelBatch
from fricenv.gap.quarter_car.config import DiagnoseConfig
from fricenv.gap.quarter_car.data import Data
from fricenv.gap.quarter_car.params import ROAD_NAMES, effect_param, road_of
from fricenv.gap.quarter_car.stats import CandidateFit, paired_z, robust_gap
from fricenv.plants import quarter_car as qc

__all__ = ["RANGE_EDGE", "at_range_edge", "explains", "gap_is_real", "paired_order", "significant", "told_apart"]

# A fitted effect parameter within this share of its range (the registry's bounds) from a bound sits at the bound [-]
RANGE_EDGE = 1e-3


def significant(f: CandidateFit, nominal: CandidateFit, cfg: DiagnoseConfig) -> bool:
    """A held-out improvement well beyond what the measurement noise could make (:func:`paired_z`), over the
    nominal model and over the candidate's own road with its effects switched off (``z_without``, the nested
    test of :func:`fricenv.gap.quarter_car.candidates.test_against`); the robust :func:`improvement_z` and the paired t
    statistic are reported, not required."""
    nested = f.z_without is None or f.z_without > cfg.sig_z
    return f.z_paired > cfg.sig_z and nested and f.adjusted_mse < nominal.adjusted_mse



def at_range_edge(f: CandidateFit, p: qc.QuarterCarParams) -> list[str]:
    """Effect parameters of ``f`` that reach the far edge of their physical range (the registry's
    :attr:`~fricenv.effects.registry.Param.physical_range`) in any fold's fit: pressed against it, or beyond it.

    The edge on the side where the effect switches off (a lag of 1 ms, no drag) does not count: there the effect
    is simply absent. A parameter at or beyond the far edge (a relaxation length of 1 m or more) means the effect is
    being stretched to imitate something it is not, so such a candidate cannot be the verdict.
    """
    off = ModelBatch.nominal(road_of(f.x), 1, p)
    out = []
    for i, name in enumerate(f.names):
        if name in ROAD_NAMES:
            continue
        lo, hi = effect_param(name).physical_range
        if not (np.isfinite(lo) and np.isfinite(hi)):
            continue
        tol = RANGE_EDGE * (hi - lo)
        off_value = float(off.param(name)[0])
        xs = [x[i] for x in (f.x_folds or (f.x,))]
        low = off_value > lo + tol and any(x <= lo + tol for x in xs)
        high = off_value < hi - tol and any(x >= hi - tol for x in xs)
        if low or high:
            out.append(name)
    return out


def gap_is_real(nominal: CandidateFit, significant: Sequence[CandidateFit], cfg: DiagnoseConfig,
                periodic: bool = False) -> bool:
    """Whether the nominal model misses by more than the noise.

    True when its held-out gap is above ``gap_none`` beyond the few lock-up windows that no model times (the trim
    of :func:`robust_gap`, the same that judges the candidates), when a candidate beats it significantly on data
    it was not fitted to (then the nominal model cannot be within the noise either), or when its residual holds a
    ``periodic`` line that noise cannot make (:func:`fricenv.gap.quarter_car.periodic.periodic_line`).
    """
    misses = nominal.gap > cfg.gap_none and robust_gap(nominal) > cfg.gap_within_noise
    return misses or bool(significant) or periodic



def explains(f: CandidateFit, nominal: CandidateFit, cfg: DiagnoseConfig) -> bool:
    """Whether ``f`` closes a clear share of the gap on held-out data: its robust gap is at most
    ``ratio_explained`` of the nominal one, or within the noise (``gap_within_noise``)."""
    return robust_gap(f) <= cfg.ratio_explained * robust_gap(nominal) or robust_gap(f) <= cfg.gap_within_noise


def paired_order(ranked: Sequence[CandidateFit], d: Data) -> list[CandidateFit]:
    """The candidates ``ranked`` (best first by the adjusted held-out MSE), with the first two swapped when the
    paired test on held-out data prefers the second (:func:`paired_z` of the second over the first above 0).

    The adjusted MSE averages every held-out window; the paired test leaves out the windows of largest gain and
    loss and soft-caps the rest, as the significance test does. Where the two disagree the mean rests on a few
    windows (a lock-up timed a little better), and the paired test, which the verdict's evidence is measured with,
    decides. :func:`told_apart` then tests the verdict against the other as it tests any verdict.
    """
    out = list(ranked)
    if len(out) >= 2 and paired_z(out[0], out[1], d) > 0.0:
        out[0], out[1] = out[1], out[0]
    return out


def told_apart(chosen: CandidateFit, significant: Sequence[CandidateFit], d: Data, cfg: DiagnoseConfig) -> dict:
    """Whether the log tells the verdict's effect from the best other significant candidate (lowest held-out error):
    the verdict's held-out improvement over that candidate, :func:`paired_z` with the candidate as the base, above
    ``sig_z``. Below it the data read as well with either effect (a brake delay and a lag on ABS ramps, a brake gain
    and drag under steady braking), and the verdict is the better fit of two the log does not separate.

    :return: ``{"effect", "from", "params", "gap_after", "z_paired", "apart"}`` (``from`` None and ``apart`` True
        when no other candidate is significant).
    """
    others = sorted((f for f in significant if f.effect != chosen.effect), key=lambda f: f.adjusted_mse)
    if not others:
        return {"effect": chosen.effect, "from": None, "params": {}, "gap_after": None, "z_paired": None,
                "apart": True}
    other = others[0]
    z = paired_z(other, chosen, d)
    return {"effect": chosen.effect, "from": other.effect, "params": other.effect_params(), "gap_after": other.gap,
            "z_paired": z, "apart": bool(z > cfg.sig_z)}
