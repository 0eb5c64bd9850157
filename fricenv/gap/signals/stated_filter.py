"""Sensor filters the user states (the column map's ``filter``, :mod:`fricenv.logs.sensor_filter`), undone.

Read from a channel's noise roll-off (:func:`fricenv.gap.signals.filters.shared_lag`), a sensor filter's order and lag come
out only roughly: on the independent simulator's real-like logs, whose ``v`` and ``a_x`` all went through one
second-order 5 Hz Butterworth, the roll-off read orders 2 to 4 and lags of 36-100 ms against the filter's 45 ms
(tuning seed 3000). Undoing a filter of the wrong order or lag leaves errors of tens of percent in a deceleration's
content at 3-8 Hz (ABS cycles, a modulated brake), which then set the channel's noise level. A filter the user
states from the sensor's data sheet or the logger's configuration is undone as stated instead.
"""

from __future__ import annotations

from dataclasses import replace

from fricenv.gap.signals.filters import advanced, group_delay, undone
from fricenv.gap.signals.sensors import ChannelCondition, fill_missing
from fricenv.logs.sensor_filter import SensorFilter

__all__ = ["apply_stated"]


def apply_stated(conds: dict[str, ChannelCondition], stated: dict[str, SensorFilter], fs: float, f_use: float,
                 deconvolve: tuple[str, ...] = ()) -> dict[str, ChannelCondition]:
    """The channels of ``conds`` that have a stated filter, realigned by it.

    Each is flagged filtered with certainty (``filter_evidence: "column map"``), its filter reported as stated, and
    either undone (:func:`fricenv.gap.signals.filters.deconvolved`, the channels in ``deconvolve``: a deceleration whose
    brake applies reach the cut-off) or advanced by its mean group delay over ``(0, f_use]`` (a speed, whose signal
    lies far below it).

    :param conds: the conditioned channels.
    :param stated: channel -> the filter the column map states; channels absent from ``conds`` are ignored.
    :param fs: sample rate [Hz].
    :param f_use: the lag is the mean group delay over ``(0, f_use]`` [Hz].
    :param deconvolve: the channels whose filter is undone rather than advanced by its lag.
    :return: the realigned conditions of the stated channels only.
    """
    out = {}
    for c, f in stated.items():
        if c not in conds:
            continue
        lag = group_delay(f.cutoff_hz, f.order, fs, f_use, False)
        k = conds[c]
        if c in deconvolve:
            k = undone(k, fs, f.cutoff_hz, f.order, False)
        else:
            values = advanced(k.values, lag * fs)
            k = replace(k, values=values, filled=fill_missing(values))
        out[c] = replace(k, filtered=True, certain=True, stated=True,
                         filter={"lag_s": lag, **f.as_dict(), "digital": False}, lag_s=lag)
    return out
