"""Forward selection of several effects at once.

After the best single effect (the verdict), the next candidate is added while the joint model beats the current set
significantly on held-out data, up to ``MAX_EFFECTS``:

- **Pool.** Every fitted (testable) single candidate, not only the significant ones: a second effect is often
  masked by the first one on its own (the first effect's parameters and the road absorb part of it), its single fit
  may be stretched to a bound to imitate the first, or stuck in a local minimum worse than the nominal model (a
  relaxation length fitted without the brake gain that shapes its transients). An expected effect (``brake_gain``
  when the torque came from brake pressure) is tried first.
- **Order.** Per step up to ``TRIED_PER_STEP`` candidates (all of the quarter car's others) are fitted jointly with
  the set; of those that pass the test, the one with the lowest joint held-out error is added: the selection ranks
  by held-out gain over the set, not by single-fit rank.
- **Joint fit.** Started from the set's own parameters and the candidate's single fit (a single fit stretched to the
  far bound of its range is no start: the registry's start list is used instead), on top of the road starts. A
  joint fit that ends worse than the set on the training windows (it nests the set, so its start misled it) is
  fitted again from the registry's start list.
- **Screen.** Each joint model is fitted from its best start first; only one past half the addition threshold, or
  that would call its candidate confounded, is fitted again from every start, which gives exactly the unscreened fit.
- **Test.** The joint model against the set: the paired held-out z of :func:`fricenv.gap.quarter_car.stats.paired_z` above
  ``cfg.sig_z`` (the improvement on windows the fits did not see, over its spread under the measurement noise,
  less what the extra per-window nuisance states win on pure noise), a lower nuisance-adjusted held-out error, and no
  effect parameter at the far edge of its range.
- **Nested test.** The joint model also beats itself with the added effect switched off (the set's effects and the
  roads at the joint fit's own per-fold values, nothing refitted:
  :func:`fricenv.gap.quarter_car.candidates.without_effects` keeping the set) by ``cfg.sig_z``: only the added
  effect's own share of the improvement counts, as for a single candidate against its own road. A joint fit whose
  restart found a better optimum of the set's own parameters would otherwise name an effect that does nothing (a
  ``brake_gain`` of 0.999 added to a ``drag`` whose joint fit simply fits the drag better).
- **Confounded.** A candidate that is significant on its own against the nominal model, yet whose joint fit beats
  neither the set nor the candidate alone significantly, carries the same signature as the set on this log: its
  step says ``confounded_with`` (the set's effects) instead of naming it as absent.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import replace

from fricenv.effects import registry
from fricenv.gap.quarter_car.candidates import run_fits, test_against, without_effects
from fricenv.gap.quarter_car.config import DiagnoseConfig
from fricenv.gap.quarter_car.context import FitContext
from fricenv.gap.quarter_car.data import Data
from fricenv.gap.quarter_car.fitting import fit_context
from fricenv.gap.quarter_car.params import road_of
from fricenv.gap.quarter_car.stats import CandidateFit, cross_fitted, paired_z
from fricenv.gap.quarter_car.verdict import at_range_edge

__all__ = ["MAX_EFFECTS", "SCREEN_SHARE", "TRIED_PER_STEP", "confounded", "effects_of", "forward_select",
           "split_params"]

MAX_EFFECTS = 3  # largest selected set [-]
TRIED_PER_STEP = 6  # candidates fitted jointly with the set per forward step (expected, then best single first) [-]
# Share of the addition threshold ``cfg.sig_z`` that a joint model fitted from its best start must pass over the set
# to be fitted again from every start: a second start that moves a joint fit past the test is still tried [-]
SCREEN_SHARE = 0.5


def effects_of(f: CandidateFit) -> list[str]:
    """The effect names of a (joint) fit."""
    return [e for e in f.effect.split("+") if e in registry.REGISTRY]


def split_params(f: CandidateFit) -> list[dict]:
    """``[{"effect", "params"}, ...]`` of a (joint) fit, one entry per effect in order."""
    allp = f.effect_params()
    return [{"effect": e, "params": {k: allp[k] for k in registry.get(e).param_names if k in allp}}
            for e in effects_of(f)]


def _seeds(current: CandidateFit, c: CandidateFit, d: Data, restart: bool = False) -> dict:
    """Start values of the joint fit of ``current`` plus ``c``: the set's fitted parameters and ``c``'s single fit,
    unless that is pressed against the far bound of its range and the registry has a start list for ``c`` (an
    effect fitted by its own search, such as a change point, has none: its single fit is its only start). With
    ``restart``, ``c`` starts from the registry's list (:func:`_restart`)."""
    seeds = {e["effect"]: e["params"] for e in split_params(current)}
    if not restart and (not at_range_edge(c, d.p) or not registry.get(c.effect).starts(fit_context(d))):
        seeds[c.effect] = c.effect_params()
    return seeds


