"""The log prepared for the quarter-car fits (:class:`Data`) and the windowed simulation: each prediction window
starts from a state estimated from data and is simulated ``horizon`` samples ahead by
:class:`fricenv.effects.quarter_car.EffectSimulator`; :func:`window_residuals` returns the normalised residuals
of any number of parameter sets at once, the per-window nuisance states (wheel speed, speed, transient slip)
fitted by Gauss-Newton (in a compiled diagnosis by :mod:`fricenv.gap.quarter_car.windows_kernel`, one call for all the
iterations, equal to the numpy loop here bit for bit).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.signal import savgol_filter

from fricenv.effects import registry
from fricenv.effects.quarter_car import EffectSimulator, ModelBatch
from fricenv.errors import InvalidInputError
from fricenv.gap.core.pool import default_jobs
from fricenv.gap.quarter_car.config import DiagnoseConfig
from fricenv.gap.quarter_car.data import Data
from fricenv.gap.quarter_car.params import ROAD_NAMES
from fricenv.gap.signals.filters import LAG_TOP, lag_against, shared_lag
from fricenv.gap.signals.sensors import condition_channel
from fricenv.gap.signals.speed import filtered_transient_slip, reconstruct_speed
from fricenv.gap.signals.stated_filter import apply_stated
from fricenv.logs import QuarterCarLog
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import longitudinal_slip

__all__ = ["MIN_HORIZON", "MIN_WINDOWS", "NOISE_FLOOR", "Data", "LogTooShortError", "applied_torque",
           "horizon_samples", "model_batch", "prepare", "projected_jacobian_available", "speed_states",
           "trajectory_residuals", "window_jacobian", "window_nuisances", "window_residuals"]

V0_STEP = 0.02  # finite-difference step of the per-window speed nuisance (v logged) [m/s]
LAMT_STEP = 0.005  # finite-difference step of the transient-slip nuisance [-]
LAMT_MAX_MOVE = 0.1  # largest Gauss-Newton move of the transient slip per iteration [-]
OMEGA0_STEP = 0.1  # finite-difference step of the per-window wheel-speed nuisance [rad/s]
OMEGA0_MAX_MOVE = 3.0  # largest Gauss-Newton move of that nuisance per iteration, in noise std [-]
GN_ITERS = 2  # Gauss-Newton iterations of the wheel-speed nuisance
FREE_ROLL_TORQUE = 0.02  # free rolling: |T_b| below this share of max |T_b| [-]
SAVGOL = (11, 2)  # speed smoother: window [samples], polynomial order
NOISE_FLOOR = {"omega": 1e-3, "v": 1e-3, "a_x": 1e-3}  # smallest accepted noise std per channel (SI)
FILTERED_CHANNELS = ("v", "a_x")  # channels a logger may low-pass (IMU, speed estimate); omega is a pulse count
DECONVOLVED = ("a_x",)  # filtered channels whose filter is undone, not only its lag (fricenv.gap.signals.filters.shared_lag)
# A low-passed channel's filter is read from its noise spectrum above LAG_BAND_HZ (the braking dynamics' own power
# lies mostly below), and its lag is the filter's mean group delay over (0, LAG_USE_HZ] (the band of the motion a
# prediction window sees) [Hz].
LAG_BAND_HZ = 2.0
LAG_USE_HZ = 1.0
LAG_XCORR_BAND = (0.3, 4.0)  # band in which a_x is aligned with the torque's deceleration [Hz]
LAG_MAX_S = 0.15  # longest sensor lag looked for [s]
# The torque's deceleration bounds a_x's sensor lag only where it explains at least this share of a_x's motion in
# LAG_XCORR_BAND: on ice the torque barely moves the car, and a sine driver's log at 29 Hz read a bound of 0 at a
# fit of 0.26, which vetoed a 5 Hz filter its noise showed (real-like tuning seed 3010: fits 0.62-1.00 where a
# filter was read) [-]
LAG_XCORR_MIN_FIT = 0.5
MIN_HORIZON = 3  # shortest prediction window [samples] (a 0.1 s window at 25 Hz would hold 2.5)
MIN_WINDOWS = 6  # fewest prediction windows a diagnosis needs (3 per fold for the cross-fitting) [-]
# Transient slip at a window start: False = the slip of the window's start state (the wheel-speed nuisance fit then
# absorbs the difference); True = the measured slip filtered through the relaxation equation.
RELAX_STATE_FROM_FILTER = True
# Whether the transient slip is also fitted per window, like the wheel speed (the filtered estimate alone predicts
# the relaxation model's transients poorly). It is a state fitted on the window's own samples, so it lowers the
# relaxation model's held-out error by about one noise variance per window even on pure noise; the significance
# tests subtract that (:func:`window_nuisances`).
RELAX_STATE_FITTED = True
# A compiled diagnosis fits the window start states in one compiled call (:mod:`fricenv.gap.quarter_car.windows_kernel`); False
# runs the Gauss-Newton loop in numpy around the compiled simulator (the loop the kernel is tested against).
FUSED_NUISANCE_FIT = True


class LogTooShortError(InvalidInputError):
    """A log with too few samples for the diagnosis' prediction windows."""


