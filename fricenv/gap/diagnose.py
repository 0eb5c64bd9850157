"""Sim-to-real gap diagnosis of a quarter-car braking log (issue 6): where the gap lies, which effect, how far it shrinks.

Method (every error measure is computed on data not used for fitting):

1. **Noise level.** Estimated from the log itself, per channel, by the median absolute second difference
   (white noise of std s gives second differences of std s sqrt(6); the median ignores the sparse kinks of the
   signal). No assumption on the log writer's noise values.
2. **States from data.** The log is cut into prediction windows of ``horizon`` samples (0.1 s: beyond the
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
   the road away from the rest of the data. The road is always treated as unknown.
4. **Gap.** Held-out residuals over all logged channels, each divided by its noise level (the smaller of the
   difference-based estimate and the calibrated nominal model's training residual: both over-estimate). A window's
   mean squared normalised residual counts at most ``WINDOW_MSE_CAP``. ``gap`` is the model part of the held-out
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
   ``gap_within_noise``); ``unexplained`` when the gap is real (nominal gap above ``gap_none`` and not only in the
   trimmed windows, or a significant candidate) and no candidate closes it; ``none`` otherwise. The two best
   significant candidates are also fitted jointly; if only the joint model closes the gap, the larger single effect
   is the verdict and the other follows in ``candidates`` (the joint fit is reported under ``where["joint_fit"]``).
   A candidate whose effect parameter is pressed against the far bound of its physical range (:func:`at_range_edge`)
   still shows that the gap is real, but cannot be the verdict: it is being stretched to imitate something else.
8. **Drift test.** The verdict's model is refitted on the early and on the late half of the log separately (each
   half cross-fitted within itself). A library effect has constant parameters, so if the split model beats the
   constant one significantly (paired z above ``drift_z``) and halves the robust gap it leaves (when that gap is
   above the noise), the effect only imitates the cause (brake fade looks like a brake gain that drifts down) and
   the verdict is ``unexplained``. The constant model is refitted from the split fits first, so that a better
   optimum is not mistaken for a drift (``where["drift_test"]``).
"""

from __future__ import annotations

import os
import time
import warnings
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import savgol_filter

from fricenv.effects.quarter_car import (
    DEFAULT_SUBSTEPS,
    EFFECT_PARAMS,
    EFFECTS,
    EffectSimulator,
    ModelBatch,
)
from fricenv.gap.speed import filtered_transient_slip, reconstruct_speed
from fricenv.logs import QuarterCarLog, read_log
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import ROADS, MagicFormula, longitudinal_slip

__all__ = [
    "ROAD_NAMES",
    "CandidateFit",
    "DiagnoseConfig",
    "Diagnosis",
    "diagnose",
    "diagnose_file",
    "estimate_noise",
    "load_params",
]

ROAD_NAMES = ("B", "C", "E", "theta")
# Road parameter bounds for the fit: wide enough for every preset and for unknown roads. B and theta: wide.
# C and E: the physically plausible range of longitudinal Magic Formula shapes (the presets span C 0.9-2.3,
# E -6.4-1). A wider range lets the nominal road take unphysical shapes that absorb an effect (a flat curve with
# E = -12 hides a rolling-radius error on ice).
ROAD_BOUNDS = {"B": (2.0, 40.0), "C": (0.8, 2.8), "E": (-8.0, 1.0), "theta": (0.03, 1.6)}
# Effect parameter bounds (SI units) and the starting values of the multi-start.
EFFECT_BOUNDS = {
    "tau": (1e-3, 0.4), "delay": (0.0, 0.25), "gain": (0.3, 3.0), "sigma": (0.01, 3.0), "r_eff": (0.25, 0.45),
    "t_change": (-np.inf, np.inf), "theta_after": (0.03, 1.6), "c0": (0.0, 3000.0), "c2": (0.0, 10.0),
}
EFFECT_STARTS = {
    "brake_lag": [{"tau": v} for v in (0.01, 0.03, 0.07, 0.15)],
    "brake_delay": [{"delay": v} for v in (0.01, 0.025, 0.045, 0.08)],
    "brake_gain": [{"gain": v} for v in (0.8, 0.9, 1.1, 1.25)],
    "relaxation_length": [{"sigma": v} for v in (0.1, 0.3, 0.6, 1.2)],
    "radius_error": [{"r_eff": f} for f in (0.96, 0.98, 1.02, 1.04)],  # times the nominal radius
    "mu_change": [],  # change-point search, see _mu_change_starts
    "drag": [{"c0": a, "c2": b} for a, b in ((50.0, 0.0), (200.0, 0.0), (0.0, 0.3), (100.0, 0.2), (400.0, 0.5))],
}
# Finite-difference steps of the fit Jacobian, per parameter (absolute).
FD_STEP = {"B": 0.05, "C": 0.005, "E": 0.02, "theta": 0.002, "tau": 1e-3, "delay": 1e-3, "gain": 2e-3,
           "sigma": 5e-3, "r_eff": 2e-4, "t_change": 0.01, "theta_after": 0.002, "c0": 2.0, "c2": 0.01}
X_SCALE = {"B": 1.0, "C": 0.1, "E": 0.5, "theta": 0.05, "tau": 0.01, "delay": 0.01, "gain": 0.05, "sigma": 0.1,
           "r_eff": 0.005, "t_change": 0.1, "theta_after": 0.05, "c0": 50.0, "c2": 0.1}

V0_STEP = 0.02  # finite-difference step of the per-window speed nuisance (v logged) [m/s]
LAMT_STEP = 0.005  # finite-difference step of the transient-slip nuisance [-]
LAMT_MAX_MOVE = 0.1  # largest Gauss-Newton move of the transient slip per iteration [-]
OMEGA0_STEP = 0.1  # finite-difference step of the per-window wheel-speed nuisance [rad/s]
OMEGA0_MAX_MOVE = 3.0  # largest Gauss-Newton move of that nuisance per iteration, in noise std [-]
GN_ITERS = 2  # Gauss-Newton iterations of the wheel-speed nuisance
FREE_ROLL_TORQUE = 0.02  # free rolling: |T_b| below this share of max |T_b| [-]
SAVGOL = (11, 2)  # speed smoother: window [samples], polynomial order
NOISE_FLOOR = {"omega": 1e-3, "v": 1e-3, "a_x": 1e-3}  # smallest accepted noise std per channel (SI)
SPEED_BANDS = (10.0, 20.0)  # band edges [m/s]
# Transient slip at a window start: False = the slip of the window's start state (the wheel-speed nuisance fit then
# absorbs the difference); True = the measured slip filtered through the relaxation equation.
RELAX_STATE_FROM_FILTER = True
# Whether the transient slip is also fitted per window, like the wheel speed (the filtered estimate alone predicts
# the relaxation model's transients poorly). It is a state fitted on the window's own samples, so it lowers the
# relaxation model's held-out error by about one noise variance per window even on pure noise; the significance
# tests subtract that (:func:`window_nuisances`).
RELAX_STATE_FITTED = True
# A window's mean squared normalised error counts at most this much in the scores (RMS 5 noise std): a wheel lock-up
# predicted a few milliseconds early or late is wrong whatever the size of its error, and must not decide alone.
WINDOW_MSE_CAP = 25.0
# Residual scale (noise std) of the fits' robust loss; the change-point search bounds a sample's squared residual
# at (2 FIT_LOSS_SCALE)^2. Either way one lock-up cannot place the road or the change.
FIT_LOSS_SCALE = 3.0
FIT_LOSSES = ("linear", "soft_l1", "cauchy")  # losses of the least-squares fits (scipy's names)
# Share of the held-out windows (the worst) left out when judging how much of the gap a candidate closes.
TRIM_SHARE = 0.05
# A fitted effect parameter within this share of its range (EFFECT_BOUNDS) from a bound sits at the bound [-]
RANGE_EDGE = 1e-3
# A drift must leave at most this share of the constant model's robust gap (the split model halves it at least).
DRIFT_SHARE = 0.5
MU_CHANGE_FACTORS = np.geomspace(0.35, 2.0, 16)  # theta grid of the change-point search, times the nominal theta
APPLY_RATE = 0.5  # |dT_b/dt| above this share of max |T_b| per second counts as apply/release [1/s]


