"""What a real sensor does to a channel, seen from the log itself (issue 15 item 2): missing or held samples (NaN),
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
- **Filter lag.** A sensor's low-pass also delays the channel (tens of milliseconds for an IMU driver's filter):
  :func:`filter_lag` reads the filter from the roll-off of the channel's noise, :func:`lag_against` the channel's
  delay behind a reference built from unfiltered channels, and :func:`shared_lag` realigns the channels that look
  filtered by the smallest of these upper bounds: a slow channel (a speed) is advanced by it (:func:`advanced`), a
  fast one (a deceleration) has the filter of that delay undone (:func:`deconvolved`). The difference test alone
  is not enough to call a channel filtered in a quarter-car log: a rough signal (a deceleration under ABS cycles)
  fails it too, unless it reads far above white noise on the quiet start (``certain``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import median_filter

from fricenv.gap.core.noise import estimate_noise

__all__ = ["FILTERED_AC", "OUTLIER_Z", "ChannelCondition", "advanced", "band_noise", "condition_channel",
           "correlation_time", "deconvolved", "fill_missing", "filter_lag", "filter_of_lag", "frame_times",
           "group_delay", "lag_against", "looks_filtered", "shared_lag"]

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
LAG_ORDERS = (1, 2, 3, 4)  # Butterworth orders tried for a sensor filter's noise roll-off [-]
LAG_TOP = 0.45  # the roll-off is read up to this share of the sample rate [-]
LAG_ALIASES = 3  # spectral images folded back into the band (a filter ahead of a slower logger) [-]
LAG_MIN_FIT = 0.5  # fitted roll-off must explain this share of the log-spectrum's variance in the band [-]
LAG_MIN_SAMPLES = 0.25  # a shared lag below this is none (shared_lag) [samples]
# ... and below this [s]: the torque bound of an unfiltered a_x under ABS cycles reads up to ~15 ms (fricenv's
# simulator), an IMU driver's filter lags by several tens of milliseconds
LAG_MIN_S = 0.02
DECONV_MAX_GAIN = 10.0  # largest gain of the inverse sensor filter (deconvolved) [-]
LAG_BAND_STEP = 1.5  # shared_lag also fits the roll-off above this multiple of the band's bottom [-]


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

    def summary(self) -> dict:
        """The report's per-channel line (``where["sensors"]``)."""
        out = {"missing_share": self.missing, "outliers": int(self.outliers.size), "filtered": self.filtered,
               "quantisation_step": self.quant_step, "noise_std": self.noise}
        if self.filter is not None:
            out["filter"] = dict(self.filter)
        if self.lag_s > 0:
            out["lag_s"] = self.lag_s
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


def advanced(x: np.ndarray, shift: float) -> np.ndarray:
    """``x`` read ``shift`` samples later, ``y[k] = x(k + shift)`` (linear interpolation between samples): a channel
    that lags its signal by ``shift`` samples realigned. ``y[k]`` is missing where the sample nearest ``k + shift``
    is, or where ``k + shift`` lies beyond the last sample."""
    x = np.asarray(x, dtype=float)
    at = np.arange(x.size) + float(shift)
    y = np.interp(at, np.arange(x.size), fill_missing(x))
    near = np.clip(np.rint(at).astype(int), 0, x.size - 1)
    return np.where(np.isfinite(x[near]) & (at <= x.size - 1 + 1e-9), y, np.nan)


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


def _rolloff(f: np.ndarray, fc: float, order: int, fs: float, digital: bool = False) -> np.ndarray:
    """Butterworth power response: the analog ``1 / (1 + (f / fc)^(2 n))`` with the images of ``LAG_ALIASES`` sample
    rates folded back (the filter may run faster than the logger samples), or with ``digital`` the bilinear
    (``scipy.signal.butter``) filter run at the logger rate ``fs`` itself.

    The digital response in closed form: ``butter`` pre-warps the cut-off to ``tan(pi fc / fs)`` and the bilinear
    transform maps ``f`` to ``tan(pi f / fs)``, so ``|H|^2 = 1 / (1 + (tan(pi f / fs) / tan(pi fc / fs))^(2 n))``
    (equal to ``sosfreqz`` of ``butter``'s filter to 1e-11 in log scale, tested; a hundred times faster, which
    matters in :func:`filter_lag`'s grid of 400 filters per channel)."""
    if digital:
        ratio = np.tan(np.pi * np.asarray(f) / fs) / np.tan(np.pi * min(fc, 0.499 * fs) / fs)
        return np.maximum(1.0 / (1.0 + ratio ** (2 * order)), 1e-300)
    out = np.zeros_like(f)
    for k in range(-LAG_ALIASES, LAG_ALIASES + 1):
        out += 1.0 / (1.0 + (np.abs(f + k * fs) / fc) ** (2 * order))
    return out


