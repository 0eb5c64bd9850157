"""What a quarter-car log excites: the :class:`fricenv.effects.registry.Excitation` of a log and
the candidates it cannot test, by each effect's registry rule and by the size it would need to show above the noise
(:mod:`fricenv.gap.quarter_car.detectability`), so that a verdict of ``none`` is not read as "no effect" where the log could not
have shown one."""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np

from fricenv.effects import registry
from fricenv.effects.registry import Excitation
from fricenv.gap.quarter_car.config import DEFAULT_CONFIG
from fricenv.gap.quarter_car.data import Data
from fricenv.gap.quarter_car.detectability import detectability
from fricenv.gap.quarter_car.localise import APPLY_RATE
from fricenv.gap.quarter_car.stats import CandidateFit
from fricenv.gap.quarter_car.windows import FREE_ROLL_TORQUE, model_batch, speed_states
from fricenv.plants.tire import MagicFormula, longitudinal_slip

__all__ = ["NEAR_PEAK", "SLIP_TRANSIENT", "LogExcitation", "NotTestable", "excitation", "torque_events",
           "untestable"]

SLIP_TRANSIENT = 0.03  # slip change within one window that counts as a transient [-]
# Near the friction peak: friction at or above this share of the fitted road's largest. In slip terms that is about
# 0.7 times the peak slip on the dry, wet and ice presets (0.98, 0.965, 0.983 of the peak friction there); a share of
# the peak SLIP meant nothing on a road whose curve rises to slip 1 (the snow preset: 95 % of its friction at slip
# 0.1, its "peak" at 1), where a friction change was never testable [-]
NEAR_PEAK = 0.965
MIN_EVENT_SAMPLES = 2  # samples of fast torque change that make one apply/release event [-]
MIN_EVENT_CHANGE = 0.1  # torque change of one apply/release event, as a share of the largest |T_b| [-]


def torque_events(Tb: np.ndarray, dt: float) -> int:
    """Brake apply and release events of a logged torque: maximal runs of fast change (``|dT_b/dt|`` above
    ``APPLY_RATE`` of the largest torque per second) in one direction, each at least
    ``MIN_EVENT_SAMPLES`` samples long and moving the torque by ``MIN_EVENT_CHANGE`` of its largest value.

    An apply followed at once by a release (an ABS cycle, with no hold between) is two events: the direction
    change separates them. Counting runs of fast change regardless of direction made a whole ABS braking one event,
    and counting only samples with braking torque cut a step from zero to one sample (no event). Noise cannot make
    an event: it moves the torque by far less than ``MIN_EVENT_CHANGE``.
    """
    Tb = np.asarray(Tb, dtype=float)
    tmax = max(float(np.max(np.abs(Tb))), 1e-9) if Tb.size else 1e-9
    dT = np.gradient(Tb, dt) if Tb.size >= 2 else np.zeros_like(Tb)
    sign = np.where(np.abs(dT) > APPLY_RATE * tmax, np.sign(dT), 0.0).astype(int)
    cuts = np.flatnonzero(np.diff(np.concatenate([[0], sign, [0]])) != 0)
    events = 0
    for a, b in pairwise(cuts):
        change = abs(Tb[min(b, Tb.size - 1)] - Tb[max(a - 1, 0)])
        events += int(sign[a] != 0 and b - a >= MIN_EVENT_SAMPLES and change >= MIN_EVENT_CHANGE * tmax)
    return events


@dataclass(frozen=True)
class LogExcitation(Excitation):
    """A log's :class:`Excitation` and, per effect the registry rules let through, its power analysis
    (:class:`fricenv.gap.quarter_car.detectability.Detectability`)."""

    detectable: dict = field(default_factory=dict)


