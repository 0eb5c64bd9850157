"""Where a payload log's gap lies (report ``where``): the worst time blocks, the gap by regime (angular rate,
wrench size, half of the log) and by channel, with times relative to the log's first sample."""

from __future__ import annotations

import numpy as np

from fricenv.gap.core.noise import gap_of
from fricenv.gap.payload.data import CHANNELS, PayloadData, generalised_force_map

__all__ = ["where_gap"]


def where_gap(d: PayloadData, nominal, chosen, t_offset: float = 0.0) -> dict:
    """Where the nominal model misses: the worst blocks, the gap by regime and by channel, and the time base.

    Times are relative to the log's first sample; ``time_base = {"origin": "first_sample", "offset_s": ...}``
    gives that sample's time in the log's own clock (its time column plus the reader's ``t_offset``, if any).

    :param d: the prepared log; :param nominal: the nominal fit; :param chosen: the verdict's fit or None.
    :param t_offset: the log's ``t_offset`` [s] (the time its reader took off the time column; 0 if none).
    """
    scored = d.block >= 0
    G = generalised_force_map(d.theta_f, d.p)
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
        segments.append({"t_start": float(d.t[idx[0]] - d.t[0]), "t_end": float(d.t[idx[-1]] - d.t[0]),
                         "gap": gap_of(float(nominal.block_mse[b])), "held_out": bool(d.block_test[b])})
    time_base = {"origin": "first_sample", "offset_s": float(t_offset) + float(d.t[0])}
    return {"segments": segments, "regimes": regimes, "channels": channels, "labels": labels, "time_base": time_base}