def horizon_samples(cfg: DiagnoseConfig, dt: float) -> int:
    """Prediction-window length in samples: ``cfg.horizon`` when set, else ``cfg.horizon_s`` at the log's rate (at
    least ``MIN_HORIZON``)."""
    if cfg.horizon is not None:
        return int(cfg.horizon)
    return max(MIN_HORIZON, round(float(cfg.horizon_s / dt)))


def _conditioned(log: QuarterCarLog, free_end: int, p: qc.QuarterCarParams) -> dict:
    """Every logged channel's :class:`fricenv.gap.signals.sensors.ChannelCondition` (``free_end``: the quiet start); the
    channels a logger may low-pass are realigned by their filter's lag when their noise shows its roll-off
    (:func:`fricenv.gap.signals.filters.shared_lag`, band from ``LAG_BAND_HZ``, lag over ``(0, LAG_USE_HZ]``), or by the
    filter the column map states (:func:`fricenv.gap.signals.stated_filter.apply_stated`)."""
    out = {}
    for c in ("omega", "v", "a_x"):
        x = getattr(log, c)
        if x is not None:
            out[c] = condition_channel(np.asarray(x, dtype=float), NOISE_FLOOR[c], free_end, c in FILTERED_CHANNELS)
    fs = 1.0 / log.dt
    stated = {c: f for c, f in log.sensor_filters.items() if c in FILTERED_CHANNELS}
    lowpass = {c: k for c, k in out.items() if c in FILTERED_CHANNELS and c not in stated}
    if lowpass and LAG_BAND_HZ < LAG_TOP * fs:
        out.update(shared_lag(lowpass, fs, LAG_BAND_HZ, LAG_USE_HZ, _torque_lag(log, out, p), DECONVOLVED))
    out.update(apply_stated(out, stated, fs, LAG_USE_HZ, DECONVOLVED))
    return out


def _torque_lag(log: QuarterCarLog, cond: dict, p: qc.QuarterCarParams) -> dict:
    """An upper bound of ``a_x``'s sensor lag: its delay behind the deceleration that the logged torque and the
    unfiltered wheel speed give, ``a_x ~ -(T_b + J omega') / (r m)`` (wheel and vehicle equations (1)-(2) without
    the small drag; ``omega'`` by a centred Savitzky-Golay derivative). An actuator effect (lag, delay) delays the
    applied torque further, never less, so this bounds the filter's lag from above (:func:`lag_against`), where that
    deceleration explains ``LAG_XCORR_MIN_FIT`` of ``a_x``'s motion (else no bound)."""
    if "a_x" not in cond or len(log) < 4 * SAVGOL[0]:
        return {}
    wd = savgol_filter(cond["omega"].filled, SAVGOL[0], SAVGOL[1], deriv=1, delta=log.dt)
    ref = -(np.asarray(log.T_b, dtype=float) + p.J * wd) / (p.r * p.m)
    return {"a_x": lag_against(cond["a_x"].values, ref, 1.0 / log.dt, LAG_XCORR_BAND, LAG_MAX_S, LAG_XCORR_MIN_FIT)}


