"""Whether a payload log's data show its answer: the true model, at its TRUE parameters (no fit) and with the TRUE
noise levels the source drew (not the tool's estimate), put through the diagnosis' own significance test against
the nominal model the tool fitted (its pose-wrench shift included).

The noise levels are given per raw column as the white-noise standard deviation at the log's rate that carries the
same power in the diagnosis' band (a slower camera or a low-passed sensor folded to that rate, see
:func:`equivalent_white`); they go through the diagnosis' own propagation (:func:`fricenv.gap.payload.data.
residual_noise`). A nominal log always counts as shown (the answer ``none`` needs no evidence).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

__all__ = ["equivalent_white", "payload_shown", "true_prediction"]


def equivalent_white(std: float, drawn_rate_hz: float, log_rate_hz: float) -> float:
    """The white std at ``log_rate_hz`` with the in-band density of white noise of ``std`` drawn at
    ``drawn_rate_hz`` (a sensor sampled faster and low-passed, or a camera slower than the log): ``std *
    sqrt(log_rate / drawn_rate)``."""
    return float(std * np.sqrt(log_rate_hz / drawn_rate_hz))


def true_prediction(d, truth: dict) -> np.ndarray:
    """The model's filtered generalised force at the true effect parameters, on the prepared log ``d``.

    :param truth: ``S`` (3x3, default the known S), ``rate`` [1/s] (over the time since the first sample),
        ``offset`` (M0, fx0, fy0), ``shift`` [s] (the pose behind the wrench: a vision delay minus the F/T's own
        lag), ``damping_force`` ((n, 3) viscous generalised force on the log's rows, out of library) -- each
        optional.
    """
    from fricenv.gap.payload.data import generalised_force_map, lowpass

    shift = float(truth.get("shift", 0.0))
    w = d.w_hat
    if shift != 0.0:
        w = np.column_stack([np.interp(d.t - shift, d.t, d.w_hat[:, k]) for k in range(3)])
    w = w - np.asarray(truth.get("offset", (0.0, 0.0, 0.0)), dtype=float)
    S = np.asarray(truth.get("S", d.S_known), dtype=float)
    scale = 1.0 + float(truth.get("rate", 0.0)) * (d.t - d.t[0])
    force = np.einsum("nij,jk,nk->ni", generalised_force_map(d.theta_f, d.p), S, w) * scale[:, None]
    if truth.get("damping_force") is not None:
        force = force - np.asarray(truth["damping_force"], dtype=float)
    return lowpass(d.sos, force)


def payload_shown(dg, truth: dict, true_raw: dict[str, float], n_params: int, cfg=None) -> bool:
    """Whether the true model passes the diagnosis' significance test against the fitted nominal model.

    :param dg: the log's :class:`fricenv.gap.payload.diagnose.PayloadDiagnosis`.
    :param truth: see :func:`true_prediction`.
    :param true_raw: the true noise std per raw column (``M, f_x, f_y, theta, X, Y``), white at the log's rate.
    :param n_params: the parameters the tool's candidate for this effect fits (its ranking penalty).
    :param cfg: the diagnosis settings (default the tool's).
    """
    from fricenv.gap.payload.data import DEFAULT_PAYLOAD_CONFIG, residual_noise
    from fricenv.gap.payload.diagnose import improvement_z, score_prediction

    cfg = cfg or DEFAULT_PAYLOAD_CONFIG
    d = dg.data
    sigma, rho2 = residual_noise(true_raw, d.theta_f, d.S_known, d.p, d.sos, d.dt, d.y, cfg.cutoff_hz)
    dt_ = replace(d, sigma=sigma, rho2=rho2)
    nominal_pred = d.y - dg.nominal.residual * d.sigma
    nominal = score_prediction("nominal", 0, nominal_pred, dt_)
    true = score_prediction("truth", n_params, true_prediction(d, truth), dt_)
    z = improvement_z(nominal, true, dt_)
    return bool(z > cfg.sig_z and true.penalised < nominal.penalised)