@dataclass(frozen=True)
class DiagnoseConfig:
    """Settings of the diagnosis."""

    horizon: int = 10  # prediction window [samples]
    folds: int = 2  # cross-fitting folds: window i belongs to fold i % folds; each fold is held out once [-]
    max_nfev: int = 30  # least-squares iterations per start [-]
    # Least-squares runs per candidate fit, from the best starts with distinct roads: a run started in the nominal
    # road's basin can stop there (a non-smooth point of the windowed residuals) far from the effect's optimum [-]
    fit_starts: int = 2
    # Loss of the fits on the normalised residuals (scale FIT_LOSS_SCALE noise std). A robust loss keeps the few
    # lock-up windows, whose timing no model predicts, from bending the road away from the bulk of the data.
    fit_loss: str = "soft_l1"
    sig_z: float = 4.0  # robust held-out improvement (noise standard deviations) a candidate must exceed [-]
    ratio_explained: float = 0.35  # a verdict leaves at most this share: gap_after <= ratio * gap_before [-]
    gap_none: float = 1.1  # nominal gap (noise units) below which the model fits within noise [-]
    gap_within_noise: float = 0.3  # a candidate leaving a robust held-out gap below this explains the gap [-]
    substeps: int = DEFAULT_SUBSTEPS  # physics substeps per sample
    jobs: int | None = None  # processes for the candidate fits (None: min(2, available cores))
    joint: bool = True  # also fit the two best significant candidates together
    drift_check: bool = True  # refit the verdict's model on each half of the log; a drift makes it unexplained
    drift_z: float = 3.0  # paired z of the early/late refit over the constant model for a drift (one test) [-]
    candidates: tuple[str, ...] = tuple(EFFECTS)  # effects to try


@dataclass
class Data:
    """The log prepared for fitting (picklable for the worker processes)."""

    t0: float
    dt: float
    Tb: np.ndarray
    omega: np.ndarray
    v: np.ndarray | None
    a_x: np.ndarray | None
    sigma: dict  # noise std per logged channel
    v_smooth: np.ndarray | None
    starts: np.ndarray  # window start indices
    fold: np.ndarray  # cross-fitting fold of each window
    test: np.ndarray  # bool per window: held out in the fit at hand (the others are its training windows)
    horizon: int
    free_end: int  # first sample after the free-rolling stretch
    p: qc.QuarterCarParams
    substeps: int

    @property
    def n(self) -> int:
        return len(self.Tb)

    @property
    def channels(self) -> list[str]:
        return ["omega"] + (["v"] if self.v is not None else []) + (["a_x"] if self.a_x is not None else [])


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
    seconds: float = 0.0
    resid: np.ndarray | None = None  # (windows, samples) normalised residuals of all windows
    x_folds: tuple = ()  # the per-fold fits of a cross-fitted candidate (x is their mean)
    nuisances: int = 1  # states fitted per window on the window's own samples (window_nuisances)
    samples: int = 1  # normalised residuals per window (horizon times channels)

    @property
    def adjusted_mse(self) -> float:
        """Held-out mean squared normalised residual plus what the per-window nuisance states win on pure noise:
        the figure models with different nuisances are ranked by."""
        return self.test_mse + self.nuisances / self.samples

    def effect_params(self) -> dict[str, float]:
        return {k: float(v) for k, v in zip(self.names, self.x) if k not in ROAD_NAMES}

    def road(self) -> dict[str, float]:
        return {k: float(v) for k, v in zip(self.names, self.x) if k in ROAD_NAMES}


@dataclass
class Diagnosis:
    """Result of :func:`diagnose`; :func:`fricenv.gap.report.report_dict` turns it into the report.json contract."""

    verdict: str
    gap_before: float
    gap_after: float
    params: dict
    where: dict
    candidates: list  # CandidateFit, best first (single effects)
    nominal: CandidateFit
    joint: CandidateFit | None
    data: Data
    residuals: dict = field(default_factory=dict)  # "before"/"after": (n_windows, H) RMS normalised residual
    seconds: float = 0.0
    source: str = "<memory>"


# --------------------------------------------------------------------------------------------- data preparation
def estimate_noise(x: np.ndarray, order: int = 2) -> float:
    """Noise std of a sampled signal from the median absolute difference of the given order (robust to sparse
    kinks). White noise of std s gives k-th differences of std s sqrt(binomial(2k, k)); a higher order suppresses a
    smooth signal better at coarse sample times.

    :param x: the samples.
    :param order: difference order k >= 1 (default 2).
    """
    from math import comb

    if int(order) != order or order < 1:
        raise ValueError(f"order must be a positive integer, got {order!r}")
    dk = np.diff(np.asarray(x, dtype=float), int(order))
    if dk.size < 3:
        return float("nan")
    mad = np.median(np.abs(dk - np.median(dk)))
    return float(1.4826 * mad / np.sqrt(comb(2 * int(order), int(order))))


def _prepare(log: QuarterCarLog, p: qc.QuarterCarParams, cfg: DiagnoseConfig) -> Data:
    n = len(log)
    H = cfg.horizon
    if n < 3 * H:
        raise ValueError(f"{log.source}: log too short for diagnosis: {n} samples, need at least {3 * H} "
                         f"(3 prediction windows of {H} samples)")
    sigma = {"omega": max(estimate_noise(log.omega), NOISE_FLOOR["omega"])}
    if log.v is not None:
        sigma["v"] = max(estimate_noise(log.v), NOISE_FLOOR["v"])
    if log.a_x is not None:
        sigma["a_x"] = max(estimate_noise(log.a_x), NOISE_FLOOR["a_x"])
    v_smooth = None
    if log.v is not None:
        win = min(SAVGOL[0], n - (1 - n % 2))
        v_smooth = savgol_filter(log.v, win, SAVGOL[1])
    T = np.asarray(log.T_b, dtype=float)
    tmax = max(float(np.max(np.abs(T))), 1e-9)
    braking = np.flatnonzero(np.abs(T) > FREE_ROLL_TORQUE * tmax)
    free_end = int(braking[0]) if braking.size else n
    starts = np.arange(0, n - H + 1, H)
    if int(cfg.folds) != cfg.folds or cfg.folds < 2:
        raise ValueError(f"DiagnoseConfig.folds must be an integer >= 2, got {cfg.folds!r}")
    fold = np.arange(len(starts)) % int(cfg.folds)
    test = fold == 0
    return Data(t0=float(log.t[0]), dt=log.dt, Tb=T, omega=np.asarray(log.omega, dtype=float),
                v=None if log.v is None else np.asarray(log.v, dtype=float),
                a_x=None if log.a_x is None else np.asarray(log.a_x, dtype=float), sigma=sigma, v_smooth=v_smooth,
                starts=starts, fold=fold, test=test, horizon=H, free_end=free_end, p=p, substeps=cfg.substeps)


# --------------------------------------------------------------------------------------------- models
def _param_names(effects: Sequence[str]) -> tuple[str, ...]:
    names = list(ROAD_NAMES)
    for e in effects:
        names += list(EFFECT_PARAMS[e])
    return tuple(names)


