"""Forward selection of several effects at once (issue 15 item 2).

After the best single effect (the verdict), the next candidate is added while the joint model beats the current set
significantly on held-out data (:func:`fricenv.gap.stats.paired_z` of the larger set over the current one above
``sig_z``, a lower nuisance-adjusted error, no parameter at the far edge of its range), up to ``MAX_EFFECTS``. Only
significant single candidates are tried, the ``TRIED_PER_STEP`` best of them per step (CPU: each try is a joint
least-squares fit per fold); an expected effect (``brake_gain`` when the torque came from brake pressure) is always
tried.
"""

from __future__ import annotations

from collections.abc import Sequence

from fricenv.effects import registry
from fricenv.gap.candidates import run_fits, test_against
from fricenv.gap.config import DiagnoseConfig
from fricenv.gap.params import road_of
from fricenv.gap.stats import CandidateFit, cross_fitted, paired_z
from fricenv.gap.verdict import at_range_edge
from fricenv.gap.windows import Data
from fricenv.plants import quarter_car as qc

__all__ = ["MAX_EFFECTS", "TRIED_PER_STEP", "effects_of", "forward_select", "split_params"]

MAX_EFFECTS = 3  # largest selected set [-]
TRIED_PER_STEP = 2  # candidates tried per forward step (best single candidates first) [-]


def effects_of(f: CandidateFit) -> list[str]:
    """The effect names of a (joint) fit."""
    return [e for e in f.effect.split("+") if e in registry.REGISTRY]


def split_params(f: CandidateFit) -> list[dict]:
    """``[{"effect", "params"}, ...]`` of a (joint) fit, one entry per effect in order."""
    allp = f.effect_params()
    return [{"effect": e, "params": {k: allp[k] for k in registry.get(e).param_names if k in allp}}
            for e in effects_of(f)]


def _extend(current: CandidateFit, extra: Sequence[CandidateFit], folds: list[Data], d: Data, cfg: DiagnoseConfig,
            jobs: int, nominal: CandidateFit, known: dict) -> list[CandidateFit]:
    """The current set plus each of ``extra``, fitted per fold (seeded from the fits so far) and cross-fitted; a set
    in ``known`` (frozenset of effect names -> cross-fitted model) is not refitted."""
    base = effects_of(current)
    seeds = {e["effect"]: e["params"] for e in split_params(current)}
    todo = [c for c in extra if frozenset(base + [c.effect]) not in known]
    tasks = []
    for c in todo:
        s = dict(seeds, **{c.effect: c.effect_params()})
        roads = current.x_folds or (current.x,) * len(folds)
        tasks += [(base + [c.effect], road_of(x), f, cfg, s) for f, x in zip(folds, roads)]
    fits = run_fits(tasks, jobs, "forward selection") if tasks else []
    k = len(folds)
    for i, c in enumerate(todo):
        joint = cross_fitted(fits[i * k:(i + 1) * k], d)
        test_against(nominal, joint, d)
        known[frozenset(base + [c.effect])] = joint
    return [known[frozenset(base + [c.effect])] for c in extra]


def forward_select(first: CandidateFit, significant: Sequence[CandidateFit], nominal: CandidateFit,
                   folds: list[Data], d: Data, p: qc.QuarterCarParams, cfg: DiagnoseConfig, jobs: int,
                   expected: Sequence[str] = (), known: dict | None = None) -> tuple[CandidateFit, list[dict]]:
    """The selected set, grown from ``first``.

    :param significant: the significant single candidates, best first.
    :param expected: effects always tried first (a calibration the log's provenance predicts).
    :param known: sets already fitted (frozenset of effect names -> cross-fitted model), not refitted.
    :return: (the whole set's cross-fitted model, one record per step tried: the effect, its paired z over the
        set before it, and whether it was added).
    """
    current, steps, known = first, [], dict(known or {})
    pool = [f for f in significant if f.effect != first.effect]
    while pool and len(effects_of(current)) < MAX_EFFECTS:
        pool.sort(key=lambda f: (f.effect not in expected, f.adjusted_mse))
        tried = pool[:TRIED_PER_STEP]
        joints = _extend(current, tried, folds, d, cfg, jobs, nominal, known)
        z = [paired_z(current, j, d) for j in joints]
        ok = [i for i, j in enumerate(joints) if z[i] > cfg.sig_z and j.adjusted_mse < current.adjusted_mse
              and not at_range_edge(j, p)]
        steps += [{"effect": c.effect, "z_over_set": z[i], "added": False} for i, c in enumerate(tried)]
        if not ok:
            break
        best = min(ok, key=lambda i: joints[i].adjusted_mse)
        steps[len(steps) - len(tried) + best]["added"] = True
        current = joints[best]
        pool = [f for f in pool if f is not tried[best]]
    return current, steps
