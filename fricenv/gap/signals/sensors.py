"""What a real sensor does to a channel, seen from the log itself: missing or held samples (NaN),
isolated outliers, quantisation and low-pass filtering, and the honest noise level that follows.

- **Missing samples.** NaN in a channel (a held camera pose, a dropped sample) is left out of every residual; the
  states that start a prediction window use the channel linearly interpolated over the gaps.
- **Outliers.** An isolated spike, further than ``OUTLIER_Z`` robust noise std from the running median of its
  neighbours (``OUTLIER_SPAN`` samples) and from its two neighbours' mean while they agree, is an outlier: it is
  set missing (weight 0), so a single glitch cannot decide a verdict.
- **Quantisation.** When every value lies on a grid of step ``q``, the noise std is at least ``q / sqrt(12)``
  (uniform rounding error).
- **Filtering.** White noise gives first differences whose lag-1 autocorrelation is -1/2; a low-passed channel
  gives a larger one (above ``FILTERED_AC``; read on the quiet free-rolling start, where the signal barely moves). Its difference-based noise estimate is then far too small, so the
  diagnosis takes that channel's noise from the calibrated model's residual instead and inflates it by the
  residual's integrated autocorrelation time (:func:`correlation_time`): a window of ``H`` correlated samples holds
  only ``H / tau`` independent ones, the effective sample size that the significance tests assume.
- **Filter lag.** :mod:`fricenv.gap.signals.filters` reads a sensor's low-pass and its delay, and undoes them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import median_filter

from fricenv.gap.core.noise import estimate_noise

__all__ = ["FILTERED_AC", "OUTLIER_Z", "ChannelCondition", "band_noise", "condition_channel", "correlation_time",
           "fill_missing", "frame_times", "looks_filtered"]

OUTLIER_Z = 8.0  # distance from the running median beyond which an isolated sample is an outlier [noise std]
OUTLIER_SPAN = 7  # running-median span [samples]
OUTLIER_MAX_SHARE = 0.02  # largest share of flagged samples still read as glitches [-] ...
# ... unless they are this few: 2 % of a 5 s log at 28 Hz is 2.8 samples, and a glitch count that small is isolated
# whatever the log's length (before this floor, such logs kept all their outliers in: 3 of 3 on 6 tuning logs) [-]
OUTLIER_MAX_ISOLATED = 5
QUIET_MIN = 20  # samples of a quiet stretch (free rolling) that the filtering test needs [-]
FILTERED_AC = -0.35  # lag-1 autocorrelation of the first differences above which a channel looks filtered [-]
# A filter is certain when the test on a quiet start of m >= QUIET_CERTAIN_MIN differences reads above white noise's
# -1/2 by QUIET_CERTAIN_Z times its spread 1 / sqrt(m) (a still signal cannot correlate the differences) [-]
QUIET_CERTAIN_MIN = 8
QUIET_CERTAIN_Z = 3.0
QUANT_MIN_LEVELS = 3  # a grid needs at least this many distinct levels [-]
MAX_CORRELATION_TIME = 50.0  # upper bound of the integrated autocorrelation time [samples]
FILTERED_MARGIN = 0.15  # lag-1 autocorrelation of k-th differences this far above white noise's: filtered [-]
MIN_FRAMES = 10  # fresh frames a camera clock is fitted from [-]
MAX_AGE_SPREAD = 1.5  # frame ages spread over at most this many log steps for a clock [-]
MAX_LATE = 4.0  # a frame shown up to this many steps late is still on the clock (up to 3 dropped rows) [-]


@dataclass
class ChannelCondition:
    """One channel as the diagnosis uses it.

    :param values: the samples, outliers and missing samples as NaN.
    :param filled: the samples with every NaN interpolated (for the window start states).
    :param noise: the noise std estimate (difference-based, at least the quantisation floor).
    :param missing: share of samples missing in the log (NaN on input).
    :param outliers: indices of the samples set missing as outliers.
    :param quant_step: the quantisation step (0: not quantised).
    :param filtered: whether the channel looks low-pass filtered.
    """

    values: np.ndarray
    filled: np.ndarray
    noise: float
    missing: float
    outliers: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    quant_step: float = 0.0
    filtered: bool = False
    certain: bool = False  # the quiet start shows a filter beyond doubt (QUIET_CERTAIN_Z)
    filter: dict | None = None  # the sensor filter read from the noise roll-off (filter_lag), None: none seen
    lag_s: float = 0.0  # the sensor filter's lag the channel was realigned by [s] (0: not)
    stated: bool = False  # the filter is the one the column map states (fricenv.logs.sensor_filter), not read
    white: bool = False  # a filter known exactly (stated) is undone: the noise is white again (filters.undone)

    def summary(self) -> dict:
        """The report's per-channel line (``where["sensors"]``)."""
        out = {"missing_share": self.missing, "outliers": int(self.outliers.size), "filtered": self.filtered,
               "quantisation_step": self.quant_step, "noise_std": self.noise}
        if self.filter is not None:
            out["filter"] = dict(self.filter)
        if self.lag_s > 0:
            out["lag_s"] = self.lag_s
        if self.white:
            out["white"] = True
        if self.filtered:
            out["filter_evidence"] = "column map" if self.stated else "quiet start" if self.certain else "roll-off"
        return out


