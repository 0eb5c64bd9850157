"""Sim-to-real gap diagnosis of a planar-payload log: where the gap lies, which effect, how far.

The payload's dynamics are linear in the wrench, so the diagnosis compares accelerations rather than simulating:

1. **Same filter on both sides.** The vision pose and the model's generalised force are passed through the same
   zero-phase Butterworth low-pass (``cutoff_hz``). Eq. (1) is linear, so with ``F`` the filter
   ``d2/dt2 F[theta, X, Y]`` scaled by ``(I_G, m, m)`` equals ``F[G(theta) S w_hat]`` exactly, where
   ``G(theta) = [[1, -rho_y, rho_x], [0, cos, -sin], [0, sin, cos]]`` (moment arm and rotation into the vision frame)
   and ``w = S w_hat`` is eq. (3). No initial state is needed. The pose is differenced twice before filtering, so
   the filter (one linear operator, edge padding included) acts on two signals that agree up to noise and its edge
   transients cancel. The second difference equals the second derivative smoothed by a triangle kernel of width
   2 dt; the force side gets the matching 3-tap weights ``(1, 10, 1)/12`` so that coarse sample times (10 ms) do not
   leave a discretisation residual.
2. **Noise level from the data.** The white-noise std of each raw channel (``theta, X, Y, M, f_x, f_y``) is
   estimated from its 4th differences (:func:`fricenv.gap.quarter_car.diagnose.estimate_noise`) and propagated through the
   filters (the sum of the squared impulse response) to the residual of each channel; the residual's
   autocorrelation gives the effective number of independent samples used by the significance test.
3. **Held-out split in time.** Alternate blocks of ``block_s``; every ``test_every``-th block is held out; a guard at
   each block edge and a margin at both log ends (filter transients) are not scored.
4. **Candidates.** ``wrench_offset`` (3 constants) and ``calibration_error`` (the full S, 9 entries) are linear least
   squares; ``calibration_drift`` is a 1-D bounded search over the rate; ``vision_delay`` a grid plus bounded search
   over the delay (the wrench is shifted by linear interpolation, the rotation uses the measured, i.e. delayed,
   orientation). Every fit uses the training blocks only. The drift's ``t`` is the time since the log's first sample
   (docs/contracts.md: ``S(t) = S (1 + rate t)``; the report's time base, so an epoch-stamped log drifts as one from 0). Errors of m, I_G or rho map the generalised force by a constant matrix that commutes
   with the rotation, so they show up (exactly) as a ``calibration_error``.
5. **Scoring and verdict** as for the quarter car (:mod:`fricenv.gap.quarter_car.diagnose`): ``gap = sqrt(max(MSE - 1, 0))`` of
   the held-out normalised residual; a candidate is significant when its held-out improvement, without its largest
   block, exceeds ``sig_z`` standard deviations of that sum under pure noise (effective sample count), and
   candidates are ranked by the held-out MSE plus ``PENALTY_PER_PARAM`` times their parameter count over the
   effective training samples (a richer model cannot win by chance). The verdict needs significance and a held-out
   gap at most ``ratio_explained`` of the nominal one (or within ``gap_none``). The two best significant candidates
   are also fitted jointly (reported under ``where["joint_fit"]``).
6. **Reported parameters.** Once the held-out blocks have chosen the model, its parameters are fitted again on every
   scored block (training and held-out, ``where["params_fit"]``): twice the data for the estimate, while every gap
   and test stays held-out. On fresh real-like rig logs (``validation.real_payload`` seeds 2129-2131) this took the
   parameters within 15 % from 18/23 to 20/23 (tuning seeds 2125-2128: 24/32 to 27/32).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize_scalar

from fricenv.effects.payload import PAYLOAD_TESTABLE, PayloadExcitation
from fricenv.gap.core.noise import gap_of
from fricenv.gap.core.verdict import decide_verdict
from fricenv.gap.payload.data import (
    CHANNELS,
    DEFAULT_PAYLOAD_CONFIG,
    WRENCH,
    PayloadData,
    PayloadDiagnoseConfig,
    generalised_force_map,
    lowpass,
    prepare_payload,
)
from fricenv.gap.payload.guard import ACF_SPAN, guarded_z, residual_rho2
from fricenv.gap.payload.localise import where_gap
from fricenv.logs import PayloadLog, read_log
from fricenv.plants import payload as pl
from fricenv.utils import read_json_object

__all__ = [
    "CHANNELS",
    "PayloadCandidate",
    "PayloadData",
    "PayloadDiagnoseConfig",
    "PayloadDiagnosis",
    "diagnose_payload",
    "diagnose_payload_file",
    "improvement_z",
    "load_payload_params",
    "score_prediction",
    "summary_line",
]

PENALTY_PER_PARAM = 2.0  # ranking penalty per fitted parameter, in units of 1/(effective training samples) [-]
DELAY_GRID_STEP = 0.005  # delay grid step [s] before the bounded refinement
SEARCH_XTOL = 1e-5  # tolerance of the bounded 1-D searches (s or 1/s)
# Uncertainty of a force-moment filter's lag read from its noise roll-off: (share of the lag, floor [s]); every
# model's pose-wrench shift may move this far from the lag, so a vision delay below it is not told from an error of it
LAG_TOLERANCE = (0.25, 0.002)
PARAM_KEYS = ("m", "I_G", "rho_x", "rho_y", "S")  # valid keys of --params



@dataclass
class PayloadCandidate:
    """One fitted model (the attribute names match :class:`fricenv.gap.quarter_car.diagnose.CandidateFit` where the report
    needs them)."""

    effect: str  # effect name, "nominal", or "a+b" for a joint fit
    params: dict  # fitted effect parameters, SI units (S as a 3x3 nested list)
    n_params: int
    train_mse: float
    test_mse: float
    block_mse: np.ndarray  # per block, mean squared normalised residual
    residual: np.ndarray  # (n, 3) normalised residual on all samples
    gap: float = 0.0
    penalised: float = 0.0  # held-out MSE + ranking penalty
    z: float = 0.0
    seconds: float = 0.0
    shift: float = 0.0  # fitted pose-wrench shift [s]: a vision delay (> 0) or a filtered sensor's lag (< 0)

    def effect_params(self) -> dict:
        return dict(self.params)


@dataclass
class PayloadDiagnosis:
    """Result of :func:`diagnose_payload`; :func:`fricenv.gap.quarter_car.report.report_dict` turns it into report.json."""

    verdict: str
    gap_before: float
    gap_after: float
    params: dict
    where: dict
    candidates: list  # PayloadCandidate, best first
    nominal: PayloadCandidate
    joint: PayloadCandidate | None
    data: PayloadData
    chosen: PayloadCandidate | None = None
    seconds: float = 0.0
    source: str = "<memory>"
    residuals: dict = field(default_factory=dict)


# --------------------------------------------------------------------------------------------- preparation
# --------------------------------------------------------------------------------------------- models
@dataclass
class _Regressors:
    """Filtered regressors for one delay value; the prediction is linear in S (or uses the known S) and in
    c = S o. Only what the fitted effects need is filtered (a delay search filters 3 or 6 columns per step)."""

    phi: np.ndarray | None  # (n, 3, 3, 3): F[G[:, i, j] w_hat_k] -> coefficient S_jk (free S only)
    phi_t: np.ndarray | None  # the same times t (free S with drift)
    base: np.ndarray | None  # (n, 3): F[G S_known w_hat] (known S only)
    base_t: np.ndarray | None  # the same times t (known S with drift)
    g: np.ndarray | None  # (n, 3, 3): F[G[:, i, j]] -> coefficient -c_j (offset only)
    g_t: np.ndarray | None


def _regressors(d: PayloadData, delay: float, effects: Sequence[str]) -> _Regressors:
    w = d.w_hat
    if delay != 0:
        w = np.column_stack([np.interp(d.t - delay, d.t, d.w_hat[:, k]) for k in range(3)])
    G = generalised_force_map(d.theta_f, d.p)
    n = d.n
    free_S = "calibration_error" in effects
    drift = "calibration_drift" in effects
    blocks: list[tuple[str, np.ndarray]] = []
    if free_S:
        blocks.append(("phi", (G[:, :, :, None] * w[:, None, None, :]).reshape(n, 27)))
    else:
        blocks.append(("base", np.einsum("nij,jk,nk->ni", G, d.S_known, w)))
    if "wrench_offset" in effects:
        blocks.append(("g", G.reshape(n, 9)))
    if drift:
        since = (d.t - d.t[0])[:, None]  # the report's time base: from the first sample
        blocks += [(name + "_t", x * since) for name, x in blocks]
    f = lowpass(d.sos, np.concatenate([x for _, x in blocks], axis=1))
    out = dict.fromkeys(("phi", "phi_t", "base", "base_t", "g", "g_t"))
    shapes = {"phi": (n, 3, 3, 3), "base": (n, 3), "g": (n, 3, 3)}
    col = 0
    for name, x in blocks:
        out[name] = f[:, col:col + x.shape[1]].reshape(shapes[name.removesuffix("_t")])
        col += x.shape[1]
    return _Regressors(**out)


def _with_rate(x: np.ndarray | None, x_t: np.ndarray | None, rate: float) -> np.ndarray | None:
    return x if x is None or x_t is None or rate == 0.0 else x + rate * x_t


def _solve(effects: Sequence[str], R: _Regressors, rate: float, d: PayloadData, rows: np.ndarray):
    """Linear part of the fit for a given delay and drift rate: returns (S, o, prediction (n, 3))."""
    phi = _with_rate(R.phi, R.phi_t, rate)
    base = _with_rate(R.base, R.base_t, rate)
    g = _with_rate(R.g, R.g_t, rate)
    free_S = phi is not None
    free_o = g is not None
    S = d.S_known
    if not free_S and not free_o:
        return S, np.zeros(3), base
    cols = []
    target = d.y if free_S else d.y - base
    if free_S:
        cols.append(phi.reshape(d.n, 3, 9))
    if free_o:
        cols.append(-g)
    A = np.concatenate(cols, axis=2)  # (n, 3, q)
    wts = 1.0 / d.sigma
    Aw = (A[rows] * wts[None, :, None]).reshape(-1, A.shape[2])
    bw = (target[rows] * wts[None, :]).reshape(-1)
    coef, *_ = np.linalg.lstsq(Aw, bw, rcond=None)
    pred = np.einsum("niq,q->ni", A, coef) + (0.0 if free_S else base)
    if free_S:
        S = coef[:9].reshape(3, 3)
    o = np.zeros(3)
    if free_o:
        try:
            o = np.linalg.solve(S, coef[-3:])
        except np.linalg.LinAlgError:
            o = np.full(3, np.nan)
    return S, o, pred


def _cost(pred: np.ndarray, d: PayloadData, rows: np.ndarray) -> float:
    r = (d.y[rows] - pred[rows]) / d.sigma
    return float(np.mean(r**2))


def _n_params(effects: Sequence[str]) -> int:
    return sum({"wrench_offset": 3, "calibration_error": 9}.get(e, 1) for e in effects)


def _fit(effects: Sequence[str], d: PayloadData, cfg: PayloadDiagnoseConfig,
         rows: np.ndarray | None = None) -> tuple[dict, np.ndarray, float]:
    """Fit the effects on the samples ``rows`` (default: the training blocks); returns (params, prediction on all
    samples, pose-wrench shift [s])."""
    rows = d.train if rows is None else rows

    def regs(delay: float) -> _Regressors:
        return _regressors(d, delay, effects)

    def best_rate(R: _Regressors) -> tuple[float, float]:
        if "calibration_drift" not in effects:
            return 0.0, _cost(_solve(effects, R, 0.0, d, rows)[2], d, rows)
        res = minimize_scalar(lambda r: _cost(_solve(effects, R, r, d, rows)[2], d, rows),
                              bounds=(-cfg.max_rate, cfg.max_rate), method="bounded",
                              options={"xatol": SEARCH_XTOL})
        return float(res.x), float(res.fun)

    # the shift between pose and wrench, fitted for every model: a vision delay (pose late, > 0), and the wrench late
    # by a low-passed or averaging force-moment sensor (< 0), a nuisance of every model (_shift_range)
    delay, lo, hi = _shift_range(d, cfg, "vision_delay" in effects)
    if hi > lo:
        delay = _best_shift(lambda x: best_rate(regs(x))[1], lo, hi, max(DELAY_GRID_STEP, d.dt), d.dt)
    R = regs(delay)
    rate, _ = best_rate(R)
    S, o, pred = _solve(effects, R, rate, d, rows)
    params: dict = {}
    for e in effects:
        if e == "wrench_offset":
            params.update({"M0": float(o[0]), "fx0": float(o[1]), "fy0": float(o[2])})
        elif e == "calibration_error":
            params["S"] = [[float(v) for v in row] for row in S]
        elif e == "calibration_drift":
            params["rate"] = rate
        elif e == "vision_delay":
            params["delay"] = delay + (d.wrench_lag or 0.0)  # the camera's own delay: the net shift plus the lag
    return params, pred, delay


def _best_shift(cost, lo: float, hi: float, step: float, dt: float) -> float:
    """The shift in ``[lo, hi]`` of least ``cost``: a grid of ``step`` and a bounded search around its best point;
    over a range of at most one sample (the nuisance of an unfiltered sensor), the vertex of the parabola through
    both ends and the middle (the cost is quadratic in so small a shift), whichever of the four costs least."""
    if hi - lo <= dt + 1e-12:
        xs = [lo, 0.5 * (lo + hi), hi]
        cs = [cost(x) for x in xs]
        curv = cs[0] - 2.0 * cs[1] + cs[2]
        if curv > 0:
            xs.append(float(np.clip(xs[1] + 0.5 * (hi - lo) * (cs[0] - cs[2]) / (2.0 * curv), lo, hi)))
            cs.append(cost(xs[-1]))
        return float(xs[int(np.argmin(cs))])
    grid = np.linspace(lo, hi, max(int(np.ceil((hi - lo) / step - 1e-9)) + 1, 2))
    costs = [cost(g) for g in grid]
    i = int(np.argmin(costs))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    res = minimize_scalar(cost, bounds=(a, b), method="bounded", options={"xatol": SEARCH_XTOL})
    return float(res.x) if res.fun <= costs[i] else float(grid[i])


def _shift_range(d: PayloadData, cfg: PayloadDiagnoseConfig, vision: bool) -> tuple[float, float, float]:
    """(start, lower, upper) of the fitted pose-wrench shift [s] (docs/contracts.md, payload timing).

    Every model may read the wrench late, by down to ``-(L + tolerance + dt / 2)``: a sensor filter's lag ``L``
    read from the force-moment noise's roll-off (``d.wrench_lag``, within ``LAG_TOLERANCE``; without a roll-off but
    a filtered-looking channel, up to ``wrench_lag_max``) and half a sample for a logger that averages the reading
    over its sample period. The upper bound is 0 (no shift) for every model but ``vision_delay``, whose pose may lag
    by up to ``max_delay_s`` net of the lag: a lag read from the noise is a hypothesis that the motion can overrule
    (a smoothing without lag, or one that the pose passed as well, leaves the nominal model at 0), so it can never
    make a vision delay on its own. A fitted delay is reported as the camera's own (net shift plus ``L``)."""
    lag = d.wrench_lag or 0.0
    span = lag + max(LAG_TOLERANCE[0] * lag, LAG_TOLERANCE[1]) if d.wrench_lag is not None else d.wrench_lag_max
    lo = -(span + 0.5 * d.dt)
    return -lag, lo, (cfg.max_delay_s - lag if vision else 0.0)