def _window_counts(meas: dict, starts: np.ndarray, H: int) -> np.ndarray:
    rows = starts[:, None] + np.arange(H)[None, :]
    return sum(np.count_nonzero(np.isfinite(m[rows]), axis=1) for m in meas.values())


def applied_torque(log: QuarterCarLog) -> np.ndarray:
    """The brake torque the simulator holds over each sample step.

    A commanded torque (the contract's default) is what a controller held over the step: the logged sample itself
    (zero-order hold). A torque computed from a measured brake pressure (``log.torque_from_pressure``) is a sample
    of a continuous signal: between two samples it moves on, and the step's torque is the mean of the straight line
    between them, ``(T_k + T_(k+1)) / 2``. Holding the sample instead would delay the torque by half a step (20 ms
    at 25 Hz), as large as the brake delays the diagnosis looks for."""
    T = np.asarray(log.T_b, dtype=float)
    if not log.torque_from_pressure or T.size < 2:
        return T
    return np.r_[0.5 * (T[:-1] + T[1:]), T[-1]]


def prepare(log: QuarterCarLog, p: qc.QuarterCarParams, cfg: DiagnoseConfig) -> Data:
    """The log cut into prediction windows, dealt into cross-fitting folds (fold 0 held out), with its noise levels,
    outliers and missing samples (:mod:`fricenv.gap.signals.sensors`).

    :raises LogTooShortError: a log shorter than ``MIN_WINDOWS`` prediction windows.
    :raises ValueError: fewer than two folds.
    """
    if int(cfg.folds) != cfg.folds or cfg.folds < 2:
        raise ValueError(f"DiagnoseConfig.folds must be an integer >= 2, got {cfg.folds!r}")
    n = len(log)
    H = horizon_samples(cfg, log.dt) if n >= 2 else MIN_HORIZON
    need = max(MIN_WINDOWS, 3 * int(cfg.folds)) * H
    if n < need:
        raise LogTooShortError(f"{log.source}: log too short for diagnosis: {n} samples, need at least {need} "
                               f"({need // H} prediction windows of {H} samples); log a longer braking segment")
    T = applied_torque(log)
    tmax = max(float(np.max(np.abs(T))), 1e-9)
    braking = np.flatnonzero(np.abs(T) > FREE_ROLL_TORQUE * tmax)
    free_end = int(braking[0]) if braking.size else n
    cond = _conditioned(log, free_end, p)
    sigma = {c: k.noise for c, k in cond.items()}
    v_smooth = None
    if "v" in cond:
        win = min(SAVGOL[0], n - (1 - n % 2))
        v_smooth = savgol_filter(cond["v"].filled, win, SAVGOL[1])
    starts = np.arange(0, n - H + 1, H)
    fold = np.arange(len(starts)) % int(cfg.folds)
    meas = {c: k.values for c, k in cond.items()}
    return Data(t0=float(log.t[0]), dt=log.dt, Tb=T, omega=cond["omega"].filled,
                v=cond["v"].filled if "v" in cond else None, a_x=cond["a_x"].filled if "a_x" in cond else None,
                sigma=sigma, v_smooth=v_smooth, starts=starts, fold=fold, test=fold == 0, horizon=H,
                free_end=free_end, p=p, substeps=cfg.substeps, meas=meas, counts=_window_counts(meas, starts, H),
                sensors={c: k.summary() for c, k in cond.items()}, compiled=cfg.compiled,
                threads=default_jobs(cfg.jobs))


