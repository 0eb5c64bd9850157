"""Sim-to-real gap diagnosis of a quarter-car braking log: where the gap lies, which effect, how far it shrinks.

Method (every error measure is computed on data not used for fitting):

1. **Noise level.** Estimated from the log itself, per channel, by the median absolute second difference
   (white noise of std s gives second differences of std s sqrt(6); the median ignores the sparse kinks of the
   signal). No assumption on the log writer's noise values. Missing or held samples (NaN) and isolated outliers are
   left out of every residual, a quantised channel's noise is at least step / sqrt(12), and a low-passed ``v`` or
   ``a_x`` takes its noise from the calibrated model's residual times its autocorrelation time
   (:mod:`fricenv.gap.signals.sensors`, reported in ``where["sensors"]``).
2. **States from data.** The log is cut into prediction windows of 0.1 s at its rate (``horizon_s``; beyond the
   friction peak the wheel dynamics are unstable, so longer open-loop predictions measure the timing of a lock-up
   rather than the model); the windows are dealt in turn into ``folds`` folds for cross-fitting: every model is fitted
   once per fold on the other folds' windows, so every window is predicted by a fit that did not see it (all error
   measures below are these held-out predictions). A window starts from a state estimated from
   data: the wheel speed (and the speed, when ``v`` is logged; and the transient slip of a relaxation model) as
   per-window nuisance states fitted by two Gauss-Newton steps on that window's measurements; when ``v`` is not
   logged, the speed is reconstructed by integrating the model's vehicle equation
   ``m v' = -F_z mu(lambda(v, omega_meas)) - F_d`` driven by the measured wheel speed from the free-rolling start
   ``v(0) = r omega`` (the nominal model is a dynamic model; this fits the initial state from omega alone). Effect
   states with a known input (brake-lag filter, delay buffer) run over the logged command.
3. **Calibrate.** The nominal model's road ``(B, C, E, theta)`` is fitted on the training windows of each fold
   (multi-start from the road presets) by least squares with a robust loss (``fit_loss``, soft L1 beyond
   ``FIT_LOSS_SCALE`` noise std), so that the few windows of a lock-up, whose timing no model predicts, do not bend
   the road away from the rest of the data. The road is always treated as unknown. The fits' Jacobians come from
   each window at its fitted start states with what those states absorb projected out (variable projection,
   ``fit_jacobian``), and a run stops at a relative step of ``fit_xtol``.
4. **Gap.** Held-out residuals over all logged channels, each divided by its noise level (the smaller of the
   difference-based estimate and the calibrated nominal model's training residual: both over-estimate). A window's
   mean squared normalised residual grows only logarithmically beyond ``WINDOW_MSE_CAP`` (:func:`soft_cap`). ``gap`` is the model part of the held-out
   error in noise units, ``sqrt(max(MSE - 1, 0))`` (0 for a model that fits within the noise). ``gap_before`` is
   the calibrated nominal model's.
5. **Localise.** Nominal residuals by window (worst time segments), by regime (slip below/above the fitted road's
   peak, brake apply/hold/release, speed bands) and by channel, before and after.
6. **Candidates.** Every library effect is fitted (road + effect parameters, multi-start; ``mu_change`` by a
   change-point search over the road shapes) per fold, in parallel processes, and scored on the held-out windows.
   Least squares runs from the best starts of two different road shapes (``fit_starts``): started in the nominal
   road's basin alone, it can stop there. A candidate is significant when its held-out improvement of the squared
   normalised error, without its single largest window, exceeds ``sig_z`` times its spread under the measurement
   noise (twice the norm of the two models' prediction difference, :func:`paired_z`): a richer model cannot win by
   fitting noise (the improvement is measured on data it was not fitted to), nor by one lucky window, and an
   effect that shows in few windows is still seen.
7. **Verdict.** An effect when it is significant and closes a clear share of the gap (robust held-out gap, the worst
   ``TRIM_SHARE`` of windows left out, at most ``ratio_explained`` of the nominal one, or below
   ``gap_within_noise``; the best-ranked of those, ahead of a better-ranked one that does not close it alone;
   ranked by the adjusted held-out error, except that the paired test orders the first two where it prefers the
   second, :func:`fricenv.gap.quarter_car.verdict.paired_order`);
   ``unexplained`` when the gap is real (nominal gap above ``gap_none`` and not only in the
   trimmed windows, a significant candidate, or a periodic line in the wheel-speed residual that no library effect
   makes, :mod:`fricenv.gap.quarter_car.periodic`) and no candidate closes it; ``none`` otherwise. The two best
   significant candidates are also fitted jointly; if only the joint model closes the gap, the larger single effect
   is the verdict and the other follows in ``candidates`` (the joint fit is reported under ``where["joint_fit"]``).
   A candidate whose effect parameter is pressed against the far bound of its physical range (:func:`at_range_edge`)
   still shows that the gap is real, but cannot be the verdict: it is being stretched to imitate something else.
8. **Drift test.** The verdict's model is refitted on the early and on the late half of the log separately (each
   half cross-fitted within itself). A library effect has constant parameters, so if the split model beats the
   constant one significantly (paired z above ``drift_z``) and halves the robust gap it leaves (when that gap is
   above the noise), or if a parameter's early and late estimates differ beyond their jackknife standard errors
   (Student's t at ``drift_alpha``, :func:`fricenv.gap.quarter_car.drift.parameter_shift`) by at least half the
   effect's size, the effect only imitates the cause (brake fade looks like a brake gain that drifts down) and the
   verdict is ``unexplained``. The constant model is refitted from the split fits first, so that a better optimum
   is not mistaken for a drift (``where["drift_test"]``). A set that the forward selection makes the verdict
   where no single effect closed the gap is tested the same way.
9. **Testability and several effects.** Candidates the log cannot show (each effect's registry rule, e.g. a
   relaxation length without slip transients) are not fitted and are listed in ``where["not_testable"]``, as are
   those too small for this log's noise at their largest plausible size (:mod:`fricenv.gap.quarter_car.detectability`); these
   are fitted all the same, since that power analysis is linearised, and one that turns out significant (or
   selected) leaves the list for a caveat (``where["caveats"]``). After the verdict, a
   forward selection (:mod:`fricenv.gap.quarter_car.selection`) adds the next candidate (any fitted one) while the joint model
   beats the set so far on held-out data, up to three (``effects``; ``gap_after`` is the whole set's). A named
   effect that an untested one would imitate on this log's channels comes with that effect's equivalent size
   (:mod:`fricenv.gap.quarter_car.alternatives`, ``where["alternatives"]``: a brake gain without ``v`` and ``a_x``
   may be a rolling-radius error).
10. **Told apart.** The verdict's effect is tested against the best other significant candidate by the same paired
   z (:func:`fricenv.gap.quarter_car.verdict.told_apart`, ``where["told_apart"]``): below ``sig_z`` the log reads as
   well with the other effect, and the report says so.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field, replace

from fricenv import progress
from fricenv.gap.core.noise import estimate_noise, gap_of
from fricenv.gap.core.pool import default_jobs, map_tasks, shared_pool
from fricenv.gap.core.verdict import decide_verdict
from fricenv.gap.quarter_car.alternatives import alternatives
from fricenv.gap.quarter_car.candidates import (
    fit_candidate,
    nested_nominal,
    run_fits,
    start_fits,
    test_against,
)
from fricenv.gap.quarter_car.changepoint import change_point_starts
from fricenv.gap.quarter_car.config import DEFAULT_CONFIG, FIT_LOSSES, DiagnoseConfig
from fricenv.gap.quarter_car.context import FitContext
from fricenv.gap.quarter_car.data import Data
from fricenv.gap.quarter_car.drift import drift_test, fit_time_split
from fricenv.gap.quarter_car.excitation import excitation, untestable
from fricenv.gap.quarter_car.findings import Findings
from fricenv.gap.quarter_car.fitting import distinct_starts, fit_nominal, refine_noise, score
from fricenv.gap.quarter_car.guard import guard
from fricenv.gap.quarter_car.localise import localise, tests_table
from fricenv.gap.quarter_car.params import ROAD_NAMES, param_names, road_of
from fricenv.gap.quarter_car.periodic import periodic_line
from fricenv.gap.quarter_car.selection import forward_select, split_params
from fricenv.gap.quarter_car.stats import (
    CandidateFit,
    cross_fitted,
    fold_data,
    robust_gap,
)
from fricenv.gap.quarter_car.verdict import (
    at_range_edge,
    explains,
    gap_is_real,
    paired_order,
    significant,
    told_apart,
)
from fricenv.gap.quarter_car.windows import prepare, window_nuisances, window_residuals
from fricenv.logs import QuarterCarLog, read_log
from fricenv.plants import quarter_car as qc

__all__ = [
    "FIT_LOSSES",
    "ROAD_NAMES",
    "Data",
    "DiagnoseConfig",
    "Diagnosis",
    "at_range_edge",
    "change_point_starts",
    "decide_verdict",
    "diagnose",
    "diagnose_file",
    "distinct_starts",
    "estimate_noise",
    "fit_candidate",
    "fit_time_split",
    "gap_is_real",
    "gap_of",
    "load_params",
    "param_names",
    "score",
    "window_nuisances",
    "window_residuals",
]


@dataclass
class Diagnosis:
    """Result of :func:`diagnose`; :func:`fricenv.gap.quarter_car.report.report_dict` turns it into the report.json contract."""

    verdict: str
    gap_before: float
    gap_after: float
    params: dict
    findings: Findings
    candidates: list  # CandidateFit, best first (single effects)
    nominal: CandidateFit
    joint: CandidateFit | None
    data: Data
    residuals: dict = field(default_factory=dict)  # "before"/"after": (n_windows, H) RMS normalised residual
    seconds: float = 0.0
    source: str = "<memory>"
    effects: list = field(default_factory=list)  # [{"effect", "params"}, ...] the selected set in order
    whole: CandidateFit | None = None  # the selected set's cross-fitted model

    @property
    def where(self) -> dict:
        """report.json's ``where`` (:meth:`Findings.as_where`)."""
        return self.findings.as_where()