def _score(name: str, effects: Sequence[str], params: dict, pred: np.ndarray, d: PayloadData,
           seconds: float) -> PayloadCandidate:
    return score_prediction(name, _n_params(effects), pred, d, params, seconds)


def score_prediction(name: str, n_params: int, pred: np.ndarray, d: PayloadData, params: dict | None = None,
                     seconds: float = 0.0) -> PayloadCandidate:
    """A model's prediction ``pred`` (n, 3) scored on the prepared log ``d`` as every candidate is: normalised
    residual, block and held-out mean squares, gap, and the held-out error penalised for ``n_params``."""
    r = (d.y - pred) / d.sigma
    sq = np.mean(r**2, axis=1)
    nb = len(d.block_test)
    scored = d.block >= 0
    sums = np.bincount(d.block[scored], weights=sq[scored], minlength=nb)
    counts = np.maximum(np.bincount(d.block[scored], minlength=nb), 1)
    n_eff_train = np.count_nonzero(d.train) * len(CHANNELS) / d.rho2
    test_mse = float(np.mean(sq[d.test]))
    return PayloadCandidate(effect=name, params=params or {}, n_params=n_params,
                            train_mse=float(np.mean(sq[d.train])), test_mse=test_mse, block_mse=sums / counts,
                            residual=r, gap=gap_of(test_mse),
                            penalised=test_mse + PENALTY_PER_PARAM * n_params / n_eff_train, seconds=seconds)