def model_batch(effects: Sequence[str], names: Sequence[str], X: np.ndarray, p: qc.QuarterCarParams) -> ModelBatch:
    """A ModelBatch of K elements from a (K, len(names)) parameter matrix."""
    X = np.atleast_2d(X)
    col = {name: X[:, i] for i, name in enumerate(names)}
    road = np.column_stack([col[k] for k in ROAD_NAMES])
    return ModelBatch.nominal(road, X.shape[0], p).with_params({k: v.copy() for k, v in col.items()}, effects)


def speed_states(batch: ModelBatch, d: Data) -> np.ndarray:
    """Speed estimate (K, n) used to start the windows."""
    if d.v_smooth is not None:
        return np.broadcast_to(d.v_smooth, (len(batch), d.n))
    return reconstruct_speed(batch, d.omega, d.t0, d.dt, d.free_end, d.p, compiled=d.compiled)


def _effect_states(batch: ModelBatch, d: Data, vhat: np.ndarray):
    """Lag-filter output and transient slip (K, n) estimated from the command log and the measured slip."""
    Ta = None
    if np.any(batch.tau > 0):
        if d.compiled and (np.any(batch.delay > 0) or np.any(batch.fade != 0)):
            from fricenv.effects import kernels  # the lag alone runs as a linear filter, already fast

            Ta = kernels.actuator_run(batch, d.Tb, 0, d.Tb[0], d.n, d.dt, d.substeps)
        else:
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
    The compiled kernel (:mod:`fricenv.effects.kernels`) runs them when ``d.compiled`` and the model has no plug-in
    effect with Python hooks; else the numpy :class:`EffectSimulator`, sample by sample.
    """
    K, W, H = len(batch), len(widx), d.horizon
    k0 = np.tile(np.repeat(d.starts[widx], reps), K)
    Ta0 = None if Ta0 is None else Ta0.ravel()
    lt0 = None if lt0 is None else lt0.ravel()
    if d.compiled:
        from fricenv.effects import kernels

        if kernels.supported(batch):
            sim = kernels.simulate_windows(batch, d.Tb, k0, v0.ravel(), w0.ravel(), Ta0, lt0, H, d.dt, d.t0,
                                           d.substeps, d.p, want_ax=d.a_x is not None, threads=d.threads,
                                           repeat=W * reps)
            out = {"omega": sim[0], **({"v": sim[1]} if d.v is not None else {}),
                   **({"a_x": sim[2]} if d.a_x is not None else {})}
            return {k: v.reshape(K, W, reps, H) for k, v in out.items()}
    full = batch.repeat(W * reps)
    sim = EffectSimulator(full, d.dt, d.n, d.p, d.substeps, d.t0, commands=d.Tb)
    sim.reset(v0.ravel(), w0.ravel(), k0=k0, Ta=Ta0, lam_t=lt0)
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
    src = d.meas if d.meas is not None else {"omega": d.omega, "v": d.v, "a_x": d.a_x}
    return {c: src[c][rows] for c in d.channels}


def _normalised(pred: dict, meas: dict, d: Data) -> np.ndarray:
    """Residuals (..., M): all channels concatenated, each divided by its noise std; 0 where no fresh measurement
    exists (a missing, held or outlier sample is left out)."""
    parts = [np.where(np.isfinite(meas[c]), (pred[c] - meas[c]) / d.sigma[c], 0.0) for c in d.channels]
    return np.concatenate(parts, axis=-1)


def trajectory_residuals(traj: dict, d: Data) -> np.ndarray:
    """Normalised residuals (W, M) of given whole-log channel trajectories (channel -> (n,) array) on every window,
    laid out as :func:`window_residuals` lays out a model's, with no start state fitted: the residuals of a
    prediction made without the windows' own samples (an oracle's noise-free truth)."""
    widx = np.arange(len(d.starts))
    rows = d.starts[widx][:, None] + np.arange(d.horizon)[None, :]
    return _normalised({c: np.asarray(traj[c], dtype=float)[rows] for c in d.channels}, _measured(d, widx), d)


def window_nuisances(effects: Sequence[str], d: Data) -> int:
    """Number of states fitted per window on that window's own samples: the wheel speed, the speed when ``v`` is
    logged, and the transient slip of a relaxation model. Each lowers a model's error on the window by about one
    noise variance even where it explains nothing, so tests between models subtract the difference."""
    states = sum(registry.get(e).window_states for e in effects)
    return 1 + (d.v is not None) + (states if RELAX_STATE_FITTED else 0)


@dataclass
class _Nuisance:
    """The per-window start states of one :func:`window_residuals` call and how Gauss-Newton fits them."""

    state: dict  # name -> (K, W): omega, v, and lam_t for a relaxation model
    free: list  # the fitted states, in the Jacobian's column order
    Ta0: np.ndarray | None  # (K, W) lag-filter state, not fitted
    max_move: dict  # largest move per iteration
    relax: bool  # the model has tire relaxation (lam_t is a state)


LOWER = {"omega": 0.0, "v": 0.0, "lam_t": -1.0}  # bounds of the fitted start states
UPPER = {"omega": np.inf, "v": np.inf, "lam_t": 1.0}


def _steps() -> dict:
    """Finite-difference step per start state (the module constants, read at call time)."""
    return {"omega": OMEGA0_STEP, "v": V0_STEP, "lam_t": LAMT_STEP}


def _nuisance(batch: ModelBatch, d: Data, s: np.ndarray) -> _Nuisance:
    """The start states of the windows starting at samples ``s``: wheel speed measured, speed and effect states
    estimated from the whole log; which of them the Gauss-Newton iterations fit."""
    K = len(batch)
    vhat = speed_states(batch, d)
    Ta, lt = _effect_states(batch, d, vhat)
    state = {"omega": np.broadcast_to(d.omega[s][None, :], (K, len(s))).copy(), "v": vhat[:, s].copy()}
    relax = bool(np.any(batch.sigma > 0))
    if relax:
        state["lam_t"] = lt[:, s].copy() if lt is not None else \
            longitudinal_slip(state["v"], state["omega"], batch.r_eff[:, None])
    free = ["omega"] + (["v"] if d.v is not None else []) + (["lam_t"] if relax and RELAX_STATE_FITTED else [])
    max_move = {"omega": OMEGA0_MAX_MOVE * d.sigma["omega"], "v": OMEGA0_MAX_MOVE * d.sigma.get("v", 1.0),
                "lam_t": LAMT_MAX_MOVE}
    return _Nuisance(state, free, None if Ta is None else Ta[:, s], max_move, relax)


def _fitted_numpy(batch: ModelBatch, d: Data, widx: np.ndarray, meas: dict, nu: _Nuisance) -> dict:
    """Gauss-Newton on the free start states, one simulator call per iteration (the numpy loop), then the
    predictions (K, W, H) per channel from the fitted states."""
    state, free, steps = nu.state, nu.free, _steps()
    reps = 1 + len(free)
    Ta0 = None if nu.Ta0 is None else np.repeat(nu.Ta0[:, :, None], reps, axis=2)
    meas_b = {c: m[None, :, None, :] for c, m in meas.items()}

    def replicas(name):
        x = np.repeat(state[name][:, :, None], reps, axis=2)
        if name in free:
            x[:, :, 1 + free.index(name)] += steps[name]
        return x

    for _ in range(GN_ITERS):
        pred = _simulate_windows(batch, d, widx, replicas("v"), replicas("omega"), Ta0,
                                 replicas("lam_t") if nu.relax else None, reps)
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
            state[n] = np.clip(state[n] + np.clip(move[..., i], -nu.max_move[n], nu.max_move[n]), LOWER[n],
                               UPPER[n])
    pred = _simulate_windows(batch, d, widx, state["v"][:, :, None], state["omega"][:, :, None],
                             None if Ta0 is None else Ta0[:, :, :1],
                             state["lam_t"][:, :, None] if nu.relax else None, 1)
    return {c: x[:, :, 0] for c, x in pred.items()}


def _fitted_compiled(batch: ModelBatch, d: Data, widx: np.ndarray, meas: dict, nu: _Nuisance) -> dict:
    """:func:`_fitted_numpy` in one compiled call (:mod:`fricenv.gap.quarter_car.windows_kernel`)."""
    from fricenv.gap.quarter_car import windows_kernel

    x0 = {"v": nu.state["v"], "omega": nu.state["omega"], "Ta": nu.Ta0, "lam_t": nu.state.get("lam_t")}
    return windows_kernel.fit_windows(batch, d.Tb, d.starts[widx], x0, meas, d.sigma, nu.free, _steps(),
                                      nu.max_move, LOWER, UPPER, GN_ITERS, d.dt, d.t0, d.substeps, d.p, d.threads)


def _fused(batch: ModelBatch, d: Data) -> bool:
    """Whether the compiled nuisance fit runs ``batch``: a compiled diagnosis, ``FUSED_NUISANCE_FIT``, and no
    plug-in effect with Python hooks (:func:`fricenv.effects.kernels.supported`)."""
    if not (d.compiled and FUSED_NUISANCE_FIT):
        return False
    from fricenv.effects import kernels

    return kernels.supported(batch)


def window_residuals(effects: Sequence[str], names: Sequence[str], X: np.ndarray, d: Data,
                     widx: np.ndarray | None = None, per_channel: bool = False):
    """Normalised residuals (K, W, M) of K parameter sets on windows ``widx``, the windows' start states (wheel
    speed; speed when ``v`` is logged; transient slip of a relaxation model) fitted by Gauss-Newton.

    :param per_channel: also return the per-channel residual blocks, dict channel -> (K, W, H).
    """
    X = np.atleast_2d(X)
    widx = np.arange(len(d.starts)) if widx is None else np.asarray(widx)
    batch = model_batch(effects, names, X, d.p)
    meas = _measured(d, widx)
    nu = _nuisance(batch, d, d.starts[widx])
    pred = (_fitted_compiled if _fused(batch, d) else _fitted_numpy)(batch, d, widx, meas, nu)
    r = _normalised(pred, {c: m[None] for c, m in meas.items()}, d)
    if per_channel:
        return r, {c: (pred[c] - meas[c][None]) / d.sigma[c] for c in d.channels}  # NaN where missing
    return r


def projected_jacobian_available(effects: Sequence[str], names: Sequence[str], x: np.ndarray, d: Data) -> bool:
    """Whether :func:`window_jacobian` can run this model: the compiled nuisance fit runs it (:func:`_fused`)."""
    return _fused(model_batch(effects, names, x, d.p), d)


def window_jacobian(effects: Sequence[str], names: Sequence[str], x: np.ndarray, fidx: np.ndarray, h: np.ndarray,
                    d: Data, widx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normalised residuals of the parameter set ``x`` on windows ``widx`` and their derivatives with respect to the
    parameters ``fidx``, the start states fitted per window as in :func:`window_residuals` and their response to the
    parameters projected out (:func:`fricenv.gap.quarter_car.windows_kernel.sensitivities`; a compiled diagnosis only, see
    :func:`projected_jacobian_available`).

    :param h: (P,) the parameter steps of the differences at fixed start states.
    :return: (r (W, M), equal to ``window_residuals(effects, names, x, d, widx)[0]``; J (W, M, P)).
    """
    from fricenv.gap.quarter_car import windows_kernel

    X = np.repeat(np.asarray(x, dtype=float)[None], 1 + len(fidx), axis=0)
    X[1 + np.arange(len(fidx)), fidx] += h
    batch = model_batch(effects, names, X, d.p)
    meas = _measured(d, widx)
    nu = _nuisance(batch, d, d.starts[widx])
    x0 = {"v": nu.state["v"], "omega": nu.state["omega"], "Ta": nu.Ta0, "lam_t": nu.state.get("lam_t")}
    return windows_kernel.sensitivities(batch, d.Tb, d.starts[widx], x0, meas, d.sigma, nu.free, _steps(),
                                        nu.max_move, LOWER, UPPER, GN_ITERS, d.dt, d.t0, d.substeps, d.p, h, d.threads)