# Effects a log's provenance predicts: log attribute -> (effect, why). Such an effect is tried first in the forward
# selection, listed first in ``effects`` and reported as a calibration, not as a discovery.
EXPECTED_EFFECTS = {"torque_from_pressure": ("brake_gain", ("T_b was computed from brake pressure through a nominal "
                                                            "factor: a brake gain is its calibration, not a discovery"))}


@dataclass
class _Selection:
    """The candidates after the tests, and what the verdict rule and the drift test made of them."""

    fits: list  # best first
    significant: list
    edges: dict  # effect -> parameters at the far edge of their range
    joint: CandidateFit | None = None
    joint_wins: bool = False
    verdict: str = "none"
    chosen: CandidateFit | None = None
    drift: dict | None = None
    residuals: dict = field(default_factory=dict)
    periodic: dict | None = None  # the line in the nominal wheel-speed residual (fricenv.gap.quarter_car.periodic), if any
    guard: dict | None = None  # what the false-discovery guard held back (fricenv.gap.quarter_car.guard), if it ran


def _calibrate_and_fit(ctx: FitContext):
    """The nominal road fitted per fold (the first fold's fit also refines the noise levels the folds share), and
    every testable candidate fitted per fold; a fold's candidate fits start in the worker processes as soon as its
    nominal fit is done, while this process calibrates the next fold.

    :return: (nominal fits per fold, candidate fits per fold, the effects not testable, the context whose settings
        hold the testable candidates only, in whose ``candidates`` order the fits are).
    """
    folds, d, cfg, jobs = ctx.folds, ctx.d, ctx.cfg, ctx.jobs
    with progress.task("calibrate the nominal model", total=len(folds)) as advance:
        first = fit_nominal(folds[0], cfg)
        refine_noise(first, folds[0])  # the folds share the noise levels (one dict)
        nominal_folds = [score("nominal", [], first.names, first.x, folds[0], first.seconds)]
        not_testable = untestable(cfg.candidates, excitation(nominal_folds[0], d, cfg.sig_z))
        # an effect rated below noise is fitted all the same: the power analysis is linearised (NotTestable.shown)
        candidates = [c for c in cfg.candidates if c not in not_testable or c in not_testable.below_noise]
        run_cfg = replace(cfg, candidates=tuple(candidates))
        pending = [start_fits([([c], nominal_folds[0].road_x(), folds[0], run_cfg, None) for c in candidates], jobs)]
        advance()
        for f in folds[1:]:
            nominal_folds.append(fit_nominal(f, cfg))
            pending.append(start_fits([([c], nominal_folds[-1].road_x(), f, run_cfg, None) for c in candidates],
                                      jobs))
            advance()
    return nominal_folds, [collect() for collect in pending], not_testable, replace(ctx, cfg=run_cfg)