def _fit_joints(ctx: FitContext, nominal: CandidateFit, current: CandidateFit, extra: Sequence[CandidateFit],
                restart: Collection[str] = ()) -> list[CandidateFit]:
    """The current set plus each of ``extra``, fitted per fold (seeded by :func:`_seeds`; the effects in ``restart``
    from the registry's start list), cross-fitted and tested against the nominal model."""
    base, d = effects_of(current), ctx.d
    roads = current.x_folds or (current.x,) * len(ctx.folds)
    tasks = [(base + [c.effect], road_of(x), f, ctx.cfg, _seeds(current, c, d, c.effect in restart))
             for c in extra for f, x in zip(ctx.folds, roads)]
    fits = run_fits(tasks, ctx.jobs, "forward selection") if tasks else []
    k = len(ctx.folds)
    joints = [cross_fitted(fits[i * k:(i + 1) * k], d) for i in range(len(extra))]
    for joint in joints:
        test_against(nominal, joint, d)
    return joints


def _extend(ctx: FitContext, nominal: CandidateFit, current: CandidateFit, extra: Sequence[CandidateFit],
            known: dict) -> list[CandidateFit]:
    """The current set plus each of ``extra``, fitted per fold and cross-fitted; a set in ``known`` (frozenset of
    effect names -> cross-fitted model) is not refitted.

    Screened: each joint model is first fitted from its best start alone (and from the registry's start
    list where that fit ends worse than the set, :func:`_restart`). Only one past ``SCREEN_SHARE`` of the addition
    threshold over the set, or that would make its candidate :func:`confounded` with the set, is fitted again from
    all ``cfg.fit_starts`` starts of the list that won, which gives exactly the unscreened fit (the best start's run
    is the first of them).
    """
    base, d, cfg = effects_of(current), ctx.d, ctx.cfg
    todo = [c for c in extra if frozenset(base + [c.effect]) not in known]
    quick = replace(ctx, cfg=replace(cfg, fit_starts=1)) if cfg.fit_starts > 1 else ctx
    joints = _fit_joints(quick, nominal, current, todo)
    restarted = dict(_restart(quick, nominal, current, todo, joints))
    joints = [restarted.get(i, j) for i, j in enumerate(joints)]
    again = [i for i, (c, j) in enumerate(zip(todo, joints))
             if quick is not ctx and (paired_z(current, j, d) > SCREEN_SHARE * cfg.sig_z
                                      or confounded(current, c, j, d, cfg))]
    restart = {todo[i].effect for i in restarted}  # refitted from all starts of the list that won the screen
    for i, joint in zip(again, _fit_joints(ctx, nominal, current, [todo[i] for i in again], restart)):
        joints[i] = joint
    for c, joint in zip(todo, joints):
        known[frozenset(base + [c.effect])] = joint
    return [known[frozenset(base + [c.effect])] for c in extra]