def group_delay(fc: float, order: int, fs: float, f_use: float, digital: bool) -> float:
    """Mean group delay of the Butterworth of :func:`_rolloff` over ``(0, f_use]`` [s]."""
    h = _response(np.linspace(0.0, f_use, 50), fc, order, fs, digital)
    return float(-(np.unwrap(np.angle(h))[-1] - np.angle(h[0])) / (2 * np.pi * f_use))


def _response(f: np.ndarray, fc: float, order: int, fs: float, digital: bool) -> np.ndarray:
    """Complex frequency response of the Butterworth of :func:`_rolloff` (analog, or digital at ``fs``) at ``f``."""
    from scipy.signal import butter, freqs, freqz

    if digital:
        b, a = butter(order, min(fc, 0.499 * fs), fs=fs)
        return freqz(b, a, worN=f, fs=fs)[1]
    b, a = butter(order, 2 * np.pi * fc, analog=True)
    return freqs(b, a, worN=2 * np.pi * np.asarray(f))[1]


def filter_lag(x: np.ndarray, fs: float, f_lo: float, f_use: float, min_cutoff: float = 0.0,
               families: tuple[bool, ...] = (False,)) -> dict | None:
    """The lag of a low-pass sensor filter, from the roll-off of the channel's noise (issue 15: a filtered
    force-moment sensor shifts the wrench against the pose like a vision delay, which the motion cannot tell apart;
    a filtered ``v`` or ``a_x`` lags the torque like a brake delay).

    The noise power spectral density (Welch) in ``[f_lo, LAG_TOP fs]``, above the signal, is fitted in log scale by a
    white density times a Butterworth power response of order ``n`` in :data:`LAG_ORDERS` and cut-off ``fc``
    (:func:`_rolloff`: analog with images folded back, and with ``True`` in ``families`` also the digital filter
    at the logger rate, whose response falls faster near the Nyquist frequency). A sensor filter is causal and
    minimum-phase, so its magnitude fixes its phase: the lag is the fitted filter's mean group delay over
    ``(0, f_use]`` (the band the diagnosis uses).

    :param min_cutoff: a fitted cut-off below this is no filter's [Hz] (0: any; a roll-off that starts below the band
        cannot be told from the signal's own spectrum falling).
    :param families: the filter families tried (False: analog, True: digital at ``fs``).
    :return: ``{"lag_s", "cutoff_hz", "order", "digital"}``, or None when no roll-off shows in the band (the fit
        explains less than ``LAG_MIN_FIT`` of the log-spectrum's variance, or the cut-off lies beyond the band's top
        or below ``min_cutoff``).
    """
    from scipy.signal import welch

    y = fill_missing(np.asarray(x, dtype=float))
    nper = int(min(y.size, max(64, 2 ** int(np.ceil(np.log2(4.0 * fs / f_lo))))))
    f, pxx = welch(y, fs=fs, nperseg=nper, detrend="linear")
    band = (f >= f_lo) & (f <= LAG_TOP * fs) & (pxx > 0)
    if np.count_nonzero(band) < 6:
        return None
    fb, lp = f[band], np.log(pxx[band])
    best = None
    for digital in families:
        for order in LAG_ORDERS:
            for fc in np.geomspace(0.5 * f_lo, fs, 200 if not digital else 100):
                model = np.log(_rolloff(fb, fc, order, fs, digital))
                resid = lp - model - np.mean(lp - model)
                cost = float(np.sum(resid**2))
                if best is None or cost < best[0]:
                    best = (cost, fc, order, digital)
    cost, fc, order, digital = best
    explained = 1.0 - cost / max(float(np.sum((lp - lp.mean()) ** 2)), 1e-300)
    if explained < LAG_MIN_FIT or fc > LAG_TOP * fs or fc < min_cutoff:
        return None
    return {"lag_s": group_delay(fc, order, fs, f_use, digital), "cutoff_hz": float(fc), "order": int(order),
            "digital": bool(digital)}