def fit_payload_candidate(effects: Sequence[str], d: PayloadData, cfg: PayloadDiagnoseConfig) -> PayloadCandidate:
    """Fit a set of effects on the training blocks and score it on all blocks."""
    t0 = time.perf_counter()
    effects = list(effects)
    params, pred, shift = _fit(effects, d, cfg)
    fit = _score("+".join(effects) if effects else "nominal", effects, params, pred, d, time.perf_counter() - t0)
    fit.shift = shift
    return fit


def improvement_z(base: PayloadCandidate, cand: PayloadCandidate, d: PayloadData) -> float:
    """Held-out improvement of the sum of squared normalised residuals, without its largest block, in standard
    deviations of that sum under pure noise (``sqrt(2) N / sqrt(n_eff)`` for correlated residuals)."""
    test_blocks = np.flatnonzero(d.block_test)
    counts = np.bincount(d.block[d.block >= 0], minlength=len(d.block_test))[test_blocks] * len(CHANNELS)
    gain = (base.block_mse[test_blocks] - cand.block_mse[test_blocks]) * counts
    if gain.size == 0:
        return 0.0
    robust = float(np.sum(gain) - max(float(np.max(gain)), 0.0))
    N = float(np.sum(counts))
    return robust / (np.sqrt(2.0) * N / np.sqrt(N / d.rho2))