def _restart(ctx: FitContext, nominal: CandidateFit, current: CandidateFit, todo: Sequence[CandidateFit],
             joints: list[CandidateFit]) -> list[tuple[int, CandidateFit]]:
    """Joint fits that ended in a local minimum, fitted again from the registry's start list: (index, refit) where
    the refit fits the training windows better.

    A joint model nests the set (its added effect switched off), so a least squares that fits the training windows
    worse than the set alone was led astray by its start: the candidate's single fit, which the set's effects may
    have pulled far off (combos tuning seed 3011, log 36: a relaxation length of 1.18 m fitted alone, 0.27 m true;
    the joint fit from it stayed near 1.2 m, from the start list it finds 0.29 m).
    """
    stuck = [i for i, j in enumerate(joints) if j.train_mse > current.train_mse]
    # only a candidate its single fit started can start elsewhere: one with a start list in the registry
    stuck = [i for i in stuck if todo[i].effect in _seeds(current, todo[i], ctx.d)
             and registry.get(todo[i].effect).starts(fit_context(ctx.d))]
    if not stuck:
        return []
    refits = _fit_joints(ctx, nominal, current, [todo[i] for i in stuck], {todo[i].effect for i in stuck})
    return [(i, r) for i, r in zip(stuck, refits) if r.train_mse < joints[i].train_mse]


def confounded(current: CandidateFit, single: CandidateFit, joint: CandidateFit, d: Data,
               cfg: DiagnoseConfig) -> list[str]:
    """The set's effects ``single`` is confounded with on this log (empty if it is not): ``single`` beats the
    nominal model significantly on its own, but the joint model beats neither the set nor ``single`` alone
    significantly: the data show one signature that either explains."""
    if single.z_paired <= cfg.sig_z:
        return []
    if paired_z(current, joint, d) > cfg.sig_z or paired_z(single, joint, d) > cfg.sig_z:
        return []
    return effects_of(current)


def forward_select(ctx: FitContext, nominal: CandidateFit, first: CandidateFit, significant: Sequence[CandidateFit],
                   expected: Sequence[str] = (), known: dict | None = None) -> tuple[CandidateFit, list[dict]]:
    """The selected set, grown from ``first``.

    :param ctx: the diagnosis' log, folds, settings and workers.
    :param nominal: the cross-fitted nominal model every joint model is tested against.
    :param significant: the single candidates the selection may add (every fitted one), best first.
    :param expected: effects always tried first (a calibration the log's provenance predicts).
    :param known: sets already fitted (frozenset of effect names -> cross-fitted model), not refitted.
    :return: (the whole set's cross-fitted model, one record per step tried: the effect, its paired z over the
        set before it, its own share ``z_own`` (the nested test) where the joint model passed the test over
        the set, whether it was added, and ``confounded_with`` where it applies).
    """
    current, steps, known, d, cfg = first, [], dict(known or {}), ctx.d, ctx.cfg
    pool = [f for f in significant if f.effect not in effects_of(first)]
    while pool and len(effects_of(current)) < MAX_EFFECTS:
        pool.sort(key=lambda f: (f.effect not in expected, f.adjusted_mse))
        tried = pool[:TRIED_PER_STEP]
        joints = _extend(ctx, nominal, current, tried, known)
        z = [paired_z(current, j, d) for j in joints]
        passed = [i for i, j in enumerate(joints) if z[i] > cfg.sig_z and j.adjusted_mse < current.adjusted_mse
                  and not at_range_edge(j, ctx.p)]
        z_own = {i: paired_z(without_effects(joints[i], d, keep=effects_of(current)), joints[i], d) for i in passed}
        ok = [i for i in passed if z_own[i] > cfg.sig_z]
        new = [{"effect": c.effect, "z_over_set": z[i], "added": False} for i, c in enumerate(tried)]
        for i, zi in z_own.items():
            new[i]["z_own"] = zi
        if not ok:
            for i, c in enumerate(tried):
                with_ = confounded(current, c, joints[i], d, cfg)
                if with_:
                    new[i]["confounded_with"] = with_
            steps += new
            break
        best = min(ok, key=lambda i: joints[i].adjusted_mse)
        new[best]["added"] = True
        steps += new
        current = joints[best]
        pool = [f for f in pool if f is not tried[best]]
    return current, steps
