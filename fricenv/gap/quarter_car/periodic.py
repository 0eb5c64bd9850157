"""A periodic component in the nominal model's wheel-speed residual: a gap that no library effect makes.

Every library effect changes the wheel's deceleration smoothly or once (a gain, a lag, a friction change); none
makes it oscillate steadily (a relaxation length can ring briefly after a brake step). A load that oscillates on
the suspension (a wheel hop at 10-15 Hz), a brake that judders, a sensor ring with a damaged tooth all leave a
spectral line in the wheel-speed residual. With a small amplitude such a line stays below the gap the verdict rule
needs (``gap_none``, set against a noise level read 10-20 % off), although it stands far above the noise's
spectrum; the log then read ``none``.

The test: the held-out residual of the calibrated nominal model on ``omega`` (its prediction windows laid end to
end, so the series is the log's own samples), its periodogram, and the largest ordinate between ``BAND_HZ[0]`` and
``min(BAND_HZ[1], TOP_SHARE fs)`` over the median ordinate of the whole spectrum. White noise gives ordinates
``Exp(1)`` times their mean, and the median is ``ln 2`` times the mean, so a ratio above ``LINE_RATIO`` = 30 has
a chance of ``exp(-30 ln 2)`` = 1e-9 per ordinate. The frequencies within one bin of a multiple of the window rate
(``fs / horizon``) are left out: each window restarts the prediction from fitted states, so any smooth model error
repeats at that rate.
"""

from __future__ import annotations

import numpy as np

from fricenv.gap.quarter_car.data import Data
from fricenv.gap.quarter_car.stats import CandidateFit

__all__ = ["BAND_HZ", "LINE_RATIO", "periodic_line"]

BAND_HZ = (8.0, 20.0)  # a wheel hop (the unsprung mass on the tyre, 10-15 Hz) or a brake judder [Hz]
TOP_SHARE = 0.45  # the band stops below this share of the sample rate [-]
# Largest ordinate over the median one that marks a line. White noise passes it with a chance of 1e-9 per
# ordinate; on 40 omega-only tuning logs (seed 3000, band from 5 Hz) the four nominal logs read at most 15.4 and
# two of the three load-oscillation logs 42 and 87 (at 13.3 and 10.8 Hz) [-]
LINE_RATIO = 30.0
MIN_SAMPLES = 64  # a shorter residual series resolves no line [-]


def periodic_line(nominal: CandidateFit, d: Data) -> dict | None:
    """The spectral line in the nominal model's held-out ``omega`` residual, if one stands ``LINE_RATIO`` times
    above the median of its periodogram inside the band.

    :param nominal: the cross-fitted nominal model (its ``resid`` held out on every window, ``omega`` first).
    :param d: the prepared log.
    :return: ``{"freq_hz", "ratio", "decided"}`` of the largest ordinate when it passes (``decided``: whether the
        line alone made the gap real, turning a ``none`` into ``unexplained``; the verdict rule sets it), else
        None.
    """
    if nominal.resid is None:
        return None
    r = np.nan_to_num(np.asarray(nominal.resid)[:, : d.horizon]).ravel()  # omega's block, windows in time order
    if r.size < MIN_SAMPLES:
        return None
    fs = 1.0 / d.dt
    f = np.fft.rfftfreq(r.size, d.dt)
    power = np.abs(np.fft.rfft(r - np.mean(r))) ** 2
    level = float(np.median(power[1:]))
    window_rate = fs / d.horizon
    near_rate = np.abs(f - window_rate * np.round(f / window_rate)) <= (f[1] - f[0]) * 1.0001
    band = (f >= BAND_HZ[0]) & (f <= min(BAND_HZ[1], TOP_SHARE * fs)) & ~near_rate
    if not band.any() or level <= 0:
        return None
    k = int(np.argmax(np.where(band, power, -np.inf)))
    ratio = float(power[k] / level)
    return {"freq_hz": float(f[k]), "ratio": ratio, "decided": False} if ratio > LINE_RATIO else None
