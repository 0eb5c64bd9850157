"""A session's events prepared for the car model: each event's samples and prediction windows
(:class:`fricenv.gap.car.model.EventData`), the channels' noise levels, and whether ``a_x`` agrees with the slope
of ``v`` well enough to be used."""

from __future__ import annotations

import numpy as np
from scipy.signal import savgol_filter

from fricenv.gap.car.config import CarConfig
from fricenv.gap.car.model import EventData
from fricenv.gap.car.session import Session
from fricenv.gap.core.noise import estimate_noise

__all__ = ["AX_LAG_MAX_S", "ax_agreement", "event_data", "noise_levels"]

NOISE_FLOOR = 1e-3  # smallest accepted noise std of any channel (SI) [-]
AX_LAG_MAX_S = 2.0  # longest lag of a_x behind v' looked for [s]
AX_LAG_OK_S = 0.1  # a_x within this lag of v' is used [s]
AX_GAIN_OK = (0.8, 1.25)  # ... and within this ratio of its size [-]
AX_MIN_CORRELATION = 0.5  # ... and correlated at least this well [-]
SAVGOL = (11, 2)  # the derivative of v: window [samples], order


def ax_agreement(s: Session, moving: np.ndarray) -> dict | None:
    """The lag and gain of ``a_x`` against the slope of ``v`` (a Savitzky-Golay derivative) over the moving
    samples: the lag maximising their correlation (0 to ``AX_LAG_MAX_S``), the gain by least squares at that lag,
    and whether the channel is ``used`` (lag, gain and correlation within bounds). None without ``a_x``."""
    if s.a_x is None or len(s) < 4 * SAVGOL[0]:
        return None
    dv = savgol_filter(np.nan_to_num(s.v), SAVGOL[0], SAVGOL[1], deriv=1, delta=s.dt)
    ax = np.asarray(s.a_x, dtype=float)
    best = (-np.inf, 0)
    for k in range(int(AX_LAG_MAX_S / s.dt) + 1):
        a, b, m = ax[k:], dv[:len(dv) - k], moving[k:] & moving[:len(moving) - k] & np.isfinite(ax[k:])
        if np.count_nonzero(m) > 10 and np.std(b[m]) > 0 and np.std(a[m]) > 0:
            c = float(np.corrcoef(a[m], b[m])[0, 1])
            best = max(best, (c, k))
    corr, k = best
    if not np.isfinite(corr):
        return None
    a, b, m = ax[k:], dv[:len(dv) - k], moving[k:] & moving[:len(moving) - k] & np.isfinite(ax[k:])
    gain = float(np.dot(a[m], b[m]) / max(np.dot(b[m], b[m]), 1e-300))
    lag = k * s.dt
    used = lag <= AX_LAG_OK_S and AX_GAIN_OK[0] <= gain <= AX_GAIN_OK[1] and corr >= AX_MIN_CORRELATION
    return {"lag_s": lag, "gain": gain, "correlation": corr, "used": bool(used)}


def ax_warning(check: dict) -> str:
    """The warning of an ``a_x`` left out of the car model."""
    return (f"a_x: trails the slope of v by {check['lag_s']:.2f} s at {check['gain']:.2f} of its size "
            f"(correlation {check['correlation']:.2f}); left out of the car model, whose body motion comes from v")


def event_data(s: Session, events: list, cfg: CarConfig, use_ax: bool) -> list[EventData]:
    """Each event's samples from its ``fit_start`` (the drive settled), cut into prediction windows of
    ``cfg.horizon_s`` (at least 3 samples), dealt into ``cfg.blocks`` contiguous blocks."""
    H = max(3, round(cfg.horizon_s / s.dt))
    pre = max(1, round(cfg.pre_s / s.dt))
    out = []
    for ev in events:
        a, b = ev.fit_start, ev.stop
        n = b - a
        starts = np.arange(0, n - H + 1, H) if n >= H and ev.skip is None else np.zeros(0, dtype=int)
        W = len(starts)
        block = (np.arange(W) * cfg.blocks) // max(W, 1)
        lead = np.asarray(s.T_b[max(0, a - pre):a], dtype=float)
        T = np.r_[np.full(pre - len(lead), lead[0] if len(lead) else s.T_b[a]), lead, s.T_b[a:b]]
        out.append(EventData(v=np.asarray(s.v[a:b], dtype=float), T=T, pre=pre,
                             wheels={c: np.asarray(w[a:b], dtype=float) for c, w in s.wheels.items()},
                             a_x=np.asarray(s.a_x[a:b], dtype=float) if use_ax and s.a_x is not None else None,
                             dt=s.dt, starts=starts, horizon=H, block=block, t0=float(s.t[a] - s.t[0])))
    return out


def noise_levels(data: list[EventData]) -> dict:
    """Noise std per channel from the events' samples: the median of the events' second-difference estimates
    (:func:`fricenv.gap.stats.estimate_noise`), weighted by their lengths, at least ``NOISE_FLOOR``."""
    out = {}
    for c in data[0].channels():
        est, wts = [], []
        for e in data:
            x = e.v if c == "v" else (e.a_x if c == "a_x" else e.wheels[c[len("omega_"):]])
            x = x[np.isfinite(x)]
            if len(x) >= 5:
                est.append(estimate_noise(x))
                wts.append(len(x))
        val = float(np.average(est, weights=wts)) if est else NOISE_FLOOR
        out[c] = max(val if np.isfinite(val) else NOISE_FLOOR, NOISE_FLOOR)
    return out
