"""The payload log prepared for the gap diagnosis (:class:`PayloadData`): the same zero-phase filter on the vision
pose's second difference and on the model's generalised force, the residual noise levels propagated from the raw
channels' noise, and the train / held-out blocks (see :mod:`fricenv.gap.payload.diagnose`)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import butter, sosfilt, sosfiltfilt

from fricenv.effects.payload import PAYLOAD_EFFECTS
from fricenv.gap.core.noise import estimate_noise
from fricenv.gap.signals.filters import filter_lag
from fricenv.gap.signals.sensors import band_noise, condition_channel, frame_times, looks_filtered
from fricenv.logs import PayloadLog
from fricenv.plants import payload as pl

__all__ = ["CHANNELS", "DEFAULT_PAYLOAD_CONFIG", "WRENCH", "PayloadData", "PayloadDiagnoseConfig", "generalised_force_map", "lowpass",
           "prepare_payload"]

CHANNELS = ("theta", "X", "Y")  # residual channels: I_G theta'' [N m], m X'' [N], m Y'' [N]
WRENCH = ("M", "f_x", "f_y")
NOISE_DIFF_ORDER = 4  # difference order of the raw noise estimate (suppresses the smooth signal at coarse dt)
NOISE_FLOOR = 1e-9  # smallest accepted raw noise std (SI) [-]
NUMEROV = np.array([1.0, 10.0, 1.0]) / 12.0  # 3-tap weights matching the second difference's triangle kernel
REL_NOISE_FLOOR = 1e-3  # smallest residual noise std as a share of the channel's RMS acceleration signal [-]
MIN_BLOCKS = 4  # a log must have at least this many scored blocks
FILTER_BAND = 2.0  # a filtered channel's noise density is read from this many times the diagnosis cut-off up [-]


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
    max_wrench_lag_s: float = 0.05  # largest lag of a low-passed force-moment sensor fitted [s]
    joint: bool = True  # also fit the two best significant candidates together
    candidates: tuple[str, ...] = tuple(PAYLOAD_EFFECTS)  # effects to try

    def __post_init__(self):
        unknown = [c for c in self.candidates if c not in PAYLOAD_EFFECTS]
        if unknown:
            raise ValueError(f"unknown payload candidate effect(s) {', '.join(unknown)}; valid effects: "
                             f"{', '.join(PAYLOAD_EFFECTS)}")
        if self.max_delay_s >= self.margin_s:
            raise ValueError(f"max_delay_s ({self.max_delay_s}) must be below margin_s ({self.margin_s})")


DEFAULT_PAYLOAD_CONFIG = PayloadDiagnoseConfig()


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
    sensors: dict | None = None  # column -> missing share, outliers (:mod:`fricenv.gap.signals.sensors`)
    wrench_lag_max: float = 0.0  # largest lag fitted for a low-passed force-moment sensor (0: not filtered) [s]
    # the low-passed force-moment sensor's lag read from its noise roll-off (fricenv.gap.signals.filters.filter_lag; None: not filtered,
    # or no roll-off below the logger's Nyquist frequency) [s]
    wrench_lag: float | None = None

    @property
    def n(self) -> int:
        return len(self.t)

    @property
    def train(self) -> np.ndarray:
        return (self.block >= 0) & ~self.block_test[np.maximum(self.block, 0)]

    @property
    def test(self) -> np.ndarray:
        return (self.block >= 0) & self.block_test[np.maximum(self.block, 0)]



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


def generalised_force_map(theta: np.ndarray, p: pl.PayloadParams) -> np.ndarray:
    """(n, 3, 3): generalised force = G(theta) w, eq. (1) (moment arm, body force rotated into the vision frame)."""
    c, s = np.cos(theta), np.sin(theta)
    G = np.zeros(theta.shape + (3, 3))
    G[..., 0, :] = p.moment_row
    G[..., 1, 1], G[..., 1, 2] = c, -s
    G[..., 2, 1], G[..., 2, 2] = s, c
    return G


def lowpass(d_sos: np.ndarray, x: np.ndarray) -> np.ndarray:
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


def _pose_clock(log: PayloadLog) -> np.ndarray | None:
    """Frame times of the pose's fresh rows when the pose is held between the frames of a slower camera
    (:func:`fricenv.gap.signals.sensors.frame_times`), else None."""
    fresh = np.zeros(len(log.t), dtype=bool)
    for c in CHANNELS:
        fresh |= np.isfinite(np.asarray(getattr(log, c), dtype=float))
    return None if fresh.all() else frame_times(np.asarray(log.t, dtype=float), fresh)


def _conditioned_columns(log: PayloadLog, filter_band_hz: float) -> tuple[dict, dict, dict]:
    """Every column with its missing (held) samples and outliers filled by a cubic spline through the fresh ones
    (:mod:`fricenv.gap.signals.sensors`), its raw noise std and its sensor summary. An orientation logged wrapped into
    (-pi, pi] is unwrapped first (the rotation per sample is far below pi). A held pose is splined through its
    frames at their capture times (:func:`_pose_clock`), not at the rows where they show. A channel with fresh
    samples only at a share ``s`` of the rows (a slower camera) carries, per row of the uniform grid, white noise of
    ``1 / sqrt(s)`` times its own: the same noise power spread over the log's faster rate (what the low-pass sees).
    A low-passed force-moment channel (:func:`looks_filtered`) takes its noise from its spectral density in
    ``[filter_band_hz, 2 filter_band_hz]`` (:func:`band_noise`), where a difference-based estimate sees almost none."""
    cols, raw, sensors = {}, {}, {}
    clock = _pose_clock(log)
    idx = np.arange(len(log.t))
    for c in CHANNELS + WRENCH:
        x = np.asarray(getattr(log, c), dtype=float)
        if c == "theta":
            ok = np.isfinite(x)
            x = x.copy()
            x[ok] = np.unwrap(x[ok])
        cond = condition_channel(x, NOISE_FLOOR, may_be_filtered=False)
        fresh = np.isfinite(cond.values)
        at = clock if c in CHANNELS and clock is not None else idx * log.dt + float(log.t[0])
        if np.count_nonzero(fresh) >= 4 and not fresh.all():
            cols[c] = CubicSpline(at[fresh], cond.values[fresh])(np.asarray(log.t, dtype=float))
        else:
            cols[c] = cond.filled
        share = max(float(np.mean(fresh)), 1e-3)
        noise = estimate_noise(cond.values[fresh], order=NOISE_DIFF_ORDER) if fresh.any() else float("nan")
        noise = max(noise if np.isfinite(noise) else NOISE_FLOOR, NOISE_FLOOR)
        filtered = c in WRENCH and looks_filtered(cond.values)
        lag = None
        if filtered:
            band = band_noise(cond.values, 1.0 / log.dt, filter_band_hz)
            noise = max(noise, band if np.isfinite(band) else 0.0)
            lag = filter_lag(cond.values, 1.0 / log.dt, filter_band_hz, filter_band_hz / FILTER_BAND)
        raw[c] = noise / np.sqrt(share)
        sensors[c] = replace(cond, noise=noise, filtered=filtered).summary()
        if filtered and lag is not None:
            sensors[c]["filter"] = lag  # lag_s, cutoff_hz, order of the sensor's own low-pass
        if c in CHANNELS and clock is not None:
            sensors[c]["frame_rate_hz"] = float((np.count_nonzero(np.isfinite(clock)) - 1)
                                                / (np.nanmax(clock) - np.nanmin(clock)))
    return cols, raw, sensors


def prepare_payload(log: PayloadLog, S_known: np.ndarray, p: pl.PayloadParams, cfg: PayloadDiagnoseConfig) -> PayloadData:
    t = np.asarray(log.t, dtype=float)
    dt = log.dt
    n = len(t)
    fs = 1.0 / dt
    if cfg.cutoff_hz >= 0.4 * fs:
        raise ValueError(f"{log.source}: sample time {dt:g} s too coarse for the {cfg.cutoff_hz:g} Hz filter "
                         f"(need a sample rate above {cfg.cutoff_hz / 0.4:g} Hz)")
    sos = butter(cfg.filter_order, cfg.cutoff_hz, fs=fs, output="sos")
    cols, raw, sensors = _conditioned_columns(log, FILTER_BAND * cfg.cutoff_hz)
    w_hat = np.column_stack([cols[c] for c in WRENCH])
    pose = np.column_stack([cols[c] for c in CHANNELS])
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
    GS = generalised_force_map(pose_f[:, 0], p) @ S_known
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
                       rho2=rho2, block=block, block_test=block_test, S_known=np.asarray(S_known, dtype=float), p=p,
                       sensors=sensors,
                       wrench_lag_max=cfg.max_wrench_lag_s if any(sensors[c]["filtered"] for c in WRENCH) else 0.0,
                       wrench_lag=_spectral_lag(sensors))


def _spectral_lag(sensors: dict) -> float | None:
    """The force-moment sensor's filter lag: the median over its filtered channels whose noise shows a roll-off
    (one sensor, one filter), or None."""
    lags = [sensors[c]["filter"]["lag_s"] for c in WRENCH if "filter" in sensors[c]]
    return float(np.median(lags)) if lags else None