def _candidates(ctx: FitContext, nominal_folds: list[CandidateFit], per_fold: list[list]):
    """The candidates cross-fitted from their fits per fold (``per_fold[j][i]``: candidate i on fold j); the nominal
    model refitted from the candidates' roads.

    :return: (cross-fitted nominal model, cross-fitted candidates in ``cfg.candidates`` order).
    """
    d, cfg = ctx.d, ctx.cfg
    nominal_folds = map_tasks(nested_nominal, [(nf, fits, f, cfg)
                                               for f, nf, fits in zip(ctx.folds, nominal_folds, per_fold)], ctx.jobs,
                              "refit the nominal model")
    nominal = cross_fitted(nominal_folds, d)
    fits = [cross_fitted([fold_fits[i] for fold_fits in per_fold], d) for i in range(len(cfg.candidates))]
    for f in fits:
        test_against(nominal, f, d)
    return nominal, fits


def _select(ctx: FitContext, nominal: CandidateFit, fits: list) -> _Selection:
    """Significance, range edges, the joint fit of the two best eligible candidates, and the verdict rule."""
    d, p, cfg = ctx.d, ctx.p, ctx.cfg
    fits = sorted(fits, key=lambda f: f.adjusted_mse)
    sig = [f for f in fits if significant(f, nominal, cfg)]
    report = None
    if cfg.false_discovery_guard:
        sig, report = guard(nominal, sig, d, cfg)
    s = _Selection(fits=fits, significant=sig, edges={f.effect: at_range_edge(f, p) for f in fits}, guard=report)
    eligible = [f for f in sig if not s.edges[f.effect]]  # significant, and not stretched to a bound
    if cfg.joint and len(eligible) >= 2:
        a, b = eligible[0], eligible[1]
        seeds = {a.effect: a.effect_params(), b.effect: b.effect_params()}
        tasks = [([a.effect, b.effect], road_of(x), f, cfg, seeds) for f, x in zip(ctx.folds, a.x_folds)]
        s.joint = cross_fitted(run_fits(tasks, ctx.jobs, "joint fit"), d)
        test_against(nominal, s.joint, d)
        s.joint_wins = significant(s.joint, nominal, cfg) and explains(s.joint, nominal, cfg) and \
            not at_range_edge(s.joint, p) and s.joint.adjusted_mse < eligible[0].adjusted_mse
    line = periodic_line(nominal, d)
    s.verdict, s.chosen, s.fits = decide_verdict(paired_order(eligible, d), fits, lambda f: explains(f, nominal, cfg),
                                                 s.joint_wins, gap_is_real(nominal, sig, cfg, periodic=line is not None))
    if line is not None:  # the line decided the verdict when the gap is real only through it
        line["decided"] = s.verdict == "unexplained" and not gap_is_real(nominal, sig, cfg)
    s.periodic = line
    return s