def fill_missing(x: np.ndarray) -> np.ndarray:
    """``x`` with NaN samples linearly interpolated (held at the ends); all NaN gives zeros."""
    x = np.asarray(x, dtype=float)
    ok = np.isfinite(x)
    if ok.all():
        return x.copy()
    if not ok.any():
        return np.zeros_like(x)
    idx = np.arange(x.size)
    return np.interp(idx, idx[ok], x[ok])


def _fresh(x: np.ndarray) -> np.ndarray:
    """The finite samples of ``x`` in order (a NaN gap joins its neighbours: good enough for difference statistics)."""
    return x[np.isfinite(x)]


def quantisation_step(x: np.ndarray) -> float:
    """The grid step of the values when they all lie on one (0 otherwise)."""
    u = np.unique(_fresh(x))
    if u.size < QUANT_MIN_LEVELS:
        return 0.0
    steps = np.diff(u)
    q = float(np.min(steps))
    if q <= 0 or u.size > 0.5 * np.count_nonzero(np.isfinite(x)):
        return 0.0
    k = (u - u[0]) / q
    return q if np.all(np.abs(k - np.round(k)) < 1e-3 * np.maximum(1.0, k)) else 0.0


def difference_ac(x: np.ndarray) -> float:
    """Lag-1 autocorrelation of the first differences (robust: median-centred, winsorised at 5 MAD)."""
    d2 = np.diff(_fresh(x))
    if d2.size < 10:
        return -0.5
    med = np.median(d2)
    mad = 1.4826 * np.median(np.abs(d2 - med)) + 1e-300
    d2 = np.clip(d2 - med, -5 * mad, 5 * mad)
    den = float(np.dot(d2, d2))
    return float(np.dot(d2[1:], d2[:-1]) / den) if den > 0 else -0.5


def _trend_spikes(f: np.ndarray, floor: float) -> np.ndarray:
    """Isolated spikes on a fast trend (a tracked pose sampled by a slow camera moves far between frames, so its
    neighbours differ and a running median follows the trend). Each sample is compared with the cubic through its
    two neighbours on either side, ``(-f[i-2] + 4 f[i-1] + 4 f[i+1] - f[i+2]) / 6`` (a smooth signal leaves a 4th
    order residual): a spike ``e`` leaves ``e`` there and ``-2e/3`` at its neighbours, a step ``s`` leaves ``s/2``
    at the two samples either side of it. A spike is beyond ``OUTLIER_Z`` robust spreads and 1.3 times its
    neighbours' residuals. The spread is that of the cubic residual itself (at least ``floor``): a difference-based
    noise level reads a fast trend's curvature as noise."""
    out = np.zeros(f.size, dtype=bool)
    if f.size < 7:
        return out
    r = np.zeros(f.size)
    r[2:-2] = f[2:-2] - (-f[:-4] + 4.0 * f[1:-3] + 4.0 * f[3:-1] - f[4:]) / 6.0
    spread = max(floor * np.sqrt(1.0 + 34.0 / 36.0), 1.4826 * float(np.median(np.abs(r[2:-2]))))
    a = np.abs(r)
    nb = np.maximum(np.r_[0.0, a[:-1]], np.r_[a[1:], 0.0])
    out[2:-2] = (a[2:-2] > OUTLIER_Z * spread) & (a[2:-2] > 1.3 * nb[2:-2])
    return out