def _batch(effects: Sequence[str], names: Sequence[str], X: np.ndarray, p: qc.QuarterCarParams) -> ModelBatch:
    """A ModelBatch of K elements from a (K, len(names)) parameter matrix."""
    X = np.atleast_2d(X)
    col = {name: X[:, i] for i, name in enumerate(names)}
    road = np.column_stack([col[k] for k in ROAD_NAMES])
    b = ModelBatch.nominal(road, X.shape[0], p)
    upd = {}
    for e in effects:
        for pname in EFFECT_PARAMS[e]:
            upd[pname] = col[pname].copy()
    return replace(b, **upd)


def _speed_states(batch: ModelBatch, d: Data) -> np.ndarray:
    """Speed estimate (K, n) used to start the windows."""
    if d.v_smooth is not None:
        return np.broadcast_to(d.v_smooth, (len(batch), d.n))
    return reconstruct_speed(batch, d.omega, d.t0, d.dt, d.free_end, d.p)


def _effect_states(batch: ModelBatch, d: Data, vhat: np.ndarray):
    """Lag-filter output and transient slip (K, n) estimated from the command log and the measured slip."""
    Ta = None
    if np.any(batch.tau > 0):
        sim = EffectSimulator(batch, d.dt, d.n, d.p, d.substeps, d.t0, commands=d.Tb)
        sim.reset(vhat[:, 0], d.omega[0], k0=0, Ta=d.Tb[0])
        Ta = sim.actuator_run(d.n)
    lt = None
    if RELAX_STATE_FROM_FILTER and np.any(batch.sigma > 0):
        lam = longitudinal_slip(vhat, d.omega[None, :], batch.r_eff[:, None])
        sig = np.where(batch.sigma > 0, batch.sigma, 1.0)
        lt = filtered_transient_slip(lam, vhat, d.dt / sig[:, None])
    return Ta, lt


def _simulate_windows(batch: ModelBatch, d: Data, widx: np.ndarray, v0, w0, Ta0, lt0, reps: int):
    """Simulate the windows ``widx`` for every element of ``batch`` and ``reps`` wheel-speed starts each.

    v0, w0, Ta0, lt0 have shape (K, W, reps) (Ta0, lt0 may be None). Returns dict channel -> (K, W, reps, H).
    """
    K, W, H = len(batch), len(widx), d.horizon
    full = batch.repeat(W * reps)
    sim = EffectSimulator(full, d.dt, d.n, d.p, d.substeps, d.t0, commands=d.Tb)
    k0 = np.tile(np.repeat(d.starts[widx], reps), K)
    sim.reset(v0.ravel(), w0.ravel(), k0=k0, Ta=None if Ta0 is None else Ta0.ravel(),
              lam_t=None if lt0 is None else lt0.ravel())
    out = {"omega": np.empty((K * W * reps, H))}
    if d.v is not None:
        out["v"] = np.empty_like(out["omega"])
    if d.a_x is not None:
        out["a_x"] = np.empty_like(out["omega"])
    for j in range(H):
        out["omega"][:, j] = sim.omega
        if "v" in out:
            out["v"][:, j] = sim.v
        if "a_x" in out:
            out["a_x"][:, j] = sim.accel()
        if j < H - 1:
            sim.step()
    return {k: v.reshape(K, W, reps, H) for k, v in out.items()}


def _measured(d: Data, widx: np.ndarray) -> dict:
    rows = d.starts[widx][:, None] + np.arange(d.horizon)[None, :]
    out = {"omega": d.omega[rows]}
    if d.v is not None:
        out["v"] = d.v[rows]
    if d.a_x is not None:
        out["a_x"] = d.a_x[rows]
    return out


def _normalised(pred: dict, meas: dict, d: Data) -> np.ndarray:
    """Residuals (..., M): all channels concatenated, each divided by its noise std."""
    parts = [(pred[c] - meas[c]) / d.sigma[c] for c in d.channels]
    return np.concatenate(parts, axis=-1)


def window_nuisances(effects: Sequence[str], d: Data) -> int:
    """Number of states fitted per window on that window's own samples: the wheel speed, the speed when ``v`` is
    logged, and the transient slip of a relaxation model. Each lowers a model's error on the window by about one
    noise variance even where it explains nothing, so tests between models subtract the difference."""
    return 1 + (d.v is not None) + ("relaxation_length" in effects and RELAX_STATE_FITTED)


def window_residuals(effects: Sequence[str], names: Sequence[str], X: np.ndarray, d: Data,
                     widx: np.ndarray | None = None, per_channel: bool = False):
    """Normalised residuals (K, W, M) of K parameter sets on windows ``widx``, wheel-speed nuisance fitted.

    :param per_channel: also return the per-channel residual blocks, dict channel -> (K, W, H).
    """
    X = np.atleast_2d(X)
    widx = np.arange(len(d.starts)) if widx is None else np.asarray(widx)
    batch = _batch(effects, names, X, d.p)
    K, W = X.shape[0], len(widx)
    vhat = _speed_states(batch, d)
    Ta, lt = _effect_states(batch, d, vhat)
    s = d.starts[widx]
    meas = _measured(d, widx)
    # nuisance states of each window, fitted by Gauss-Newton: omega0 always, v0 if v is logged, the transient slip
    # if the model has tire relaxation
    state = {"omega": np.broadcast_to(d.omega[s][None, :], (K, W)).copy(), "v": vhat[:, s].copy()}
    relax = bool(np.any(batch.sigma > 0))
    if relax:
        state["lam_t"] = lt[:, s].copy() if lt is not None else \
            longitudinal_slip(state["v"], state["omega"], batch.r_eff[:, None])
    free = ["omega"] + (["v"] if d.v is not None else []) + (["lam_t"] if relax and RELAX_STATE_FITTED else [])
    steps = {"omega": OMEGA0_STEP, "v": V0_STEP, "lam_t": LAMT_STEP}
    max_move = {"omega": OMEGA0_MAX_MOVE * d.sigma["omega"], "v": OMEGA0_MAX_MOVE * d.sigma.get("v", 1.0),
                "lam_t": LAMT_MAX_MOVE}
    lower = {"omega": 0.0, "v": 0.0, "lam_t": -1.0}
    upper = {"omega": np.inf, "v": np.inf, "lam_t": 1.0}
    reps = 1 + len(free)
    Ta0 = None if Ta is None else np.repeat(Ta[:, s][:, :, None], reps, axis=2)
    meas_b = {c: m[None, :, None, :] for c, m in meas.items()}

    def replicas(name):
        x = np.repeat(state[name][:, :, None], reps, axis=2)
        if name in free:
            x[:, :, 1 + free.index(name)] += steps[name]
        return x

    for _ in range(GN_ITERS):
        pred = _simulate_windows(batch, d, widx, replicas("v"), replicas("omega"), Ta0,
                                 replicas("lam_t") if relax else None, reps)
        r = _normalised(pred, meas_b, d)  # (K, W, reps, M)
        J = np.stack([(r[:, :, 1 + i] - r[:, :, 0]) / steps[n] for i, n in enumerate(free)], axis=-1)  # (K,W,M,q)
        A = np.einsum("kwmi,kwmj->kwij", J, J) + 1e-9 * np.eye(len(free))
        g = -np.einsum("kwmi,kwm->kwi", J, r[:, :, 0])
        try:
            move = np.linalg.solve(A, g[..., None])[..., 0]
        except np.linalg.LinAlgError:
            move = np.zeros_like(g)
        move = np.nan_to_num(move)
        for i, n in enumerate(free):
            state[n] = np.clip(state[n] + np.clip(move[..., i], -max_move[n], max_move[n]), lower[n], upper[n])
    pred = _simulate_windows(batch, d, widx, state["v"][:, :, None], state["omega"][:, :, None],
                             None if Ta0 is None else Ta0[:, :, :1],
                             state["lam_t"][:, :, None] if relax else None, 1)
    pred = {c: x[:, :, 0] for c, x in pred.items()}
    r = _normalised(pred, {c: m[None] for c, m in meas.items()}, d)
    if per_channel:
        return r, {c: (pred[c] - meas[c][None]) / d.sigma[c] for c in d.channels}
    return r