def deconvolved(x: np.ndarray, fs: float, fc: float, order: int = 2, digital: bool = False) -> np.ndarray:
    """``x`` with a low-pass sensor filter undone: the channel's spectrum divided by the filter's response (a
    Butterworth of order ``order`` and cut-off ``fc``, :func:`_response`), the gain held at most ``DECONV_MAX_GAIN``
    (where the filter has removed the signal, dividing would only raise the noise). Unlike a shift by the filter's
    group delay, this also restores the amplitude of a fast change (a brake apply, an ABS cycle) that the filter
    smoothed, which a model error would otherwise take for a brake lag. The log is mirrored at both ends before the
    transform (no wrap-around step) and missing samples stay missing."""
    x = np.asarray(x, dtype=float)
    y = fill_missing(x)
    n = y.size
    ext = np.r_[y[::-1], y, y[::-1]]
    f = np.fft.rfftfreq(ext.size, 1.0 / fs)
    h = _response(f, fc, order, fs, digital)
    inv = np.where(np.abs(h) * DECONV_MAX_GAIN >= 1.0, 1.0 / np.where(h == 0, 1.0, h), 0.0)
    u = np.fft.irfft(np.fft.rfft(ext) * inv, ext.size)[n:2 * n]
    return np.where(np.isfinite(x), u, np.nan)


def lag_against(y: np.ndarray, ref: np.ndarray, fs: float, band: tuple[float, float], max_lag: float) -> float:
    """The delay of channel ``y`` behind a reference ``ref`` of the same motion from unfiltered channels: the shift
    in ``[0, max_lag]`` (steps of a tenth of a sample) after which ``y``, band-passed to ``band`` [Hz] without phase
    (forward-backward Butterworth), is closest to a multiple of the band-passed reference (least squares) [s]."""
    from scipy.signal import butter, sosfiltfilt

    sos = butter(2, band, btype="band", fs=fs, output="sos")
    yb, rb = sosfiltfilt(sos, fill_missing(y)), sosfiltfilt(sos, fill_missing(ref))
    shifts = np.arange(0.0, max_lag * fs + 1e-9, 0.1)
    cost = np.full(shifts.size, np.inf)
    for i, sh in enumerate(shifts):
        ya = advanced(np.where(np.isfinite(y), yb, np.nan), sh)
        ok = np.isfinite(ya)
        den = float(np.dot(rb[ok], rb[ok]))
        if np.count_nonzero(ok) > 10 and den > 0:
            cost[i] = float(np.mean((ya[ok] - np.dot(ya[ok], rb[ok]) / den * rb[ok]) ** 2))
    return float(shifts[int(np.argmin(cost))] / fs) if np.isfinite(cost).any() else float("inf")


