"""Sim-to-real gap diagnosis of a planar-payload log (issue 6, item 6): where the gap lies, which effect, how far.

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
   estimated from its 4th differences (:func:`fricenv.gap.diagnose.estimate_noise`) and propagated through the
   filters (the sum of the squared impulse response) to the residual of each channel; the residual's
   autocorrelation gives the effective number of independent samples used by the significance test.
3. **Held-out split in time.** Alternate blocks of ``block_s``; every ``test_every``-th block is held out; a guard at
   each block edge and a margin at both log ends (filter transients) are not scored.
4. **Candidates.** ``wrench_offset`` (3 constants) and ``calibration_error`` (the full S, 9 entries) are linear least
   squares; ``calibration_drift`` is a 1-D bounded search over the rate; ``vision_delay`` a grid plus bounded search
   over the delay (the wrench is shifted by linear interpolation, the rotation uses the measured, i.e. delayed,
   orientation). Every fit uses the training blocks only. The drift's ``t`` is the log's own time column (DESIGN.md:
   ``S(t) = S (1 + rate t)``). Errors of m, I_G or rho map the generalised force by a constant matrix that commutes
   with the rotation, so they show up (exactly) as a ``calibration_error``.
5. **Scoring and verdict** as for the quarter car (:mod:`fricenv.gap.diagnose`): ``gap = sqrt(max(MSE - 1, 0))`` of
   the held-out normalised residual; a candidate is significant when its held-out improvement, without its largest
   block, exceeds ``sig_z`` standard deviations of that sum under pure noise (effective sample count), and
   candidates are ranked by the held-out MSE plus ``PENALTY_PER_PARAM`` times their parameter count over the
   effective training samples (a richer model cannot win by chance). The verdict needs significance and a held-out
   gap at most ``ratio_explained`` of the nominal one (or within ``gap_none``). The two best significant candidates
   are also fitted jointly (reported under ``where["joint_fit"]``).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.signal import butter, sosfilt, sosfiltfilt

from fricenv.effects.payload import PAYLOAD_EFFECTS
from fricenv.gap.diagnose import decide_verdict, estimate_noise, gap_of
from fricenv.logs import PayloadLog, read_log
from fricenv.plants import payload as pl
from fricenv.utils import read_json_object

__all__ = [
    "CHANNELS",
    "PayloadCandidate",
    "PayloadDiagnoseConfig",
    "PayloadDiagnosis",
    "diagnose_payload",
    "diagnose_payload_file",
    "load_payload_params",
    "summary_line",
]

CHANNELS = ("theta", "X", "Y")  # residual channels: I_G theta'' [N m], m X'' [N], m Y'' [N]
WRENCH = ("M", "f_x", "f_y")
NOISE_DIFF_ORDER = 4  # difference order of the raw noise estimate (suppresses the smooth signal at coarse dt)
NOISE_FLOOR = 1e-9  # smallest accepted raw noise std (SI) [-]
NUMEROV = np.array([1.0, 10.0, 1.0]) / 12.0  # 3-tap weights matching the second difference's triangle kernel
PENALTY_PER_PARAM = 2.0  # ranking penalty per fitted parameter, in units of 1/(effective training samples) [-]
DELAY_GRID_STEP = 0.005  # delay grid step [s] before the bounded refinement
SEARCH_XTOL = 1e-5  # tolerance of the bounded 1-D searches (s or 1/s)
REL_NOISE_FLOOR = 1e-3  # smallest residual noise std as a share of the channel's RMS acceleration signal [-]
MIN_BLOCKS = 4  # a log must have at least this many scored blocks
PARAM_KEYS = ("m", "I_G", "rho_x", "rho_y", "S")  # valid keys of --params


@dataclass(frozen=True)
class PayloadDiagnoseConfig:
    """Settings of the payload diagnosis."""

    cutoff_hz: float = 4.0  # low-pass cutoff of both sides [Hz]
    filter_order: int = 4  # Butterworth order (applied forward and backward) [-]
    margin_s: float = 0.5  # not scored at each end of the log (filter transients, delay start-up) [s]
    block_s: float = 0.5  # train / held-out block length [s]
    guard_s: float = 0.05  # not scored at each block edge [s]
    test_every: int = 2  # every test_every-th block is held out [-]
    sig_z: float = 4.0  # held-out improvement (noise standard deviations) a candidate must exceed [-]
    ratio_explained: float = 0.35  # a verdict leaves at most this share: gap_after <= ratio * gap_before [-]
    gap_none: float = 1.1  # nominal gap (noise units) below which the model fits within noise [-]
    max_delay_s: float = 0.25  # largest vision delay searched [s]
    max_rate: float = 0.05  # largest |calibration drift rate| searched [1/s]
    joint: bool = True  # also fit the two best significant candidates together
    candidates: tuple[str, ...] = tuple(PAYLOAD_EFFECTS)  # effects to try

    def __post_init__(self):
        unknown = [c for c in self.candidates if c not in PAYLOAD_EFFECTS]
        if unknown:
            raise ValueError(f"unknown payload candidate effect(s) {', '.join(unknown)}; valid effects: "
                             f"{', '.join(PAYLOAD_EFFECTS)}")
        if self.max_delay_s >= self.margin_s:
            raise ValueError(f"max_delay_s ({self.max_delay_s}) must be below margin_s ({self.margin_s})")


@dataclass
class PayloadData:
    """The log prepared for fitting."""

    t: np.ndarray  # (n,) time [s]
    dt: float
    w_hat: np.ndarray  # (n, 3) raw readings
    theta_f: np.ndarray  # (n,) low-passed orientation [rad]
    y: np.ndarray  # (n, 3) (I_G theta'', m X'', m Y'') from the filtered pose
    sos: np.ndarray  # the low-pass
    sigma: np.ndarray  # (3,) residual noise std per channel [N m, N, N]
    raw_noise: dict  # raw noise std per log column
    rho2: float  # sum over lags of the squared residual autocorrelation (effective-sample divisor) [-]
    block: np.ndarray  # (n,) block index of scored samples, -1 where not scored
    block_test: np.ndarray  # (n_blocks,) held out
    S_known: np.ndarray
    p: pl.PayloadParams

    @property
    def n(self) -> int:
        return len(self.t)

    @property
    def train(self) -> np.ndarray:
        return (self.block >= 0) & ~self.block_test[np.maximum(self.block, 0)]

    @property
    def test(self) -> np.ndarray:
        return (self.block >= 0) & self.block_test[np.maximum(self.block, 0)]


@dataclass
class PayloadCandidate:
    """One fitted model (the attribute names match :class:`fricenv.gap.diagnose.CandidateFit` where the report
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

    def effect_params(self) -> dict:
        return dict(self.params)


@dataclass
class PayloadDiagnosis:
    """Result of :func:`diagnose_payload`; :func:`fricenv.gap.report.report_dict` turns it into report.json."""

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
def _impulse_norms(sos: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Impulse responses of the force-side filter (low-pass + 3-tap weights) and of the pose-side filter
    (low-pass + second difference, per dt^2 = 1), and their squared norms."""
    imp = np.zeros(n)
    imp[n // 2] = 1.0
    h_lp = sosfiltfilt(sos, imp)
    h_force = np.convolve(h_lp, NUMEROV, mode="same")
    h_pose = np.convolve(h_lp, [1.0, -2.0, 1.0], mode="same")
    return h_force, h_pose, float(np.sum(h_force**2)), float(np.sum(h_pose**2))


def _acf_sq_sum(h: np.ndarray) -> float:
    """Sum over all lags of the squared autocorrelation of white noise passed through ``h``."""
    ac = np.correlate(h, h, mode="full")
    ac = ac / ac[len(h) - 1]
    return float(np.sum(ac**2))


def _G(theta: np.ndarray, p: pl.PayloadParams) -> np.ndarray:
    """(n, 3, 3): generalised force = G(theta) w, eq. (1) (moment arm, body force rotated into the vision frame)."""
    c, s = np.cos(theta), np.sin(theta)
    G = np.zeros(theta.shape + (3, 3))
    G[..., 0, :] = p.moment_row
    G[..., 1, 1], G[..., 1, 2] = c, -s
    G[..., 2, 1], G[..., 2, 2] = s, c
    return G


def _lowpass(d_sos: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The force-side filter along axis 0: zero-phase low-pass, then the 3-tap weights."""
    x = np.asarray(x, dtype=float)
    out = np.zeros_like(x)
    out[1:-1] = NUMEROV[0] * x[:-2] + NUMEROV[1] * x[1:-1] + NUMEROV[2] * x[2:]
    return _zero_filtfilt(d_sos, out)


def _zero_filtfilt(sos: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Zero-phase filtering along axis 0 of the signal extended by zeros (zero initial state, forward and
    backward). A plain linear operator without data-dependent edge padding: two signals that agree up to noise stay
    in agreement up to the filtered noise, right to the edges (the huge noise of a differenced pose would otherwise
    set the edge padding)."""
    y = sosfilt(sos, x, axis=0)
    return sosfilt(sos, y[::-1], axis=0)[::-1]


def _prepare(log: PayloadLog, S_known: np.ndarray, p: pl.PayloadParams, cfg: PayloadDiagnoseConfig) -> PayloadData:
    t = np.asarray(log.t, dtype=float)
    dt = log.dt
    n = len(t)
    fs = 1.0 / dt
    if cfg.cutoff_hz >= 0.4 * fs:
        raise ValueError(f"{log.source}: sample time {dt:g} s too coarse for the {cfg.cutoff_hz:g} Hz filter "
                         f"(need a sample rate above {cfg.cutoff_hz / 0.4:g} Hz)")
    sos = butter(cfg.filter_order, cfg.cutoff_hz, fs=fs, output="sos")
    w_hat = np.column_stack([log.M, log.f_x, log.f_y]).astype(float)
    # an orientation logged wrapped into (-pi, pi] is unwrapped (the rotation per sample is far below pi)
    pose = np.column_stack([np.unwrap(np.asarray(log.theta, dtype=float)), log.X, log.Y]).astype(float)
    raw = {c: max(estimate_noise(getattr(log, c), order=NOISE_DIFF_ORDER), NOISE_FLOOR) for c in CHANNELS + WRENCH}
    pose_f = sosfiltfilt(sos, pose, axis=0)
    # second difference first, then the filter: the filter (with its edge padding) is one linear operator applied
    # to both sides, so its edge transients cancel instead of acting on the large drift of the pose
    acc = np.empty_like(pose)
    acc[1:-1] = (pose[2:] - 2.0 * pose[1:-1] + pose[:-2]) / dt**2
    acc[0], acc[-1] = 0.0, 0.0
    y = _zero_filtfilt(sos, acc) * np.array([p.I_G, p.m, p.m])
    # noise propagation
    n_imp = int(min(n, max(8 * fs / cfg.cutoff_hz, 64)))
    h_force, h_pose, e_force, e_pose = _impulse_norms(sos, n_imp)
    GS = _G(pose_f[:, 0], p) @ S_known
    w_var = np.array([raw[c] ** 2 for c in WRENCH])
    force_var = np.mean(np.einsum("nij,j->ni", GS**2, w_var), axis=0) * e_force
    pose_var = (np.array([raw[c] for c in CHANNELS]) * np.array([p.I_G, p.m, p.m]) / dt**2) ** 2 * e_pose
    # a floor relative to the signal: a noise-free log is judged at a relative accuracy, not at rounding level
    sigma = np.maximum(np.sqrt(force_var + pose_var), REL_NOISE_FLOOR * np.sqrt(np.mean(y**2, axis=0)))
    share = pose_var / (force_var + pose_var)
    rho2 = float(np.mean(share * _acf_sq_sum(h_pose) + (1 - share) * _acf_sq_sum(h_force)))
    # blocks
    margin = round(cfg.margin_s / dt)
    blen = max(round(cfg.block_s / dt), 1)
    guard = round(cfg.guard_s / dt)
    block = np.full(n, -1)
    usable = np.arange(margin, n - margin)
    nb = len(usable) // blen
    if nb < MIN_BLOCKS:
        raise ValueError(f"{log.source}: log too short for diagnosis: {n * dt:.3g} s; need at least "
                         f"{2 * cfg.margin_s + MIN_BLOCKS * cfg.block_s:.3g} s ({MIN_BLOCKS} blocks of "
                         f"{cfg.block_s:g} s plus {cfg.margin_s:g} s margins)")
    for b in range(nb):
        s0 = margin + b * blen
        block[s0 + guard:s0 + blen - guard] = b
    block_test = (np.arange(nb) % cfg.test_every) == (cfg.test_every - 1)
    return PayloadData(t=t, dt=dt, w_hat=w_hat, theta_f=pose_f[:, 0], y=y, sos=sos, sigma=sigma, raw_noise=raw,
                       rho2=rho2, block=block, block_test=block_test, S_known=np.asarray(S_known, dtype=float), p=p)


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
    if delay > 0:
        w = np.column_stack([np.interp(d.t - delay, d.t, d.w_hat[:, k]) for k in range(3)])
    G = _G(d.theta_f, d.p)
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
        blocks += [(name + "_t", x * d.t[:, None]) for name, x in blocks]
    f = _lowpass(d.sos, np.concatenate([x for _, x in blocks], axis=1))
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


def _fit(effects: Sequence[str], d: PayloadData, cfg: PayloadDiagnoseConfig) -> tuple[dict, np.ndarray]:
    """Fit the effects on the training samples; returns (params, prediction on all samples)."""
    rows = d.train

    def regs(delay: float) -> _Regressors:
        return _regressors(d, delay, effects)

    def best_rate(R: _Regressors) -> tuple[float, float]:
        if "calibration_drift" not in effects:
            return 0.0, _cost(_solve(effects, R, 0.0, d, rows)[2], d, rows)
        res = minimize_scalar(lambda r: _cost(_solve(effects, R, r, d, rows)[2], d, rows),
                              bounds=(-cfg.max_rate, cfg.max_rate), method="bounded",
                              options={"xatol": SEARCH_XTOL})
        return float(res.x), float(res.fun)

    delay = 0.0
    if "vision_delay" in effects:
        grid = np.arange(0.0, cfg.max_delay_s + 1e-12, max(DELAY_GRID_STEP, d.dt))
        costs = [best_rate(regs(g))[1] for g in grid]
        i = int(np.argmin(costs))
        lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
        if hi > lo:
            res = minimize_scalar(lambda x: best_rate(regs(x))[1], bounds=(lo, hi), method="bounded",
                                  options={"xatol": SEARCH_XTOL})
            delay = float(res.x) if res.fun <= costs[i] else float(grid[i])
        else:
            delay = float(grid[i])
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
            params["delay"] = delay
    return params, pred


def _score(name: str, effects: Sequence[str], params: dict, pred: np.ndarray, d: PayloadData,
           seconds: float) -> PayloadCandidate:
    r = (d.y - pred) / d.sigma
    sq = np.mean(r**2, axis=1)
    nb = len(d.block_test)
    scored = d.block >= 0
    sums = np.bincount(d.block[scored], weights=sq[scored], minlength=nb)
    counts = np.maximum(np.bincount(d.block[scored], minlength=nb), 1)
    k = _n_params(effects)
    n_eff_train = np.count_nonzero(d.train) * len(CHANNELS) / d.rho2
    test_mse = float(np.mean(sq[d.test]))
    return PayloadCandidate(effect=name, params=params, n_params=k, train_mse=float(np.mean(sq[d.train])),
                            test_mse=test_mse, block_mse=sums / counts, residual=r, gap=gap_of(test_mse),
                            penalised=test_mse + PENALTY_PER_PARAM * k / n_eff_train, seconds=seconds)


def fit_payload_candidate(effects: Sequence[str], d: PayloadData, cfg: PayloadDiagnoseConfig) -> PayloadCandidate:
    """Fit a set of effects on the training blocks and score it on all blocks."""
    t0 = time.perf_counter()
    effects = list(effects)
    params, pred = _fit(effects, d, cfg)
    return _score("+".join(effects) if effects else "nominal", effects, params, pred, d, time.perf_counter() - t0)


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


# --------------------------------------------------------------------------------------------- localisation
def _where(d: PayloadData, nominal: PayloadCandidate, chosen: PayloadCandidate | None) -> dict:
    scored = d.block >= 0
    G = _G(d.theta_f, d.p)
    force = np.linalg.norm(np.einsum("nij,jk,nk->ni", G, d.S_known, d.w_hat), axis=1)
    rate = np.abs(np.gradient(d.theta_f, d.dt))
    t_mid = 0.5 * (d.t[0] + d.t[-1])
    labels = {
        "angular_rate_low": rate <= np.median(rate[scored]),
        "angular_rate_high": rate > np.median(rate[scored]),
        "wrench_low": force <= np.median(force[scored]),
        "wrench_high": force > np.median(force[scored]),
        "first_half": d.t < t_mid,
        "second_half": d.t >= t_mid,
    }
    sq_b = np.mean(nominal.residual**2, axis=1)
    sq_a = None if chosen is None else np.mean(chosen.residual**2, axis=1)
    regimes = {}
    for name, mask in labels.items():
        m = mask & scored
        n = int(np.count_nonzero(m))
        regimes[name] = {"gap": gap_of(float(np.mean(sq_b[m]))) if n else None, "samples": n}
        if sq_a is not None:
            regimes[name]["gap_after"] = gap_of(float(np.mean(sq_a[m]))) if n else None
    units = {"theta": "N m (I_G theta'')", "X": "N (m X'')", "Y": "N (m Y'')"}
    channels = {}
    for i, c in enumerate(CHANNELS):
        channels[c] = {"gap": gap_of(float(np.mean(nominal.residual[scored, i] ** 2))),
                       "noise_std": float(d.sigma[i]), "unit": units[c]}
        if chosen is not None:
            channels[c]["gap_after"] = gap_of(float(np.mean(chosen.residual[scored, i] ** 2)))
    order = np.argsort(-nominal.block_mse)[:3]
    segments = []
    for b in order:
        idx = np.flatnonzero(d.block == b)
        segments.append({"t_start": float(d.t[idx[0]]), "t_end": float(d.t[idx[-1]]),
                         "gap": gap_of(float(nominal.block_mse[b])), "held_out": bool(d.block_test[b])})
    return {"segments": segments, "regimes": regimes, "channels": channels, "labels": labels}


# --------------------------------------------------------------------------------------------- diagnosis
def diagnose_payload(log: PayloadLog, S_known=pl.PAPER_S, p: pl.PayloadParams = pl.PAPER_PARAMS,
                     cfg: PayloadDiagnoseConfig = PayloadDiagnoseConfig()) -> PayloadDiagnosis:
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
    d = _prepare(log, S_known, p, cfg)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        nominal = fit_payload_candidate([], d, cfg)
        fits = [fit_payload_candidate([c], d, cfg) for c in cfg.candidates]
    for f in fits:
        f.z = improvement_z(nominal, f, d)
    fits.sort(key=lambda f: f.penalised)

    def significant(f: PayloadCandidate) -> bool:
        return f.z > cfg.sig_z and f.penalised < nominal.penalised

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
    loc = _where(d, nominal, chosen)
    n_scored = int(np.count_nonzero(d.block >= 0))
    where = {
        "segments": loc["segments"],
        "regimes": loc["regimes"],
        "channels": loc["channels"],
        "data": {"samples": d.n, "dt": d.dt, "blocks": len(d.block_test),
                 "held_out_blocks": int(np.count_nonzero(d.block_test)), "block_s": cfg.block_s,
                 "scored_samples": n_scored, "effective_samples": n_scored * len(CHANNELS) / d.rho2,
                 "filter": f"zero-phase Butterworth order {cfg.filter_order}, {cfg.cutoff_hz:g} Hz",
                 "raw_noise_std": d.raw_noise},
        "tests": {f.effect: {"z": f.z, "penalised_test_mse": f.penalised, "n_params": f.n_params,
                             "significant": bool(significant(f))} for f in fits},
    }
    if joint is not None:
        where["joint_fit"] = {"effects": joint.effect.split("+"), "params": joint.effect_params(),
                              "gap_after": joint.gap, "z": joint.z}
    gap_after = chosen.gap if chosen is not None else nominal.gap
    residuals = {"labels": loc["labels"]}
    return PayloadDiagnosis(verdict=verdict, gap_before=nominal.gap, gap_after=gap_after,
                            params=chosen.effect_params() if chosen is not None else {}, where=where,
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
                          cfg: PayloadDiagnoseConfig = PayloadDiagnoseConfig()) -> PayloadDiagnosis:
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

