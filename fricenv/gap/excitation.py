"""What a quarter-car log excites (issue 15 item 3): the :class:`fricenv.effects.registry.Excitation` of a log and
the candidates it cannot test, by each effect's registry rule, so that a verdict of ``none`` is not read as "no
effect" where the log could not have shown one."""

from __future__ import annotations

import numpy as np

from fricenv.effects import registry
from fricenv.effects.registry import Excitation
from fricenv.gap.localise import APPLY_RATE
from fricenv.gap.stats import CandidateFit
from fricenv.gap.windows import FREE_ROLL_TORQUE, Data, model_batch, speed_states
from fricenv.plants.tire import MagicFormula, longitudinal_slip

__all__ = ["NEAR_PEAK", "SLIP_TRANSIENT", "excitation", "untestable"]

SLIP_TRANSIENT = 0.03  # slip change within one window that counts as a transient [-]
NEAR_PEAK = 0.7  # slip above this share of the fitted road's peak slip counts as near the peak [-]
MIN_EVENT_SAMPLES = 2  # samples of fast torque change that make one apply/release event [-]


def _events(fast: np.ndarray) -> int:
    """Runs of at least ``MIN_EVENT_SAMPLES`` consecutive True samples."""
    edges = np.diff(np.concatenate([[0], fast.astype(int), [0]]))
    lengths = np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)
    return int(np.count_nonzero(lengths >= MIN_EVENT_SAMPLES))


def excitation(nominal: CandidateFit, d: Data) -> Excitation:
    """The log's excitation, with the speed and slip of the calibrated nominal model."""
    rows = d.starts[:, None] + np.arange(d.horizon)[None, :]
    vhat = speed_states(model_batch([], nominal.names, nominal.x, d.p), d)[0]
    lam = np.clip(longitudinal_slip(vhat, d.omega, d.p.r), -1.0, 1.0)
    tmax = max(float(np.max(np.abs(d.Tb))), 1e-9)
    braking = np.abs(d.Tb) > FREE_ROLL_TORQUE * tmax
    fast = braking & (np.abs(np.gradient(d.Tb, d.dt)) > APPLY_RATE * tmax)
    braking_w = np.any(braking[rows], axis=1)
    lam_w = lam[rows]
    transient = braking_w & (np.ptp(lam_w, axis=1) > SLIP_TRANSIENT)
    peak = MagicFormula(**nominal.road()).peak_slip
    near = braking_w & (np.max(lam_w, axis=1) > NEAR_PEAK * peak)
    half = len(d.starts) // 2
    v_brake = vhat[braking]
    k = int(np.max(d.fold)) + 1
    return Excitation(has_v=d.v is not None, has_a_x=d.a_x is not None, braking_windows=int(np.sum(braking_w)),
                      torque_transients=_events(fast), slip_transient_windows=int(np.sum(transient)),
                      near_peak_early=int(np.sum(near[:half])), near_peak_late=int(np.sum(near[half:])),
                      speed_range=float(np.ptp(v_brake)) if v_brake.size else 0.0,
                      training_windows=int(min(np.sum(d.fold != j) for j in range(k))))


def untestable(effects, x: Excitation) -> dict[str, str]:
    """The effects among ``effects`` the log cannot show, each with the reason (the registry's testability rule)."""
    out = {}
    for e in effects:
        reason = registry.get(e).testable(x)
        if reason is not None:
            out[e] = reason
    return out