def _check_drift(ctx: FitContext, s: _Selection, nominal: CandidateFit) -> None:
    """Refit the model that closes the gap on each half of the log; replace it by its constant refit, and make the
    verdict ``unexplained`` if its parameters drift."""
    tested_joint = s.joint_wins and not explains(s.chosen, nominal, ctx.cfg)  # the model that closes the gap
    s.drift, refit = drift_test(s.joint if tested_joint else s.chosen, ctx.d, ctx.cfg, ctx.jobs)
    test_against(nominal, refit, ctx.d)
    if tested_joint:
        s.joint = refit
    else:
        s.fits = [refit if f is s.chosen else f for f in s.fits]
        s.significant = [refit if f is s.chosen else f for f in s.significant]
        s.chosen = refit
    if s.drift["drifts"]:  # the nearest library effect imitates something it is not: its parameters move
        s.verdict, s.chosen = "unexplained", None


def diagnose(log: QuarterCarLog, p: qc.QuarterCarParams = qc.PAPER_PARAMS,
             cfg: DiagnoseConfig = DEFAULT_CONFIG) -> Diagnosis:
    """Diagnose the sim-to-real gap of a quarter-car log (see the module docstring).

    :param log: the log (from :func:`fricenv.logs.read_log`).
    :param p: nominal vehicle parameters (``--params``).
    :param cfg: settings.
    :return: a :class:`Diagnosis`.
    """
    t_start = time.perf_counter()
    cfg.check()
    d = prepare(log, p, cfg)
    ctx = FitContext(d, tuple(fold_data(d, j) for j in range(int(cfg.folds))), cfg, default_jobs(cfg.jobs))
    expected = {e: why for attr, (e, why) in EXPECTED_EFFECTS.items() if getattr(log, attr, False)}
    with warnings.catch_warnings(), shared_pool(ctx.jobs):  # one start of the worker processes for every map below
        warnings.simplefilter("ignore", RuntimeWarning)
        nominal_folds, per_fold, not_testable, run = _calibrate_and_fit(ctx)
        nominal, fits = _candidates(run, nominal_folds, per_fold)
        s = _select(run, nominal, fits)
        # each half needs training windows in every fold: at least ``folds`` windows per half
        drift_check = cfg.drift_check and len(d.starts) >= 2 * int(cfg.folds)
        if s.chosen is not None and drift_check:
            _check_drift(ctx, s, nominal)
        whole, steps = _forward(ctx, s, nominal, tuple(expected))
        if whole is not None and s.chosen is None and drift_check:
            whole = _set_drifts(ctx, s, whole)
    effects = [] if whole is None else _order(split_params(whole), expected)
    if s.periodic is not None and whole is not None:  # the line is the effect's own signature if the set removes it
        s.periodic["remains_with_effects"] = periodic_line(whole, d) is not None
    not_testable = not_testable.shown({f.effect for f in s.significant} | {e["effect"] for e in effects})
    findings = _findings(nominal, s, d, cfg, not_testable, steps, expected)
    findings.alternatives = alternatives(effects, not_testable, p)
    if s.guard is not None:
        findings.extra["false_discovery_guard"] = s.guard
    if s.chosen is not None:
        findings.extra["told_apart"] = told_apart(s.chosen, s.significant, d, cfg)
    findings.extra.update(time_base={"origin": "first_sample", "offset_s": float(log.t_offset)},
                          warnings=list(log.warnings))
    verdict = effects[0]["effect"] if effects else s.verdict  # a discovery before an expected calibration
    return Diagnosis(verdict=verdict, gap_before=nominal.gap,
                     gap_after=nominal.gap if whole is None else whole.gap,
                     params=next((e["params"] for e in effects if e["effect"] == verdict), {}), findings=findings,
                     candidates=s.fits, nominal=nominal, joint=s.joint, data=d, residuals=s.residuals,
                     seconds=time.perf_counter() - t_start, source=log.source, effects=effects, whole=whole)


