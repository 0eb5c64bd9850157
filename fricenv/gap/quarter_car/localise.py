"""Localisation of the gap: the nominal model's held-out residuals (and the verdict model's) by time segment, by
operating regime (slip below/above the fitted road's peak, brake apply/hold/release, speed bands) and by channel,
assembled into the report's ``where``."""

from __future__ import annotations

import numpy as np
from scipy.signal import savgol_filter

from fricenv.gap.quarter_car.data import Data
from fricenv.gap.quarter_car.stats import CandidateFit, gap_of, robust_gap
from fricenv.gap.quarter_car.windows import model_batch, speed_states
from fricenv.plants.tire import MagicFormula, longitudinal_slip

__all__ = ["APPLY_RATE", "SPEED_BANDS", "localise"]

SPEED_BANDS = (10.0, 20.0)  # band edges [m/s]
APPLY_RATE = 0.5  # |dT_b/dt| above this share of max |T_b| per second counts as apply/release [1/s]


def _by_channel(resid: np.ndarray, d: Data) -> dict:
    """Split (windows, samples) residuals into their channel blocks, dict channel -> (windows, horizon)."""
    return {c: resid[:, i * d.horizon:(i + 1) * d.horizon] for i, c in enumerate(d.channels)}


def _regimes(nominal: CandidateFit, d: Data, r_ch: dict, r_after: dict | None = None) -> dict:
    """Residual by regime (slip vs the fitted peak, apply/hold/release, speed band) and by channel, on all windows:
    the nominal model's (``gap``) and, if given, the verdict model's (``gap_after``)."""
    rows = d.starts[:, None] + np.arange(d.horizon)[None, :]
    vhat = speed_states(model_batch([], nominal.names, nominal.x, d.p), d)[0]
    road = MagicFormula(**nominal.road())
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




def _certainty(d: Data) -> str:
    missing = [c for c in ("v", "a_x") if c not in d.channels]
    if not missing:
        return "all channels logged"
    return (f"{' and '.join(missing)} not logged: "
            + ("speed reconstructed from the wheel speed through the fitted model (initial state from the "
               "free-rolling start); " if "v" in missing else "")
            + "effects acting on the vehicle (drag, radius, friction level) and actuator gain are less "
              "identifiable from the wheel speed alone; the verdict is less certain")


def localise(nominal: CandidateFit, chosen: CandidateFit | None, d: Data, folds: int) -> tuple[dict, dict]:
    """The report's ``where`` (segments, regimes, channels, the nominal road, the data) and the residuals for the
    plots: ``before``/``after`` (windows,) RMS normalised residual, their per-channel samples and the regime labels.

    :param chosen: the verdict's model, or None.
    :param folds: the number of cross-fitting folds.
    """
    r_ch = _by_channel(nominal.resid, d)
    residuals = {"before": np.sqrt(np.mean(nominal.resid ** 2, axis=-1)), "before_samples": r_ch}
    r_after_ch = None
    if chosen is not None:
        r_after_ch = _by_channel(chosen.resid, d)
        residuals["after"] = np.sqrt(np.mean(chosen.resid ** 2, axis=-1))
        residuals["after_samples"] = r_after_ch
    loc = _regimes(nominal, d, r_ch, r_after_ch)
    residuals["labels"] = loc["labels"]
    wm = nominal.window_mse
    order = np.argsort(-wm)[:3]
    segments = [{"t_start": float(d.t0 + d.dt * d.starts[i]), "t_end": float(d.t0 + d.dt * (d.starts[i] + d.horizon)),
                 "gap": gap_of(float(wm[i])), "held_out": True} for i in order]
    where = {
        "segments": segments,
        "regimes": loc["regimes"],
        "channels": loc["channels"],
        "fitted_peak_slip": loc["peak_slip"],
        "nominal_road": nominal.road(),
        "data": {"channels": d.channels, "samples": d.n, "windows": len(d.starts),
                 "held_out_windows": len(d.starts), "folds": int(folds), "horizon_s": d.horizon * d.dt,
                 "speed_source": "logged v (smoothed)" if d.v is not None else "reconstructed from omega",
                 "certainty": _certainty(d)},
    }
    return where, residuals


def tests_table(fits: list, significant: list, edges: dict) -> dict:
    """Per candidate: its held-out tests, robust gap, significance and the parameters at a range edge."""
    return {f.effect: {"t_stat": f.t_stat, "z": f.z, "z_paired": f.z_paired,
                       "z_without_effect": f.z_without, "robust_gap": robust_gap(f),
                       "significant": any(f is s for s in significant),
                       "at_range_edge": edges.get(f.effect, [])} for f in fits}