def shared_lag(conds: dict[str, ChannelCondition], fs: float, f_lo: float, f_use: float,
               bounds: dict[str, float] | None = None, deconvolve: tuple[str, ...] = ()) \
        -> dict[str, ChannelCondition]:
    """Channels low-passed by a sensor filter, read from their noise roll-off and realigned (issue 15: an IMU
    driver's filter on ``v`` and ``a_x`` delays them against the torque by tens of milliseconds, a model error that
    inflates the noise level read from the model's residual until real effects drown, and imitates a brake delay).

    Each channel that looks filtered (``filtered``, the difference test of :func:`condition_channel`) has its
    roll-off fitted above ``f_lo`` and above ``LAG_BAND_STEP f_lo`` (:func:`filter_lag`, cut-off at least the
    band's bottom; the fit of smaller lag is kept). The signal's own power can only add to the low end of the band,
    which lowers a fitted cut-off and lengthens the lag, never the reverse, so every estimate is an upper bound of
    the lag. When at least one channel shows a roll-off (the
    log has a sensor filter), every channel that looks filtered (one logger filters them alike) is advanced
    (:func:`advanced`) by the smallest of the fitted lags and of the ``bounds`` (other upper bounds, e.g.
    :func:`lag_against` a reference that an actuator effect can only delay further), and keeps its own roll-off
    fit as ``filter`` (None where its own spectrum showed none): the model is compared with the signal the sensor
    saw, and the noise level read later from the model's residual no longer holds the lag's error. Without any
    roll-off, or when the lag is below ``LAG_MIN_SAMPLES`` or ``LAG_MIN_S`` (a bound says the roll-off was the
    signal's own), no channel is ``filtered``: the difference test alone takes a rough signal (a deceleration under ABS cycles) for a
    filter, and a filtered channel's noise level, read from the model's residual, would then hold the model's error
    (up to 60 times the sensor noise on the independent simulator's unfiltered ``a_x``).

    :param conds: the conditioned channels that a logger may low-pass (a channel the difference test passed as
        unfiltered is never shifted: a signal's own spectrum can show a roll-off).
    :param fs: sample rate [Hz].
    :param f_lo: bottom of the fitted band [Hz].
    :param f_use: the lag is the mean group delay over ``(0, f_use]`` [Hz].
    :param bounds: other upper bounds of the lag, by name [s].
    :param deconvolve: the channels whose filter is undone (:func:`deconvolved`, the filter of
        :func:`filter_of_lag`) rather than advanced by its lag, when the filter is certain (a quiet start shows it;
        an inverse filter on a channel that was never filtered would only raise its noise tenfold): those with signal
        near the cut-off (a deceleration that follows the brake torque), where a shift leaves the smoothing; a
        channel whose signal lies far below it (a speed) is advanced, which leaves its noise as small as the filter
        made it.
    """
    from dataclasses import replace

    fits = {}
    for c, k in conds.items():
        found = [filter_lag(k.values, fs, lo, f_use, min_cutoff=lo, families=(False, True))
                 for lo in (f_lo, LAG_BAND_STEP * f_lo) if lo < LAG_TOP * fs] if k.filtered else []
        found = [f for f in found if f is not None]
        if found:
            fits[c] = min(found, key=lambda f: f["lag_s"])
    upper = list((bounds or {}).values())
    lag = min([f["lag_s"] for f in fits.values()] + upper) if fits else 0.0
    certain = any(k.certain for k in conds.values())
    if certain and lag < LAG_MIN_S:  # the quiet start shows a filter: a bound below any filter's lag is wrong
        lag = min([f["lag_s"] for f in fits.values()] + [b for b in upper if np.isfinite(b) and b >= LAG_MIN_S],
                  default=0.0)
    if not certain and (lag * fs < LAG_MIN_SAMPLES or lag < LAG_MIN_S):  # no roll-off, or the signal's own
        return {c: replace(k, filtered=False) for c, k in conds.items()}
    moved = lag * fs >= LAG_MIN_SAMPLES  # else a certain filter without any lag estimate: flagged, not moved
    out = dict(conds)
    for c, k in conds.items():
        if not k.filtered:
            continue
        values = k.values
        if moved and c in deconvolve and certain:
            fc, order, digital = filter_of_lag(fits.get(c) or next(iter(fits.values()), None), lag, fs)
            values = deconvolved(k.values, fs, fc, order, digital)
        elif moved:
            values = advanced(k.values, lag * fs)
        # one logger filters its channels alike: the filter's certainty is the log's, not each channel's
        out[c] = replace(k, values=values, filled=fill_missing(values), filter=fits.get(c),
                         lag_s=lag if moved else 0.0, certain=certain)
    return out


def filter_of_lag(fit: dict | None, lag: float, fs: float) -> tuple[float, int, bool]:
    """The sensor filter (cut-off, order, digital) whose mean group delay is ``lag``: the roll-off ``fit``'s order
    and family with its cut-off scaled by its lag over ``lag`` (a Butterworth's delay goes as one over its cut-off;
    the bound that set ``lag`` is the tighter estimate), or without a fit a second-order analog Butterworth, an IMU
    driver's usual filter (low-frequency delay ``sqrt(2) / (2 pi fc)``)."""
    if fit is None:
        return float(np.sqrt(2.0) / (2.0 * np.pi * lag)), 2, False
    return float(fit["cutoff_hz"] * fit["lag_s"] / lag), int(fit["order"]), bool(fit["digital"])