def _forward(ctx: FitContext, s: _Selection, nominal: CandidateFit, expected: tuple[str, ...]):
    """Forward selection from the verdict's effect; on an ``unexplained`` verdict with significant candidates (and
    no drift), from the best of them, and the set becomes the verdict if it closes the gap (:func:`explains`) where
    no single effect did. Returns (the whole set's model or None, the steps tried)."""
    eligible = paired_order([f for f in s.significant if not s.edges.get(f.effect)], ctx.d)
    drifted = s.drift is not None and s.drift["drifts"]  # the nearest effect imitates a drift: no set rescues it
    first = s.chosen if s.chosen is not None else \
        (eligible[0] if s.verdict == "unexplained" and eligible and not drifted else None)
    if first is None:
        return None, []
    known = {frozenset(s.joint.effect.split("+")): s.joint} if s.joint is not None else {}
    whole, steps = forward_select(ctx, nominal, first, s.fits, expected, known)
    if s.chosen is None and (whole is first or not explains(whole, nominal, ctx.cfg)):
        return None, steps
    return whole, steps


def _set_drifts(ctx: FitContext, s: _Selection, whole: CandidateFit) -> CandidateFit | None:
    """The drift test of a set that the forward selection made the verdict where no single effect closed the gap
    (the verdict was ``unexplained``, so no single model was tested for drift): its effects' parameters must be
    constant too. A brake fade is otherwise read as a brake gain plus a drag whose speed dependence imitates the
    fade's heating (clean seed 3804, logs 25 and 32). Returns the set, or None when its parameters drift."""
    s.drift, _ = drift_test(whole, ctx.d, ctx.cfg, ctx.jobs)
    return None if s.drift["drifts"] else whole