def _outliers(x: np.ndarray, noise: float, floor: float) -> np.ndarray:
    """Indices of isolated spikes: far from the running median of their neighbours and from the mean of the two
    adjacent samples, while those two agree (a step or a lock-up moves its neighbours too), or off the local trend
    from both sides (:func:`_trend_spikes`). When more than ``OUTLIER_MAX_SHARE`` of the samples, and more than
    ``OUTLIER_MAX_ISOLATED``, qualify, the channel is spiky by nature and nothing is flagged."""
    ok = np.isfinite(x)
    if np.count_nonzero(ok) < OUTLIER_SPAN or not noise > 0:
        return np.zeros(0, dtype=int)
    f = fill_missing(x)
    dev = np.abs(f - median_filter(f, size=OUTLIER_SPAN, mode="nearest"))
    spread = max(noise, 1.4826 * float(np.median(dev[ok])))
    mid = np.zeros_like(f)
    mid[1:-1] = np.abs(f[1:-1] - 0.5 * (f[:-2] + f[2:]))
    agree = np.zeros(f.size, dtype=bool)
    agree[1:-1] = np.abs(f[2:] - f[:-2]) < 0.5 * mid[1:-1]
    flag = ok & (((dev > OUTLIER_Z * spread) & (mid > OUTLIER_Z * spread) & agree) | _trend_spikes(f, floor))
    if np.count_nonzero(flag) > max(OUTLIER_MAX_SHARE * f.size, OUTLIER_MAX_ISOLATED):
        return np.zeros(0, dtype=int)
    return np.flatnonzero(flag)


def condition_channel(x: np.ndarray, floor: float, quiet: int = 0, may_be_filtered: bool = True) \
        -> ChannelCondition:
    """Missing samples, outliers, quantisation and filtering of one channel, and its noise estimate.

    :param x: the channel's samples (NaN: missing).
    :param floor: the smallest accepted noise std (SI).
    :param quiet: length of the quiet start (free rolling, where the signal barely moves): the filtering test reads
        the differences there when it holds ``QUIET_MIN`` samples (elsewhere the signal's own curvature
        correlates them), else over the whole channel.
    :param may_be_filtered: run the filtering test (False for a wheel-speed sensor: its pulses are counted, not
        low-passed, and its small noise under a curved signal would read as filtered).
    """
    x = np.asarray(x, dtype=float).copy()
    missing = float(np.mean(~np.isfinite(x))) if x.size else 0.0
    q = quantisation_step(x)
    raw = estimate_noise(_fresh(x))
    noise = max(raw if np.isfinite(raw) else floor, floor, q / np.sqrt(12.0))
    fresh = np.flatnonzero(np.isfinite(x))
    out = fresh[_outliers(x[fresh], noise, floor)]  # on the fresh samples only: a held channel's frames are its samples
    x[out] = np.nan
    if out.size:
        raw = estimate_noise(_fresh(x))
        noise = max(raw if np.isfinite(raw) else floor, floor, q / np.sqrt(12.0))
    quiet_ac = difference_ac(x[:quiet]) if quiet > QUIET_CERTAIN_MIN else -0.5
    filtered = may_be_filtered and q == 0.0 and \
        (quiet_ac if quiet >= QUIET_MIN else difference_ac(x)) > FILTERED_AC
    certain = filtered and quiet_ac > -0.5 + QUIET_CERTAIN_Z / np.sqrt(max(quiet - 1, 1))
    return ChannelCondition(values=x, filled=fill_missing(x), noise=noise, missing=missing, outliers=out,
                            quant_step=q, filtered=filtered, certain=certain)


def looks_filtered(x: np.ndarray, order: int = 2) -> bool:
    """Whether a channel looks low-pass filtered: the lag-1 autocorrelation of its ``order``-th differences lies
    ``FILTERED_MARGIN`` above white noise's ``-order / (order + 1)`` (a higher order suppresses a smooth signal that
    would correlate first differences at a high rate)."""
    dk = np.diff(_fresh(np.asarray(x, dtype=float)), order - 1) if order > 1 else _fresh(np.asarray(x, dtype=float))
    return difference_ac(dk) > -order / (order + 1.0) + FILTERED_MARGIN