# --------------------------------------------------------------------------------------------- diagnosis
def payload_untestable(d: PayloadData) -> dict[str, str]:
    """The payload effects the log cannot show, each with the reason (:data:`PAYLOAD_TESTABLE`)."""
    snr = min(float(np.std(d.w_hat[:, i])) / max(d.raw_noise[c], 1e-12) for i, c in enumerate(WRENCH))
    fresh = (d.sensors or {}).get("theta", {}).get("missing_share", 0.0)
    x = PayloadExcitation(duration=d.n * d.dt, wrench_snr=snr, pose_rate=(1.0 - fresh) / d.dt)
    return {e: r for e, rule in PAYLOAD_TESTABLE.items() if (r := rule(x)) is not None}


def _data_summary(d: PayloadData, cfg: PayloadDiagnoseConfig) -> dict:
    """``where["data"]``: samples, blocks, effective samples, the filter and the raw noise levels."""
    n_scored = int(np.count_nonzero(d.block >= 0))
    return {"samples": d.n, "dt": d.dt, "blocks": len(d.block_test),
            "held_out_blocks": int(np.count_nonzero(d.block_test)), "block_s": cfg.block_s,
            "scored_samples": n_scored, "effective_samples": n_scored * len(CHANNELS) / d.rho2,
            "filter": f"zero-phase Butterworth order {cfg.filter_order}, {cfg.cutoff_hz:g} Hz",
            "raw_noise_std": d.raw_noise}


