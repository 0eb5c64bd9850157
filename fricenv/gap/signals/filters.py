"""A sensor's low-pass filter seen from the log: its roll-off, its delay, and the channel realigned or deconvolved.

A sensor's low-pass also delays the channel (tens of milliseconds for an IMU driver's filter):
  :func:`filter_lag` reads the filter from the roll-off of the channel's noise, :func:`lag_against` the channel's
  delay behind a reference built from unfiltered channels, and :func:`shared_lag` realigns the channels that look
  filtered by the smallest of these upper bounds: a slow channel (a speed) is advanced by it (:func:`advanced`), a
  fast one (a deceleration) has the filter of that delay undone (:func:`deconvolved`). The difference test alone
  is not enough to call a channel filtered in a quarter-car log: a rough signal (a deceleration under ABS cycles)
  fails it too, unless it reads far above white noise on the quiet start (``certain``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from fricenv.gap.core.noise import estimate_noise
from fricenv.gap.signals.sensors import ChannelCondition, fill_missing

__all__ = ["LAG_TOP", "advanced", "deconvolved", "filter_lag", "filter_of_lag", "group_delay", "lag_against",
           "shared_lag", "undone", "undone_noise"]

LAG_ORDERS = (1, 2, 3, 4)  # Butterworth orders tried for a sensor filter's noise roll-off [-]
LAG_TOP = 0.45  # the roll-off is read up to this share of the sample rate [-]
LAG_ALIASES = 3  # spectral images folded back into the band (a filter ahead of a slower logger) [-]
LAG_MIN_FIT = 0.5  # fitted roll-off must explain this share of the log-spectrum's variance in the band [-]
LAG_MIN_SAMPLES = 0.25  # a shared lag below this is none (shared_lag) [samples]
# ... and below this [s]: the torque bound of an unfiltered a_x under ABS cycles reads up to ~15 ms (fricenv's
# simulator), an IMU driver's filter lags by several tens of milliseconds
LAG_MIN_S = 0.02
DECONV_MAX_GAIN = 10.0  # largest gain of the inverse sensor filter (deconvolved) [-]
LAG_BAND_STEP = 1.5  # ratio of the successive band bottoms shared_lag fits the roll-off above [-]
LAG_BANDS = 3  # band bottoms f_lo LAG_BAND_STEP^k, k < LAG_BANDS, each fitted by shared_lag [-]


def advanced(x: np.ndarray, shift: float) -> np.ndarray:
    """``x`` read ``shift`` samples later, ``y[k] = x(k + shift)`` (linear interpolation between samples): a channel
    that lags its signal by ``shift`` samples realigned. ``y[k]`` is missing where the sample nearest ``k + shift``
    is, or where ``k + shift`` lies beyond the last sample."""
    x = np.asarray(x, dtype=float)
    at = np.arange(x.size) + float(shift)
    y = np.interp(at, np.arange(x.size), fill_missing(x))
    near = np.clip(np.rint(at).astype(int), 0, x.size - 1)
    return np.where(np.isfinite(x[near]) & (at <= x.size - 1 + 1e-9), y, np.nan)


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
    """The lag of a low-pass sensor filter, from the roll-off of the channel's noise (a filtered
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


def undone(k: ChannelCondition, fs: float, fc: float, order: int = 2, digital: bool = False) -> ChannelCondition:
    """Channel ``k`` with a sensor filter known exactly (stated) undone (:func:`deconvolved`), ``white`` set: its
    noise is white again, so its level is read from the undone samples (:func:`undone_noise`, at least the level
    ``k`` had), as an unfiltered channel's is, not from a model's residual."""
    values = deconvolved(k.values, fs, fc, order, digital)
    level = undone_noise(values, fs, fc, order, digital)
    return replace(k, values=values, filled=fill_missing(values), white=True,
                   noise=max(level, k.noise) if np.isfinite(level) else k.noise)


def undone_noise(x: np.ndarray, fs: float, fc: float, order: int = 2, digital: bool = False) -> float:
    """The white-noise std of a channel before its sensor filter, from the channel with the filter undone (``x``,
    :func:`deconvolved` with the same filter): the difference-based estimate
    (:func:`fricenv.gap.core.noise.estimate_noise`) over the square root of the share of a white noise's
    second-difference power that the deconvolution keeps (it zeroes the band where the filter's gain is below
    ``1 / DECONV_MAX_GAIN``, which holds most of that power: at 100 Hz, a 5 Hz second-order filter leaves about a
    hundredth of it)."""
    f = np.linspace(0.0, 0.5 * fs, 1025)
    kept = np.abs(_response(f, fc, order, fs, digital)) * DECONV_MAX_GAIN >= 1.0
    weight = (2.0 * np.sin(np.pi * f / fs)) ** 4  # second differences: |1 - exp(-i 2 pi f / fs)|^4
    share = float(np.sum(weight * kept) / np.sum(weight))
    fresh = np.asarray(x, dtype=float)
    raw = estimate_noise(fresh[np.isfinite(fresh)])
    return raw / np.sqrt(share) if share > 0.0 and np.isfinite(raw) else float("nan")