def _order(effects: list[dict], expected: dict) -> list[dict]:
    """The selected effects with the discoveries first and the expected ones (a calibration the log's provenance
    predicts, such as the gain of a nominal pressure-to-torque factor) after them: the verdict names what the model
    misses, and an expected calibration is the verdict only when nothing else was found."""
    return [e for e in effects if e["effect"] not in expected] + [e for e in effects if e["effect"] in expected]


def _findings(nominal: CandidateFit, s: _Selection, d: Data, cfg: DiagnoseConfig, not_testable, steps: list,
              expected: dict) -> Findings:
    """The evidence behind the verdict: the localisation, the tests and the selection (the residuals for the
    plots go into ``s``)."""
    localisation, s.residuals = localise(nominal, s.chosen, d, cfg.folds)
    joint = None if s.joint is None else {"effects": s.joint.effect.split("+"), "params": s.joint.effect_params(),
                                          "gap_after": s.joint.gap, "t_stat": s.joint.t_stat}
    return Findings(localisation=localisation, tests=tests_table(s.fits, s.significant, s.edges),
                    robust_gap_before=robust_gap(nominal), not_testable=not_testable, sensors=d.sensors,
                    forward_selection=steps, periodic=s.periodic, drift_test=s.drift, joint_fit=joint,
                    expected_effects=expected or None)


def load_params(path) -> qc.QuarterCarParams:
    """Vehicle parameters from a JSON file (keys of :class:`QuarterCarParams`; unknown keys rejected). A ``car``
    section (a car's mass and axle positions, docs/contracts.md section 2) is not a quarter-car key: it is passed
    over here and read by the car's own loader."""
    from dataclasses import fields as dc_fields

    from fricenv.utils import read_json_object

    raw = {k: v for k, v in read_json_object(path, "vehicle parameters").items() if k != "car"}
    valid = [f.name for f in dc_fields(qc.QuarterCarParams)]
    unknown = sorted(set(raw) - set(valid))
    if unknown:
        raise ValueError(f"{path}: unknown parameter(s) {', '.join(unknown)}; valid: {', '.join(valid)}")
    try:
        return qc.QuarterCarParams(**{k: float(v) for k, v in raw.items()})
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: {exc}") from None


def diagnose_file(path, plant: str = "quarter-car", params_file=None, cfg: DiagnoseConfig = DEFAULT_CONFIG):
    """Read a log with :func:`fricenv.logs.read_log` and diagnose it."""
    if plant != "quarter-car":
        raise ValueError(f"unknown plant {plant!r} for this diagnosis; valid plants: quarter-car")
    p = load_params(params_file) if params_file is not None else qc.PAPER_PARAMS
    log = read_log(path, plant)
    return diagnose(log, p, cfg)