# --------------------------------------------------------------------------------------------- fitting
def _bounds(names: Sequence[str], d: Data):
    lo, hi = [], []
    for n in names:
        b = ROAD_BOUNDS.get(n) or EFFECT_BOUNDS[n]
        if n == "t_change":  # at least one training window on either side
            train = d.starts[~d.test]
            b = (d.t0 + d.dt * (train[0] + d.horizon), d.t0 + d.dt * train[-1])
        lo.append(b[0])
        hi.append(b[1])
    return np.array(lo), np.array(hi)


def _fit_loss(r: np.ndarray, loss: str) -> np.ndarray:
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


def _distinct_starts(starts: np.ndarray, cost: np.ndarray, k: int) -> list[np.ndarray]:
    """The ``k`` best of ``starts`` by ``cost`` whose road parts (B, C, E, theta) differ: a fit started from the
    nominal model's road can stay in that road's basin, so the further starts come from other road shapes."""
    chosen: list[np.ndarray] = []
    for i in np.argsort(cost, kind="stable"):
        if not np.isfinite(cost[i]) or len(chosen) == k:
            break
        if all(not np.allclose(starts[i, :4], c[:4]) for c in chosen):
            chosen.append(starts[i].copy())
    return chosen or [starts[0].copy()]


def _fit(effects: Sequence[str], names: Sequence[str], starts: np.ndarray, d: Data, cfg: DiagnoseConfig,
         fixed: dict | None = None, runs: int = 1) -> np.ndarray:
    """Least squares on the training windows from the best ``runs`` of ``starts`` (K, len(names)) with distinct
    roads; the lowest final loss wins. ``fixed`` params are held."""
    train = np.flatnonzero(~d.test)
    lo, hi = _bounds(names, d)
    starts = np.clip(np.atleast_2d(starts), lo, hi)
    fixed = fixed or {}
    for k, v in fixed.items():
        starts[:, names.index(k)] = v
    r = window_residuals(effects, names, starts, d, train)
    cost = np.sum(_fit_loss(r.reshape(len(starts), -1), cfg.fit_loss), axis=1)
    cost = np.where(np.isfinite(cost), cost, np.inf)
    fidx = np.flatnonzero([n not in fixed for n in names])
    if fidx.size == 0:
        return starts[int(np.argmin(cost))].copy()
    results = [_least_squares(effects, names, x0, fidx, lo, hi, train, d, cfg)
               for x0 in _distinct_starts(starts, cost, runs)]
    return min(results, key=lambda res: res[1])[0]


def _least_squares(effects: Sequence[str], names: Sequence[str], x0: np.ndarray, fidx: np.ndarray, lo, hi,
                   train: np.ndarray, d: Data, cfg: DiagnoseConfig) -> tuple[np.ndarray, float]:
    """One trust-region least-squares run from ``x0`` over the parameters ``fidx``: (solution, final loss)."""
    steps = np.array([FD_STEP[names[i]] for i in fidx])
    cache: dict = {}

    def full(z):
        x = x0.copy()
        x[fidx] = z
        return x

    def evaluate(Z):
        R = window_residuals(effects, names, np.array([full(z) for z in Z]), d, train).reshape(len(Z), -1)
        return np.where(np.isfinite(R), R, 1e3)

    def fun(z):
        key = z.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = evaluate([z])[0]
        return cache[key]

    def jac(z):
        # forward differences, stepping inwards at an upper bound; all perturbations in one batch
        h = np.where(z + steps > hi[fidx], -steps, steps)
        Z = [z] + [z + h[i] * np.eye(len(z))[i] for i in range(len(z))]
        R = evaluate(Z)
        cache.clear()
        cache[z.tobytes()] = R[0]
        return ((R[1:] - R[0]) / h[:, None]).T

    z0 = np.clip(x0[fidx], lo[fidx] + 1e-12, hi[fidx] - 1e-12)
    sol = least_squares(fun, z0, jac=jac, bounds=(lo[fidx], hi[fidx]),
                        x_scale=np.array([X_SCALE[names[i]] for i in fidx]), max_nfev=cfg.max_nfev, method="trf",
                        loss=cfg.fit_loss, f_scale=FIT_LOSS_SCALE)
    return full(sol.x), float(sol.cost)


def _score(effect: str, effects: Sequence[str], names, x, d: Data, seconds: float) -> CandidateFit:
    r = window_residuals(effects, names, x, d)[0]
    wm = np.minimum(np.mean(r**2, axis=-1), WINDOW_MSE_CAP)
    return CandidateFit(effect=effect, names=tuple(names), x=np.asarray(x, dtype=float),
                        train_mse=float(np.mean(wm[~d.test])), test_mse=float(np.mean(wm[d.test])), window_mse=wm,
                        seconds=seconds, resid=r, nuisances=window_nuisances(effects, d),
                        samples=d.horizon * len(d.channels))


def _road_starts(d: Data) -> np.ndarray:
    return np.array([ROADS[k].as_array() for k in ROADS])


def fit_nominal(d: Data, cfg: DiagnoseConfig) -> CandidateFit:
    """Calibrate the nominal model's road on the training windows."""
    t = time.perf_counter()
    names = _param_names([])
    x = _fit([], names, _road_starts(d), d, cfg)
    return _score("nominal", [], names, x, d, time.perf_counter() - t)


def _mu_change_starts(road: np.ndarray, d: Data, k: int) -> list[np.ndarray]:
    """Starts of the mu_change fit by a change-point search, from the ``k`` best road shapes; t_change only moves the
    windows it falls in, so it is searched, not differentiated.

    Every training window is scored at a grid of theta values, for the nominal fit's road shape (B, C, E) and for
    each preset's (the nominal fit's shape has absorbed part of the change, so it can be far from the true one); the
    best split into a before and an after theta (exact over the grid, by cumulative sums) locates the change between
    two training windows for each shape; the switching time is then refined at single-sample resolution over that
    stretch for the ``k`` shapes whose best split costs least.
    """
    train = np.flatnonzero(~d.test)
    names = _param_names([])
    lo_t, hi_t = ROAD_BOUNDS["theta"]
    thetas = np.clip(road[3] * MU_CHANGE_FACTORS, lo_t, hi_t)
    shapes = np.vstack([road[None], _road_starts(d)])
    X = np.repeat(shapes, len(thetas), axis=0)
    X[:, 3] = np.tile(thetas, len(shapes))
    r = window_residuals([], names, X, d, train)
    c = np.sum(np.minimum(r**2, FIT_LOSS_SCALE**2 * 4), axis=-1)  # (S F, Wtrain), outliers bounded
    c = np.where(np.isfinite(c), c, np.inf).reshape(len(shapes), len(thetas), -1)
    cum = np.cumsum(c, axis=2)  # (S, F, Wtrain)
    before = cum[:, :, :-1].min(axis=1)  # (S, splits): best theta before each split
    after = (cum[:, :, -1:] - cum[:, :, :-1]).min(axis=1)
    total = before + after
    best_split = np.argmin(total, axis=1)
    ranked = np.argsort(total[np.arange(len(shapes)), best_split])
    return [_refine_change_time(shapes[s], thetas, cum[s], int(best_split[s]) + 1, d) for s in ranked[:k]]