def _sensors(d: PayloadData, nominal: PayloadCandidate) -> dict:
    """``where["sensors"]``; a low-passed force-moment sensor also gets its lag (from its noise roll-off if it
    shows, else the nominal model's shift) and ``lag_fit_s``, the nominal model's shift (the motion's view)."""
    sensors = d.sensors
    if d.wrench_lag_max > 0:
        for c in WRENCH:
            sensors[c]["lag_s"] = -nominal.shift if d.wrench_lag is None else d.wrench_lag
            sensors[c]["lag_fit_s"] = -nominal.shift
    return sensors


def diagnose_payload(log: PayloadLog, S_known=pl.PAPER_S, p: pl.PayloadParams = pl.PAPER_PARAMS,
                     cfg: PayloadDiagnoseConfig = DEFAULT_PAYLOAD_CONFIG) -> PayloadDiagnosis:
    """Diagnose the sim-to-real gap of a payload log (see the module docstring).

    :param log: the log (from :func:`fricenv.logs.read_log` with ``plant="payload"``).
    :param S_known: the calibration the nominal model assumes, 3x3.
    :param p: nominal mass properties and sensor location.
    :param cfg: settings.
    :return: a :class:`PayloadDiagnosis`.
    """
    t_start = time.perf_counter()
    S_known = np.asarray(S_known, dtype=float)
    if S_known.shape != (3, 3) or not np.all(np.isfinite(S_known)) or np.linalg.cond(S_known) > 1e12:
        raise ValueError(f"S_known must be a finite invertible 3x3 matrix, got {S_known!r}")
    d = prepare_payload(log, S_known, p, cfg)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        nominal = fit_payload_candidate([], d, cfg)
        fits = [fit_payload_candidate([c], d, cfg) for c in cfg.candidates]
    for f in fits:
        f.z = improvement_z(nominal, f, d)
    fits.sort(key=lambda f: f.penalised)

    # the false-discovery guard: where the nominal model fits within the noise, its residual is the noise, and a
    # candidate's evidence must also hold with the correlation that residual shows (a filtered, held or quantised
    # channel: fewer independent samples than the propagation of white raw noise counts)
    within_noise = nominal.gap <= cfg.gap_none
    measured_rho2 = residual_rho2(nominal.residual, d.block >= 0, round(ACF_SPAN / (cfg.cutoff_hz * d.dt)))

    def evidence(f: PayloadCandidate) -> float:
        return guarded_z(f.z, d.rho2, measured_rho2) if within_noise else f.z

    def significant(f: PayloadCandidate) -> bool:
        return evidence(f) > cfg.sig_z and f.penalised < nominal.penalised

    def explains(f: PayloadCandidate) -> bool:
        return f.gap <= cfg.ratio_explained * nominal.gap or f.gap <= cfg.gap_none

    sig = [f for f in fits if significant(f)]
    joint = None
    if cfg.joint and len(sig) >= 2:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            joint = fit_payload_candidate([sig[0].effect, sig[1].effect], d, cfg)
        joint.z = improvement_z(nominal, joint, d)
    joint_wins = joint is not None and significant(joint) and explains(joint) and bool(sig) and \
        joint.penalised < sig[0].penalised
    verdict, chosen, fits = decide_verdict(sig, fits, explains, joint_wins, nominal.gap > cfg.gap_none)
    loc = where_gap(d, nominal, chosen, getattr(log, "t_offset", 0.0))
    where = {
        "time_base": loc["time_base"],
        "segments": loc["segments"],
        "regimes": loc["regimes"],
        "channels": loc["channels"],
        "data": _data_summary(d, cfg),
        "tests": {f.effect: {"z": f.z, "z_measured_noise": evidence(f), "penalised_test_mse": f.penalised,
                             "n_params": f.n_params, "significant": bool(significant(f))} for f in fits},
        # candidates significant by the propagated noise alone on a log the nominal model fits within the noise
        "red_flags": [f.effect for f in fits if within_noise and f.z > cfg.sig_z and not significant(f)
                      and f.penalised < nominal.penalised],
        "residual_rho2": {"propagated": d.rho2, "measured": measured_rho2},
    }
    where["sensors"] = _sensors(d, nominal)
    where["not_testable"] = payload_untestable(d)
    if joint is not None:
        where["joint_fit"] = {"effects": joint.effect.split("+"), "params": joint.effect_params(),
                              "gap_after": joint.gap, "z": joint.z}
    gap_after = chosen.gap if chosen is not None else nominal.gap
    residuals = {"labels": loc["labels"]}
    params = {}
    if chosen is not None:  # chosen on held-out blocks; its parameters estimated from every scored block
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            params = _fit(chosen.effect.split("+"), d, cfg, rows=d.block >= 0)[0]
        where["params_fit"] = "all scored blocks (training and held-out), after the held-out verdict"
    return PayloadDiagnosis(verdict=verdict, gap_before=nominal.gap, gap_after=gap_after, params=params, where=where,
                            candidates=fits, nominal=nominal, joint=joint, data=d, chosen=chosen,
                            seconds=time.perf_counter() - t_start, source=log.source, residuals=residuals)