def band_noise(x: np.ndarray, fs: float, f_lo: float) -> float:
    """White-equivalent noise std of a low-passed channel: its noise power spectral density read in the band
    ``[f_lo, 2 f_lo]`` (above the signal, below a sensor filter's cut-off; Welch median over the band), as the std of
    white noise at rate ``fs`` with that density. A difference-based estimate reads the density near ``fs / 2``,
    where the filter has removed it, and would be far too small."""
    from scipy.signal import welch

    y = fill_missing(x)
    nper = int(min(y.size, max(64, 2 ** int(np.ceil(np.log2(4.0 * fs / f_lo))))))
    f, pxx = welch(y, fs=fs, nperseg=nper, detrend="linear")
    band = (f >= f_lo) & (f <= 2.0 * f_lo)
    if not band.any():
        return float("nan")
    return float(np.sqrt(np.median(pxx[band]) * fs / 2.0))


def frame_times(t: np.ndarray, fresh: np.ndarray) -> np.ndarray | None:
    """Capture times of a slow camera's frames, from the rows where a fresh frame first shows (``fresh``).

    A frame taken at ``f`` shows at the first row at or after it: its row is late by an age between 0 and one log
    step, which a fast pose turns into an error far above the vision noise. A camera runs on its own clock,
    ``f_j = a + j T``: the frame numbers ``j`` are counted from the gaps between fresh rows in frame periods, ``T``
    and ``a`` fitted by least squares, and the clock is placed so that the middle 80 % of the ages spread evenly
    over one log step; a fresh row off the clock is taken half a step before its row, and the log's first row (a
    frame taken before the log started) one period before the next frame. Returns the frame time of each fresh row (NaN elsewhere), or None where the fresh rows do not
    follow a clock (fewer than ``MIN_FRAMES``, a camera faster than half the log rate, or ages spread beyond
    ``MAX_AGE_SPREAD`` steps).
    """
    rows = np.flatnonzero(fresh)
    if rows.size < MIN_FRAMES or rows.size > 0.5 * t.size:
        return None
    h = float(np.median(np.diff(t)))
    out = np.full(t.size, np.nan)
    if rows[0] == 0:  # the first row shows a frame taken before the log started: one period before the next frame
        clock = frame_times(t, np.r_[False, fresh[1:]])
        if clock is not None:
            clock[0] = min(t[0], clock[rows[1]] - (clock[rows[-1]] - clock[rows[1]]) / (rows.size - 2))
        return clock
    tr = t[rows]
    period = (tr[-1] - tr[0]) / (rows.size - 1)
    # frame numbers from the gaps (a frame shown late after a dropped row makes a gap of up to 1.65 periods), then
    # from the fitted clock itself, refitted each time
    j = np.concatenate([[0], np.cumsum(np.maximum(np.floor(np.diff(tr) / period + 0.35), 1))])
    on = np.ones(rows.size, dtype=bool)  # rows on the clock (a frame held from before the log starts is not)
    for _ in range(3):
        period, a = np.polyfit(j[on], tr[on], 1)
        j = np.rint((tr - a - float(np.median((tr - a - period * j)[on]))) / period)
        on = np.concatenate([[True], np.diff(j) >= 1])
    period, a = np.polyfit(j[on], tr[on], 1)
    age = tr - (a + period * j)
    lo, hi = np.percentile(age[on], [10.0, 90.0])
    if hi - lo > MAX_AGE_SPREAD * h:
        return None
    on &= (age > lo - h) & (age < hi + MAX_LATE * h)  # dropped rows before a frame's row show it later
    f = np.where(on, a + period * j + 0.5 * (lo + hi) - 0.5 * h, tr - 0.5 * h)
    if np.any(np.diff(f) <= 0):
        return None
    out[rows] = f
    return out


def correlation_time(r: np.ndarray) -> float:
    """Integrated autocorrelation time ``1 + 2 sum_k rho_k`` of residual rows ``r`` (windows, H), NaN ignored, the
    sum stopped at the first non-positive autocorrelation; at least 1."""
    r = np.where(np.isfinite(r), r, 0.0)
    r = r - np.mean(r)  # a model's residual: centred over the log, not per window (a window mean is signal)
    den = float(np.sum(r * r))
    if den <= 0 or r.shape[-1] < 3:
        return 1.0
    tau = 1.0
    for k in range(1, r.shape[-1] - 1):
        rho = float(np.sum(r[:, k:] * r[:, :-k])) / den * r.shape[-1] / (r.shape[-1] - k)
        if rho <= 0:
            break
        tau += 2.0 * rho
    return float(min(tau, MAX_CORRELATION_TIME))