def _refine_change_time(shape: np.ndarray, thetas: np.ndarray, cum: np.ndarray, split: int, d: Data) -> np.ndarray:
    """The mu_change start for one road shape: its best thetas before and after training window ``split`` (cum:
    (F, Wtrain) cumulative window costs over the theta grid), and the switching time searched sample by sample
    between the two windows around the split."""
    train = np.flatnonzero(~d.test)
    i = int(np.argmin(cum[:, split - 1]))
    j = int(np.argmin(cum[:, -1] - cum[:, split - 1]))
    mnames = _param_names(["mu_change"])
    lo, hi = _bounds(mnames, d)
    t_lo = d.t0 + d.dt * (d.starts[train[split - 1]] + d.horizon // 2)
    t_hi = d.t0 + d.dt * (d.starts[train[split]] + d.horizon // 2)
    fine_t = np.clip(np.arange(t_lo, t_hi + 1e-9, d.dt), lo[4], hi[4])
    base = shape.copy()
    base[3] = thetas[i]
    fine = np.array([np.concatenate([base, [tc, thetas[j]]]) for tc in fine_t])
    r = window_residuals(["mu_change"], mnames, fine, d, train)
    cost = np.sum(np.minimum(r.reshape(len(fine), -1) ** 2, FIT_LOSS_SCALE**2 * 4), axis=1)
    return fine[int(np.argmin(np.where(np.isfinite(cost), cost, np.inf)))]


def _effect_start_matrix(effects: Sequence[str], road: np.ndarray, d: Data, seeds: dict | None = None) -> np.ndarray:
    """Starting points (K, 4 + q) for the effects' fit: the product of the roads (the nominal fit's and the presets)
    and each effect's start list. The nominal road has absorbed part of the effect, so it is not always the best
    start."""
    rows = [road.copy()] + [r for r in _road_starts(d)]
    for e in effects:
        if seeds and e in seeds:
            opts = [seeds[e]]
        elif e == "radius_error":
            opts = [{"r_eff": f["r_eff"] * d.p.r} for f in EFFECT_STARTS[e]]
            if d.v_smooth is not None and d.free_end >= 3:
                m = min(d.free_end, 50)
                ratio = np.median(d.v_smooth[:m] / np.maximum(d.omega[:m], 1e-6))
                if np.isfinite(ratio):
                    opts.append({"r_eff": float(ratio)})
        else:
            opts = EFFECT_STARTS[e]
        rows = [np.concatenate([r, [o[k] for k in EFFECT_PARAMS[e]]]) for r in rows for o in opts]
    return np.array(rows)


def _fit_mu_change(start: np.ndarray, d: Data, cfg: DiagnoseConfig) -> np.ndarray:
    """Least squares of the mu_change model from ``start`` with the switching time held, then one alternation:
    re-search the switching time with the fitted road, and refit the rest if it moved."""
    effects, names = ["mu_change"], _param_names(["mu_change"])
    x = _fit(effects, names, start[None], d, cfg, fixed={"t_change": float(start[4])})
    lo, hi = _bounds(names, d)
    fine_t = np.clip(x[4] + d.dt * np.arange(-d.horizon * 3 // 2, d.horizon * 3 // 2 + 1), lo[4], hi[4])
    fine = np.repeat(x[None], len(fine_t), axis=0)
    fine[:, 4] = fine_t
    r = window_residuals(effects, names, fine, d, np.flatnonzero(~d.test))
    cost = np.sum(r.reshape(len(fine), -1) ** 2, axis=1)
    best = fine[int(np.argmin(np.where(np.isfinite(cost), cost, np.inf)))]
    if best[4] != x[4]:
        x = _fit(effects, names, best[None], d, cfg, fixed={"t_change": float(best[4])})
    return x


def fit_candidate(effects: Sequence[str], road: np.ndarray, d: Data, cfg: DiagnoseConfig,
                  seeds: dict | None = None) -> CandidateFit:
    """Fit road + the effects' parameters on the training windows; score on all windows."""
    t = time.perf_counter()
    effects = list(effects)
    names = _param_names(effects)
    if effects == ["mu_change"]:
        train = np.flatnonzero(~d.test)
        xs = [_fit_mu_change(start, d, cfg) for start in _mu_change_starts(road, d, int(cfg.fit_starts))]
        r = window_residuals(effects, names, np.array(xs), d, train)
        cost = np.sum(_fit_loss(r.reshape(len(xs), -1), cfg.fit_loss), axis=1)
        x = xs[int(np.argmin(np.where(np.isfinite(cost), cost, np.inf)))]
    else:
        x = _fit(effects, names, _effect_start_matrix(effects, road, d, seeds), d, cfg, runs=int(cfg.fit_starts))
    return _score("+".join(effects), effects, names, x, d, time.perf_counter() - t)


def _fit_worker(job):
    """``(fn, args)`` -> ``fn(*args)`` in a worker process, the fits' RuntimeWarnings silenced."""
    fn, args = job
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return fn(*args)


def _map_fits(fn, tasks: list, jobs: int) -> list:
    """``[fn(*t) for t in tasks]``, in worker processes when there are several; results in task order."""
    if jobs > 1 and len(tasks) > 1:
        with ProcessPoolExecutor(max_workers=min(jobs, len(tasks))) as pool:
            return list(pool.map(_fit_worker, [(fn, t) for t in tasks]))
    return [_fit_worker((fn, t)) for t in tasks]


# --------------------------------------------------------------------------------------------- scoring, verdict
def gap_of(mse: float) -> float:
    """Model part of a mean squared normalised residual, in noise units: sqrt(max(mse - 1, 0))."""
    return float(np.sqrt(max(mse - 1.0, 0.0)))


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


def _refine_noise(nominal: CandidateFit, d: Data) -> None:
    """Noise level per channel: the smaller of the difference-based estimate and the calibrated nominal model's
    training residual (corrected for the fitted wheel-speed nuisance). Both over-estimate (the first by the signal's
    own curvature, the second by any model error), so the smaller is the better estimate."""
    train = np.flatnonzero(~d.test)
    _, r_ch = window_residuals([], nominal.names, nominal.x, d, train, per_channel=True)
    for c in d.channels:
        rms = float(np.sqrt(np.mean(r_ch[c][0] ** 2))) * d.sigma[c]
        if c == "omega" or c == "v":  # one fitted nuisance state per window in this channel
            rms *= np.sqrt(d.horizon / (d.horizon - 1.0))
        d.sigma[c] = max(min(d.sigma[c], rms), NOISE_FLOOR[c])


def _window_gain(base: CandidateFit, cand: CandidateFit, m: int) -> np.ndarray:
    """Per-window held-out gain of the sum of squared normalised residuals (``m`` samples per window), less what
    ``cand``'s extra per-window nuisance states win on pure noise (one noise variance each)."""
    return (base.window_mse - cand.window_mse) * m - (cand.nuisances - base.nuisances)


def improvement_z(base: CandidateFit, cand: CandidateFit, d: Data) -> float:
    """Held-out improvement of the sum of squared normalised residuals (less the nuisance discount of
    :func:`_window_gain`), without its single largest window, in units of that sum's standard deviation under pure
    noise (sqrt(2 n)); one lucky window cannot make it large."""
    m = d.horizon * len(d.channels)
    gain = _window_gain(base, cand, m)
    if gain.size == 0:
        return 0.0
    robust = float(np.sum(gain) - max(float(np.max(gain)), 0.0))
    return robust / np.sqrt(2.0 * gain.size * m)


def paired_z(base: CandidateFit, cand: CandidateFit, d: Data) -> float:
    """Held-out improvement of ``cand`` over ``base`` in units of its spread under the measurement noise.

    With normalised residuals ``r_b = e + a`` and ``r_c = e + b`` (``e`` unit white noise, ``a``, ``b`` the models'
    errors), the per-sample gain ``r_b^2 - r_c^2 = a^2 - b^2 + 2 e (a - b)`` has noise spread ``2 |a - b|``, and
    ``a - b = r_b - r_c`` is the difference of the two predictions, known exactly. The statistic is the held-out gain
    over ``2 ||r_b - r_c||``: a z score that is large when the data prefer the candidate however few windows carry the
    difference, and about ``-||a - b|| / 2 + N(0, 1)`` when the base model is right. Per window the gain and the
    squared difference are capped (``WINDOW_MSE_CAP``), the window of largest gain is left out, as in
    :func:`improvement_z`, and the gain is less what ``cand``'s extra per-window nuisance states win on pure noise
    (:func:`_window_gain`).
    """
    if base.resid is None or cand.resid is None:
        return 0.0
    m = d.horizon * len(d.channels)
    gain = _window_gain(base, cand, m)
    diff2 = np.minimum(np.sum((base.resid - cand.resid) ** 2, axis=-1), m * WINDOW_MSE_CAP)
    if gain.size < 2:
        return 0.0
    drop = int(np.argmax(gain))
    keep = np.arange(gain.size) != drop
    spread = 2.0 * np.sqrt(float(np.sum(diff2[keep])))
    return float(np.sum(gain[keep]) / spread) if spread > 0 else 0.0


def _significant(f: CandidateFit, nominal: CandidateFit, cfg: DiagnoseConfig) -> bool:
    """A held-out improvement well beyond what the measurement noise could make (:func:`paired_z`); the robust
    :func:`improvement_z` and the paired t statistic are reported, not required."""
    return f.z_paired > cfg.sig_z and f.adjusted_mse < nominal.adjusted_mse


def robust_gap(f: CandidateFit) -> float:
    """Held-out gap with the worst ``TRIM_SHARE`` of the windows left out: a wheel lock-up that starts a few
    milliseconds earlier or later than any model predicts costs a window its whole error whatever the model, so the
    share of the gap a candidate closes is judged without those few windows."""
    wm = np.sort(f.window_mse)
    keep = wm.size - int(np.ceil(TRIM_SHARE * wm.size))
    return gap_of(float(np.mean(wm[:max(keep, 1)])))


def at_range_edge(f: CandidateFit, p: qc.QuarterCarParams) -> list[str]:
    """Effect parameters of ``f`` that sit at a bound of their physical range (EFFECT_BOUNDS) in any fold's fit.

    The bound on the side where the effect switches off (a lag of 1 ms, no drag) does not count: there the effect
    is simply absent. A parameter pressed against the far bound (a 3 m relaxation length) means the effect is being
    stretched to imitate something it is not, so such a candidate cannot be the verdict.
    """
    off = ModelBatch.nominal(f.x[:len(ROAD_NAMES)], 1, p)
    out = []
    for i, name in enumerate(f.names):
        lo, hi = EFFECT_BOUNDS.get(name, (-np.inf, np.inf))
        if not (np.isfinite(lo) and np.isfinite(hi)):
            continue
        tol = RANGE_EDGE * (hi - lo)
        off_value = float(getattr(off, name)[0])
        edges = [b for b, off_side in ((lo, off_value <= lo + tol), (hi, off_value >= hi - tol)) if not off_side]
        if any(abs(x[i] - b) <= tol for x in (f.x_folds or (f.x,)) for b in edges):
            out.append(name)
    return out


def gap_is_real(nominal: CandidateFit, significant: Sequence[CandidateFit], cfg: DiagnoseConfig) -> bool:
    """Whether the nominal model misses by more than the noise.

    True when its held-out gap is above ``gap_none`` beyond the few lock-up windows that no model times (the trim
    of :func:`robust_gap`, the same that judges the candidates), or when a candidate beats it significantly on data
    it was not fitted to (then the nominal model cannot be within the noise either).
    """
    misses = nominal.gap > cfg.gap_none and robust_gap(nominal) > cfg.gap_within_noise
    return misses or bool(significant)


def _fold_data(d: Data, j: int) -> Data:
    """The data with fold ``j`` held out and the other folds as training windows."""
    return replace(d, test=d.fold == j)


def _cross_fitted(fits: Sequence[CandidateFit], d: Data) -> CandidateFit:
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


def _effects_of(model: CandidateFit) -> list[str]:
    return model.effect.split("+") if model.effect != "nominal" else []


def _fixed_of(model: CandidateFit) -> dict | None:
    """``mu_change`` keeps its switching time in refits: it only moves the windows it falls in, so it is searched,
    not fitted by least squares."""
    return {"t_change": float(model.x[model.names.index("t_change")])} if "t_change" in model.names else None


def fit_time_split(model: CandidateFit, d: Data, cfg: DiagnoseConfig, jobs: int = 1) -> CandidateFit:
    """``model`` refitted separately on the early and on the late half of the log's windows, each half cross-fitted
    within itself (a window is predicted by the fit of its own half that did not see it).

    A library effect that is the right model has constant parameters, so letting them change once at mid-log cannot
    improve the held-out error beyond the noise; an effect outside the library that the nearest library effect only
    imitates (brake fade looks like a brake gain that drifts down) is caught by this test.

    :return: the split model; ``x_folds`` holds its fits, early half first, ``folds`` per half.
    """
    t = time.perf_counter()
    effects = _effects_of(model)
    late = np.arange(len(d.starts)) >= len(d.starts) // 2
    starts = np.vstack([model.x[None]] + [x[None] for x in model.x_folds])
    halves = [(half, j) for half in (~late, late) for j in range(int(cfg.folds))]
    xs = _map_fits(_fit, [(effects, model.names, starts, replace(d, test=~(half & (d.fold != j))), cfg,
                           _fixed_of(model)) for half, j in halves], jobs)
    resid = np.empty_like(model.resid)
    for x, (half, j) in zip(xs, halves):  # every window is held out in exactly one (half, fold)
        held = half & (d.fold == j)
        resid[held] = window_residuals(effects, model.names, x, d, np.flatnonzero(held))[0]
    wm = np.minimum(np.mean(resid**2, axis=-1), WINDOW_MSE_CAP)
    return CandidateFit(effect=f"{model.effect} (early/late)", names=model.names, x=np.mean(xs, axis=0),
                        train_mse=float("nan"), test_mse=float(np.mean(wm)), window_mse=wm,
                        gap=gap_of(float(np.mean(wm))), seconds=time.perf_counter() - t, resid=resid,
                        x_folds=tuple(xs), nuisances=model.nuisances, samples=model.samples)


def _refit_from(model: CandidateFit, extra_starts: Sequence[np.ndarray], d: Data, cfg: DiagnoseConfig,
                jobs: int) -> CandidateFit:
    """``model`` refitted per fold from its own fits and ``extra_starts``: the split fits sometimes find a better
    optimum of the constant model, which must not be mistaken for a drift."""
    effects = _effects_of(model)
    folds = [_fold_data(d, j) for j in range(int(cfg.folds))]
    xs = _map_fits(_fit, [(effects, model.names, np.vstack([xj[None]] + [x[None] for x in extra_starts]), f, cfg,
                           _fixed_of(model)) for xj, f in zip(model.x_folds, folds)], jobs)
    fits = [_score(model.effect, effects, model.names, x, f, model.seconds / len(folds)) for x, f in zip(xs, folds)]
    return _cross_fitted(fits, d)


def drift_test(model: CandidateFit, d: Data, cfg: DiagnoseConfig, jobs: int = 1) -> tuple[dict, CandidateFit]:
    """Whether ``model``'s parameters drift over the log: :func:`fit_time_split` beats it significantly
    (:func:`paired_z` above ``cfg.drift_z``) and closes a clear share of the robust gap the constant model leaves,
    when that gap is above the noise (``gap_within_noise``). Both conditions: the paired test alone is dominated by
    the few windows whose lock-up timing no model predicts, which a split fit can hit by chance.

    :return: (the test's figures with the early and late fits, ``model`` refitted from the split fits as well).
    """
    split = fit_time_split(model, d, cfg, jobs)
    refit = _refit_from(model, split.x_folds, d, cfg, jobs)
    if refit.train_mse >= model.train_mse:
        refit = model
    k = int(cfg.folds)
    z = paired_z(refit, split, d)

    def params(xs):
        return {n: float(np.mean([x[i] for x in xs])) for i, n in enumerate(model.names) if n not in ROAD_NAMES}

    info = {"model": model.effect, "z_paired": z, "robust_gap": robust_gap(refit),
            "robust_gap_split": robust_gap(split), "params_early": params(split.x_folds[:k]),
            "params_late": params(split.x_folds[k:]), "seconds": split.seconds,
            "drifts": bool(z > cfg.drift_z and robust_gap(refit) > cfg.gap_within_noise
                           and robust_gap(split) <= DRIFT_SHARE * robust_gap(refit))}
    return info, refit


def _fit_cost(effects: Sequence[str], d: Data) -> int:
    """Relative cost of a candidate fit: each evaluation simulates (fitted parameters + 1) parameter sets, each with
    one replica per fitted window state (``mu_change`` holds its switching time during the least squares)."""
    fitted = len(ROAD_NAMES) + sum(len(EFFECT_PARAMS[e]) for e in effects) - (list(effects) == ["mu_change"])
    return (fitted + 1) * (1 + window_nuisances(effects, d))


def _run_fits(tasks: list, jobs: int) -> list:
    """Candidate fits (:func:`fit_candidate` argument tuples), in worker processes when there are several; the
    longest fits go first, which keeps the workers busy."""
    order = sorted(range(len(tasks)), key=lambda i: -_fit_cost(tasks[i][0], tasks[i][2]))
    done = dict(zip(order, _map_fits(fit_candidate, [tasks[i] for i in order], jobs)))
    return [done[i] for i in range(len(tasks))]


def _nested_nominal(nominal: CandidateFit, fits: Sequence[CandidateFit], d: Data, cfg: DiagnoseConfig) \
        -> CandidateFit:
    """The nominal fit, refitted from the candidates' roads when one of them fits the training windows better.

    The nominal model is every candidate with its effect switched off, so its best road is at least as good as any
    candidate's road; a candidate whose multi-start found a better road optimum than the nominal fit would
    otherwise look like an effect (a ``brake_gain`` of 1.000 beating the nominal model).
    """
    starts = np.vstack([nominal.x[None]] + [f.x[None, :4] for f in fits])
    x = _fit([], nominal.names, starts, d, cfg)
    better = _score("nominal", [], nominal.names, x, d, nominal.seconds)
    return better if better.train_mse < nominal.train_mse else nominal


def _test_against(nominal: CandidateFit, f: CandidateFit, d: Data) -> None:
    f.t_stat = paired_t(nominal, f, d)
    f.z = improvement_z(nominal, f, d)
    f.z_paired = paired_z(nominal, f, d)


def _jobs(cfg: DiagnoseConfig) -> int:
    if cfg.jobs is not None:
        return max(int(cfg.jobs), 1)
    try:
        avail = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - non-Linux
        avail = os.cpu_count() or 1
    return max(min(2, avail), 1)


def _by_channel(resid: np.ndarray, d: Data) -> dict:
    """Split (windows, samples) residuals into their channel blocks, dict channel -> (windows, horizon)."""
    return {c: resid[:, i * d.horizon:(i + 1) * d.horizon] for i, c in enumerate(d.channels)}


def _regimes(nominal: CandidateFit, d: Data, r_ch: dict, r_after: dict | None = None) -> dict:
    """Residual by regime (slip vs the fitted peak, apply/hold/release, speed band) and by channel, on all windows:
    the nominal model's (``gap``) and, if given, the verdict model's (``gap_after``)."""
    rows = d.starts[:, None] + np.arange(d.horizon)[None, :]
    vhat = _speed_states(_batch([], nominal.names, nominal.x, d.p), d)[0]
    road = MagicFormula(*nominal.x[:4])
    lam = longitudinal_slip(vhat, d.omega, d.p.r)
    lam_s = savgol_filter(lam, min(5, d.n - (1 - d.n % 2)), 1)
    dT = np.gradient(d.Tb, d.dt)
    tmax = max(float(np.max(np.abs(d.Tb))), 1e-9)
    labels = {
        "slip_below_peak": lam_s < road.peak_slip,
        "slip_above_peak": lam_s >= road.peak_slip,
        "apply": dT > APPLY_RATE * tmax,
        "release": dT < -APPLY_RATE * tmax,
        "hold": np.abs(dT) <= APPLY_RATE * tmax,
        f"speed_below_{SPEED_BANDS[0]:g}": vhat < SPEED_BANDS[0],
        f"speed_{SPEED_BANDS[0]:g}_to_{SPEED_BANDS[1]:g}": (vhat >= SPEED_BANDS[0]) & (vhat < SPEED_BANDS[1]),
        f"speed_above_{SPEED_BANDS[1]:g}": vhat >= SPEED_BANDS[1],
    }
    sq = sum(r_ch[c] ** 2 for c in d.channels) / len(d.channels)  # (W, H)
    sq_after = None if r_after is None else sum(r_after[c] ** 2 for c in d.channels) / len(d.channels)
    regimes = {}
    for name, mask in labels.items():
        m = mask[rows]
        n = int(np.count_nonzero(m))
        regimes[name] = {"gap": gap_of(float(np.mean(sq[m]))) if n else None, "samples": n}
        if sq_after is not None:
            regimes[name]["gap_after"] = gap_of(float(np.mean(sq_after[m]))) if n else None
    channels = {}
    for c in d.channels:
        channels[c] = {"gap": gap_of(float(np.mean(r_ch[c] ** 2))), "noise_std": d.sigma[c]}
        if r_after is not None:
            channels[c]["gap_after"] = gap_of(float(np.mean(r_after[c] ** 2)))
    return {"regimes": regimes, "channels": channels, "peak_slip": road.peak_slip, "labels": labels}


def decide_verdict(significant: list, fits: list, explains, joint_wins: bool, gap_is_real: bool) \
        -> tuple[str, object, list]:
    """The verdict rule shared by every plant's diagnosis (DESIGN.md: none / an effect / unexplained).

    The best significant candidate is the verdict if it explains the gap, or if fitting it together with the
    second one does (two effects at once: the larger is the verdict, the other follows in candidates). A real gap
    that no candidate explains is ``unexplained``; otherwise ``none``.

    :param significant: the significant candidates, best first.
    :param fits: all candidates, best first.
    :param explains: ``fit -> bool``, whether a fit closes a clear share of the gap on held-out data.
    :param joint_wins: whether the joint fit of the two best is significant, explains, and beats the best alone.
    :param gap_is_real: whether the nominal model does not fit within the noise (its held-out gap is large, or a
        candidate beats it significantly on held-out data).
    :return: (verdict, chosen fit or None, candidates with the chosen one first).
    """
    if significant and (explains(significant[0]) or joint_wins):
        chosen = significant[0]
        return chosen.effect, chosen, [chosen] + [f for f in fits if f is not chosen]
    return ("unexplained" if gap_is_real else "none"), None, fits


def diagnose(log: QuarterCarLog, p: qc.QuarterCarParams = qc.PAPER_PARAMS,
             cfg: DiagnoseConfig = DiagnoseConfig()) -> Diagnosis:
    """Diagnose the sim-to-real gap of a quarter-car log (see the module docstring).

    :param log: the log (from :func:`fricenv.logs.read_log`).
    :param p: nominal vehicle parameters (``--params``).
    :param cfg: settings.
    :return: a :class:`Diagnosis`.
    """
    t_start = time.perf_counter()
    unknown = [c for c in cfg.candidates if c not in EFFECTS]
    if unknown:
        raise ValueError(f"unknown candidate effect(s) {', '.join(unknown)}; valid effects: {', '.join(EFFECTS)}")
    if cfg.fit_loss not in FIT_LOSSES:
        raise ValueError(f"DiagnoseConfig.fit_loss must be one of {', '.join(FIT_LOSSES)}, got {cfg.fit_loss!r}")
    d = _prepare(log, p, cfg)
    folds = [_fold_data(d, j) for j in range(int(cfg.folds))]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        first = fit_nominal(folds[0], cfg)
        _refine_noise(first, folds[0])  # the folds share the noise levels (one dict)
        nominal_folds = [_score("nominal", [], first.names, first.x, folds[0], first.seconds)]
        nominal_folds += [fit_nominal(f, cfg) for f in folds[1:]]
    nominal = _cross_fitted(nominal_folds, d)
    jobs = _jobs(cfg)
    tasks = [([c], nf.x[:4], f, cfg, None) for c in cfg.candidates for f, nf in zip(folds, nominal_folds)]
    per_fold = _run_fits(tasks, jobs)
    k = len(folds)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        nominal_folds = [_nested_nominal(nf, per_fold[j::k], f, cfg)
                         for j, (f, nf) in enumerate(zip(folds, nominal_folds))]
    nominal = _cross_fitted(nominal_folds, d)
    fits = [_cross_fitted(per_fold[i * k:(i + 1) * k], d) for i in range(len(cfg.candidates))]
    for f in fits:
        _test_against(nominal, f, d)
    fits.sort(key=lambda f: f.adjusted_mse)
    significant = [f for f in fits if _significant(f, nominal, cfg)]
    edges = {f.effect: at_range_edge(f, p) for f in fits}
    eligible = [f for f in significant if not edges[f.effect]]  # significant, and not stretched to a bound
    joint = None
    if cfg.joint and len(eligible) >= 2:
        a, b = eligible[0], eligible[1]
        seeds = {a.effect: a.effect_params(), b.effect: b.effect_params()}
        joint = _cross_fitted(_run_fits([([a.effect, b.effect], af[:4], f, cfg, seeds)
                                         for f, af in zip(folds, a.x_folds)], jobs), d)
        _test_against(nominal, joint, d)

    def explains(f: CandidateFit) -> bool:
        return robust_gap(f) <= cfg.ratio_explained * robust_gap(nominal) or robust_gap(f) <= cfg.gap_within_noise

    joint_wins = joint is not None and _significant(joint, nominal, cfg) and explains(joint) and \
        not at_range_edge(joint, p) and joint.adjusted_mse < eligible[0].adjusted_mse
    verdict, chosen, fits = decide_verdict(eligible, fits, explains, joint_wins,
                                           gap_is_real(nominal, significant, cfg))
    drift = None
    # each half needs training windows in every fold: at least ``folds`` windows per half
    if chosen is not None and cfg.drift_check and len(d.starts) >= 2 * int(cfg.folds):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            tested_joint = joint_wins and not explains(chosen)  # the model that closes the gap
            drift, refit = drift_test(joint if tested_joint else chosen, d, cfg, jobs)
        _test_against(nominal, refit, d)
        if tested_joint:
            joint = refit
        else:
            fits = [refit if f is chosen else f for f in fits]
            significant = [refit if f is chosen else f for f in significant]
            chosen = refit
        if drift["drifts"]:  # the nearest library effect imitates something it is not: its parameters move
            verdict, chosen = "unexplained", None

    # localisation: the nominal model's held-out residuals on all windows
    r_ch = _by_channel(nominal.resid, d)
    residuals = {"before": np.sqrt(np.mean(nominal.resid ** 2, axis=-1)), "before_samples": r_ch}
    gap_after = nominal.gap
    params: dict = {}
    r_after_ch = None
    if chosen is not None:
        r_after_ch = _by_channel(chosen.resid, d)
        residuals["after"] = np.sqrt(np.mean(chosen.resid ** 2, axis=-1))
        residuals["after_samples"] = r_after_ch
        gap_after = chosen.gap
        params = chosen.effect_params()
    loc = _regimes(nominal, d, r_ch, r_after_ch)
    residuals["labels"] = loc["labels"]
    wm = nominal.window_mse
    order = np.argsort(-wm)[:3]
    segments = [{"t_start": float(d.t0 + d.dt * d.starts[i]), "t_end": float(d.t0 + d.dt * (d.starts[i] + d.horizon)),
                 "gap": gap_of(float(wm[i])), "held_out": True} for i in order]
    missing = [c for c in ("v", "a_x") if c not in d.channels]
    certainty = ("all channels logged" if not missing else
                 f"{' and '.join(missing)} not logged: "
                 + ("speed reconstructed from the wheel speed through the fitted model (initial state from the "
                    "free-rolling start); " if "v" in missing else "")
                 + "effects acting on the vehicle (drag, radius, friction level) and actuator gain are less "
                   "identifiable from the wheel speed alone; the verdict is less certain")
    where = {
        "segments": segments,
        "regimes": loc["regimes"],
        "channels": loc["channels"],
        "fitted_peak_slip": loc["peak_slip"],
        "nominal_road": nominal.road(),
        "data": {"channels": d.channels, "samples": d.n, "windows": len(d.starts),
                 "held_out_windows": len(d.starts), "folds": int(cfg.folds), "horizon_s": d.horizon * d.dt,
                 "speed_source": "logged v (smoothed)" if d.v is not None else "reconstructed from omega",
                 "certainty": certainty},
        "tests": {f.effect: {"t_stat": f.t_stat, "z": f.z, "z_paired": f.z_paired, "robust_gap": robust_gap(f),
                             "significant": any(f is s for s in significant),
                             "at_range_edge": edges.get(f.effect, [])} for f in fits},
        "robust_gap_before": robust_gap(nominal),
    }
    if drift is not None:
        where["drift_test"] = drift
    if joint is not None:
        where["joint_fit"] = {"effects": joint.effect.split("+"), "params": joint.effect_params(),
                              "gap_after": joint.gap, "t_stat": joint.t_stat}
    return Diagnosis(verdict=verdict, gap_before=nominal.gap, gap_after=gap_after, params=params, where=where,
                     candidates=fits, nominal=nominal, joint=joint, data=d, residuals=residuals,
                     seconds=time.perf_counter() - t_start, source=log.source)


def load_params(path) -> qc.QuarterCarParams:
    """Vehicle parameters from a JSON file (keys of :class:`QuarterCarParams`; unknown keys rejected)."""
    from dataclasses import fields as dc_fields

    from fricenv.utils import read_json_object

    raw = read_json_object(path, "vehicle parameters")
    valid = [f.name for f in dc_fields(qc.QuarterCarParams)]
    unknown = sorted(set(raw) - set(valid))
    if unknown:
        raise ValueError(f"{path}: unknown parameter(s) {', '.join(unknown)}; valid: {', '.join(valid)}")
    try:
        return qc.QuarterCarParams(**{k: float(v) for k, v in raw.items()})
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: {exc}") from None


def diagnose_file(path, plant: str = "quarter-car", params_file=None, cfg: DiagnoseConfig = DiagnoseConfig()):
    """Read a log with :func:`fricenv.logs.read_log` and diagnose it."""
    if plant != "quarter-car":
        raise ValueError(f"unknown plant {plant!r} for this diagnosis; valid plants: quarter-car")
    p = load_params(params_file) if params_file is not None else qc.PAPER_PARAMS
    log = read_log(path, plant)
    return diagnose(log, p, cfg)