class NotTestable(dict):
    """``{effect: reason}`` of the candidates a log cannot show; ``detectable`` holds, per analysed effect,
    ``{param: smallest detectable |param - off|}`` (the report's ``where["detectable"]``), ``caveats`` per tested
    effect what its test rests on where the log shows it only in part (``where["caveats"]``)."""

    detectable: dict
    caveats: dict
    below_noise: tuple

    def __init__(self, reasons: dict, detectable: dict, caveats: dict | None = None, below_noise=()):
        super().__init__(reasons)
        self.detectable = detectable
        self.caveats = caveats or {}
        self.below_noise = tuple(below_noise)  # the effects only the power analysis rules out (still fitted)

    def __reduce__(self):  # pickled for the worker processes like the plain dict it extends
        return NotTestable, (dict(self), self.detectable, self.caveats, self.below_noise)

    def shown(self, effects) -> NotTestable:
        """These reasons less the effects among ``effects`` that the power analysis rated below noise and the fits
        showed after all (significant, or selected): the analysis is linearised at the nominal road, and an effect
        that moves a wheel lock-up acts on the data nonlinearly. Each gets a caveat saying so."""
        found = [e for e in self.below_noise if e in effects]
        caveats = {**self.caveats, **{e: f"rated below noise by the power analysis ({self[e]}), yet significant "
                                         "on held-out data" for e in found}}
        return NotTestable({e: r for e, r in self.items() if e not in found}, self.detectable, caveats,
                           [e for e in self.below_noise if e not in found])


def excitation(nominal: CandidateFit, d: Data, sig_z: float = DEFAULT_CONFIG.sig_z) -> LogExcitation:
    """The log's excitation, with the speed and slip of the calibrated nominal model, and the power analysis of the
    effects its registry rules let through, at the verdict's significance threshold ``sig_z``."""
    rows = d.starts[:, None] + np.arange(d.horizon)[None, :]
    vhat = speed_states(model_batch([], nominal.names, nominal.x, d.p), d)[0]
    lam = np.clip(longitudinal_slip(vhat, d.omega, d.p.r), -1.0, 1.0)
    tmax = max(float(np.max(np.abs(d.Tb))), 1e-9)
    braking = np.abs(d.Tb) > FREE_ROLL_TORQUE * tmax
    braking_w = np.any(braking[rows], axis=1)
    lam_w = lam[rows]
    transient = braking_w & (np.ptp(lam_w, axis=1) > SLIP_TRANSIENT)
    road = MagicFormula(**nominal.road())
    near = braking_w & (np.max(road.mu(lam_w), axis=1) >= NEAR_PEAK * road.mu_max)
    # halves of the braking (not of the log: the free-rolling start would fill most of the early half of a short log)
    brake_idx = np.flatnonzero(braking_w)
    half = int(brake_idx[brake_idx.size // 2]) if brake_idx.size else len(d.starts) // 2
    v_brake = vhat[braking]
    k = int(np.max(d.fold)) + 1
    x = Excitation(has_v=d.v is not None, has_a_x=d.a_x is not None, braking_windows=int(np.sum(braking_w)),
                   torque_transients=torque_events(d.Tb, d.dt), slip_transient_windows=int(np.sum(transient)),
                   near_peak_early=int(np.sum(near[:half])), near_peak_late=int(np.sum(near[half:])),
                   speed_range=float(np.ptp(v_brake)) if v_brake.size else 0.0,
                   training_windows=int(min(np.sum(d.fold != j) for j in range(k))))
    excited = [e for e in registry.effects_in_library() if registry.get(e).testable(x) is None]
    return LogExcitation(**vars(x), detectable=detectability(nominal, d, excited, sig_z))


def untestable(effects, x: Excitation) -> NotTestable:
    """The effects among ``effects`` the log cannot show, each with the reason: the registry's testability rule,
    then (a :class:`LogExcitation`) the power analysis, "below noise" when no plausible size would be significant;
    and the registry's caveats of the others."""
    power = getattr(x, "detectable", {})
    out, below = {}, []
    for e in effects:
        reason = registry.get(e).testable(x)
        if reason is None and e in power and (reason := power[e].reason()) is not None:
            below.append(e)
        if reason is not None:
            out[e] = reason
    caveats = {e: why for e in effects if e not in out and registry.get(e).caveat is not None
               and (why := registry.get(e).caveat(x)) is not None}
    return NotTestable(out, {e: power[e].min_detectable for e in effects if e in power}, caveats, below)