def load_payload_params(path) -> tuple[np.ndarray, pl.PayloadParams]:
    """Known calibration ``S`` (key ``S``, 3x3 row-major) and mass properties (``m, I_G, rho_x, rho_y``) from a JSON
    file; missing keys keep the paper's values, unknown keys are rejected."""
    raw = read_json_object(path, "payload parameters")
    unknown = sorted(set(raw) - set(PARAM_KEYS))
    if unknown:
        raise ValueError(f"{path}: unknown parameter(s) {', '.join(unknown)}; valid: {', '.join(PARAM_KEYS)}")
    S = pl.PAPER_S
    if "S" in raw:
        try:
            S = np.asarray(raw["S"], dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{path}: key 'S' must be a 3x3 list of numbers") from None
        if S.size == 9:
            S = S.reshape(3, 3)
        if S.shape != (3, 3) or not np.all(np.isfinite(S)) or abs(np.linalg.det(S)) < 1e-12:
            raise ValueError(f"{path}: key 'S' must be a finite invertible 3x3 matrix (row-major), got {raw['S']!r}")
    try:
        p = pl.PayloadParams(**{k: float(v) for k, v in raw.items() if k != "S"})
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: {exc}") from None
    return S, p


def diagnose_payload_file(path, params_file=None,
                          cfg: PayloadDiagnoseConfig = DEFAULT_PAYLOAD_CONFIG) -> PayloadDiagnosis:
    """Read a payload log with :func:`fricenv.logs.read_log` and diagnose it."""
    S, p = load_payload_params(params_file) if params_file is not None else (pl.PAPER_S, pl.PAPER_PARAMS)
    return diagnose_payload(read_log(path, "payload"), S, p, cfg)


def _fmt(v) -> str:
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return f"{v:.4g}"


def summary_line(dg: PayloadDiagnosis) -> str:
    """One-line summary for the command line."""
    params = ", ".join(f"{k}={_fmt(v)}" for k, v in dg.params.items())
    verdict = dg.verdict + (f" ({params})" if params else "")
    seg = dg.where["segments"][0] if dg.where.get("segments") else None
    worst = f"; worst segment {seg['t_start']:.2f}-{seg['t_end']:.2f} s" if seg else ""
    return (f"verdict: {verdict}; gap_before {dg.gap_before:.3g} -> gap_after {dg.gap_after:.3g} "
            f"(noise units, held-out){worst}")