def lag_against(y: np.ndarray, ref: np.ndarray, fs: float, band: tuple[float, float], max_lag: float,
                min_fit: float = 0.0) -> float:
    """The delay of channel ``y`` behind a reference ``ref`` of the same motion from unfiltered channels: the shift
    in ``[0, max_lag]`` (steps of a tenth of a sample) after which ``y``, band-passed to ``band`` [Hz] without phase
    (forward-backward Butterworth), is closest to a multiple of the band-passed reference (least squares) [s].

    :param min_fit: the share of the band-passed ``y``'s power that the reference must explain at that shift; below
        it the reference does not follow the channel's motion and says nothing of its delay: ``inf`` (no bound).
    """
    from scipy.signal import butter, sosfiltfilt

    sos = butter(2, band, btype="band", fs=fs, output="sos")
    yb, rb = sosfiltfilt(sos, fill_missing(y)), sosfiltfilt(sos, fill_missing(ref))
    shifts = np.arange(0.0, max_lag * fs + 1e-9, 0.1)
    cost = np.full(shifts.size, np.inf)
    power = np.full(shifts.size, np.inf)
    for i, sh in enumerate(shifts):
        ya = advanced(np.where(np.isfinite(y), yb, np.nan), sh)
        ok = np.isfinite(ya)
        den = float(np.dot(rb[ok], rb[ok]))
        if np.count_nonzero(ok) > 10 and den > 0:
            cost[i] = float(np.mean((ya[ok] - np.dot(ya[ok], rb[ok]) / den * rb[ok]) ** 2))
            power[i] = float(np.mean(ya[ok] ** 2))
    if not np.isfinite(cost).any():
        return float("inf")
    best = int(np.argmin(cost))
    if power[best] > 0 and 1.0 - cost[best] / power[best] < min_fit:
        return float("inf")
    return float(shifts[best] / fs)


def shared_lag(conds: dict[str, ChannelCondition], fs: float, f_lo: float, f_use: float,
               bounds: dict[str, float] | None = None, deconvolve: tuple[str, ...] = ()) \
        -> dict[str, ChannelCondition]:
    """Channels low-passed by a sensor filter, read from their noise roll-off and realigned (an IMU
    driver's filter on ``v`` and ``a_x`` delays them against the torque by tens of milliseconds, a model error that
    inflates the noise level read from the model's residual until real effects drown, and imitates a brake delay).

    Each channel that looks filtered (``filtered``, the difference test of :func:`condition_channel`) has its
    roll-off fitted above ``f_lo LAG_BAND_STEP^k``, ``k < LAG_BANDS`` (:func:`filter_lag`, cut-off at least the
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
    fits = {}
    for c, k in conds.items():
        found = [filter_lag(k.values, fs, lo, f_use, min_cutoff=lo, families=(False, True))
                 for lo in f_lo * LAG_BAND_STEP ** np.arange(LAG_BANDS) if lo < LAG_TOP * fs] if k.filtered else []
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
        if moved and c in deconvolve and certain:
            fc, order, digital = filter_of_lag(fits.get(c) or next(iter(fits.values()), None), lag, fs)
            k = replace(k, values=deconvolved(k.values, fs, fc, order, digital))
        elif moved:
            k = replace(k, values=advanced(k.values, lag * fs))
        # one logger filters its channels alike: the filter's certainty is the log's, not each channel's
        out[c] = replace(k, filled=fill_missing(k.values), filter=fits.get(c), lag_s=lag if moved else 0.0,
                         certain=certain)
    return out


def filter_of_lag(fit: dict | None, lag: float, fs: float) -> tuple[float, int, bool]:
    """The sensor filter (cut-off, order, digital) whose mean group delay is ``lag``: the roll-off ``fit``'s order
    and family with its cut-off scaled by its lag over ``lag`` (a Butterworth's delay goes as one over its cut-off;
    the bound that set ``lag`` is the tighter estimate), or without a fit a second-order analog Butterworth, an IMU
    driver's usual filter (low-frequency delay ``sqrt(2) / (2 pi fc)``)."""
    if fit is None:
        return float(np.sqrt(2.0) / (2.0 * np.pi * lag)), 2, False
    return float(fit["cutoff_hz"] * fit["lag_s"] / lag), int(fit["order"]), bool(fit["digital"])
