"""The diagnosis of a car's session: its braking events found, the car's parameters fitted across them and held out
by event, each event's own verdict, and the spread of the car's parameters over the events.

Steps: find the events (:mod:`.events`) and say why the rest was skipped; measure each wheel's rolling radius in
free rolling (:mod:`.radius`); check ``a_x`` against the slope of ``v`` and leave a lagging or mis-scaled channel out
(:mod:`.data`); cross-fit the nominal car and select the effects forward on held-out windows (:mod:`.select`);
refit the selected set on every event for the report's parameters, and on each event alone for the spread.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from fricenv import progress
from fricenv.errors import InvalidInputError
from fricenv.gap.car.coast import coast_down
from fricenv.gap.car.config import CarConfig
from fricenv.gap.car.data import ax_agreement, ax_warning, event_data, noise_levels
from fricenv.gap.car.events import find_events, session_summary
from fricenv.gap.car.model import nominal_params
from fricenv.gap.car.pooled import HeldOut, Problem, cross_fit, fit, scheme
from fricenv.gap.car.radius import free_rolling_radii
from fricenv.gap.car.select import forward_select, gap, verdict
from fricenv.gap.car.session import CORNERS, CarParams, Session
from fricenv.plants import quarter_car as qc

__all__ = ["SessionDiagnosis", "diagnose_session", "effect_params"]

# An effect a log's provenance predicts is listed after the discoveries (a nominal pressure factor's gain).
EXPECTED = {"torque_from_pressure": "brake_gain"}


@dataclass
class SessionDiagnosis:
    """A session's diagnosis; :func:`fricenv.gap.car.report.report_dict` turns it into report.json."""

    verdict: str
    gap_before: float
    gap_after: float
    params: dict
    effects: list
    candidates: list
    where: dict
    session: Session
    events: list
    seconds: float = 0.0
    source: str = "<memory>"
    heldout: dict = field(default_factory=dict)  # "before"/"after": HeldOut


def effect_params(effect: str, x: dict, mapped: str) -> dict:
    """An effect's parameters under the registry's names (``radius_error``: the mapped wheel's radius)."""
    if effect == "radius_error":
        return {"r_eff": x[f"r_{mapped}"]}
    if effect == "brake_gain":
        return {"gain": x["gain"]}
    return {n: x[n] for n in {"drag": ("c0", "c2"), "brake_lag": ("tau",), "brake_delay": ("delay",)}[effect]}


def _problem(s: Session, car: CarParams, p: qc.QuarterCarParams, cfg: CarConfig, warnings: list):
    events, skipped = find_events(s, cfg.rules, car.wheelbase)
    if not events:
        raise InvalidInputError(f"{s.source}: no braking event (brake applied, no throttle, above "
                                f"{cfg.rules.min_speed:g} m/s for {cfg.rules.min_duration:g} s or more)")
    rolling = free_rolling_radii(s, car.wheelbase, cfg.rules)
    radii = [(rolling.radii if rolling is not None else s.radii).get(c, s.radii.get(c, p.r)) for c in CORNERS]
    coast = coast_down(s, car.effective_mass(radii), car.wheelbase, cfg.rules)
    check = ax_agreement(s, np.nan_to_num(s.v) > cfg.rules.min_speed)
    use_ax = check is not None and check["used"]
    if check is not None and not use_ax:
        warnings.append(ax_warning(check))
    data = event_data(s, events, cfg, use_ax)
    if sum(len(e.starts) for e in data) < 2 * cfg.blocks:
        raise InvalidInputError(f"{s.source}: the braking events hold {sum(len(e.starts) for e in data)} prediction "
                                f"windows of {cfg.horizon_s:g} s; need at least {2 * cfg.blocks}")
    pb = Problem(events=data, car=car, mapped=s.mapped, sigma=noise_levels(data), base=nominal_params(p.r, car, s.radii),
                 rolling=None if rolling is None else rolling.radii, cfg=cfg,
                 drag=None if coast is None else {"c0": coast.c0, "c2": coast.c2})
    return pb, events, skipped, rolling, check, coast


def _order(effects: list, s: Session) -> list:
    expected = [e for attr, e in EXPECTED.items() if getattr(s, attr, False)]
    return [e for e in effects if e not in expected] + [e for e in effects if e in expected]


def diagnose_session(s: Session, car: CarParams, p: qc.QuarterCarParams = qc.PAPER_PARAMS,
                     cfg: CarConfig | None = None) -> SessionDiagnosis:
    """Diagnose a car's session (see the module docstring).

    :raises InvalidInputError: a session without a braking event, or too short events.
    """
    t_start = time.perf_counter()
    cfg = cfg or CarConfig()
    cfg.check()
    warnings = list(s.warnings)
    pb, events, skipped, rolling, check, coast = _problem(s, car, p, cfg, warnings)
    with progress.task("fit the nominal car", total=1) as advance:
        before = cross_fit(pb, [])
        advance()
    # radii measured in free rolling, away from the nominal one beyond sig_z standard errors, are in the car
    # calibrations, in the set from the start: the radii and the drag measured outside the events (free rolling,
    # coasting) away from nominal beyond sig_z standard errors, and a nominal pressure factor's gain
    nominal_radii = {c: pb.base[f"r_{c}"] for c in CORNERS}
    calibrations = (("radius_error",) if rolling is not None and rolling.z(nominal_radii) > cfg.sig_z else ()) + \
        (("drag",) if coast is not None and coast.z > cfg.sig_z else ()) + \
        tuple(e for attr, e in EXPECTED.items() if getattr(s, attr, False))
    chosen, after, steps = forward_select(pb, before, tuple(c for c in calibrations if c in cfg.candidates))
    effects = _order(chosen, s)
    with progress.task("refit the car on every event", total=1 + len(pb.events)) as advance:
        whole = fit(pb, effects, [np.arange(len(e.starts)) for e in pb.events])
        advance()
        alone = []
        for i, e in enumerate(pb.events):
            only = Problem(events=[e], car=car, mapped=s.mapped, sigma=pb.sigma, base=pb.base, rolling=pb.rolling, drag=pb.drag,
                           cfg=cfg)
            alone.append(fit(only, effects, [np.arange(len(e.starts))], whole.x) if len(e.starts) else None)
            advance()
    g0, g1 = gap(before.all()), gap(after.all())
    v = verdict(effects, g0, g1, cfg.ratio_explained, cfg.gap_none)
    out_effects = [{"effect": e, "params": effect_params(e, whole.x, s.mapped)} for e in effects]
    where = _where(s, pb, events, skipped, rolling, check, before, after, alone, effects, whole, steps, warnings)
    where["car"]["coast_down"] = None if coast is None else coast.summary()
    return SessionDiagnosis(verdict=v, gap_before=g0, gap_after=g1 if effects else g0,
                            params=next((e["params"] for e in out_effects if e["effect"] == v), {}),
                            effects=out_effects, candidates=_candidates(pb, before, s.mapped, g0),
                            where=where, session=s, events=events, seconds=time.perf_counter() - t_start,
                            source=s.source, heldout={"before": before, "after": after})


def _candidates(pb: Problem, before: HeldOut, mapped: str, g0: float) -> list:
    """Each library effect alone on the nominal car, held out like the set, best first: its held-out gap, its
    score (the share of the nominal held-out excess error it closes) and its parameters (mean over the folds)."""
    out = []
    with progress.task("fit each effect alone", total=len(pb.cfg.candidates)) as advance:
        for e in pb.cfg.candidates:
            h = cross_fit(pb, [e], before)
            g = gap(h.all())
            params = {k: float(np.mean([effect_params(e, f.x, mapped)[k] for f in h.fits]))
                      for k in effect_params(e, h.fits[0].x, mapped)} if h.fits else {}
            out.append({"effect": e, "params": params, "gap_after": g,
                        "score": float(1.0 - g ** 2 / g0 ** 2) if g0 > 0 else 0.0})
            advance()
    return sorted(out, key=lambda c: c["gap_after"])


def _event_rows(events, pb: Problem, before: HeldOut, after: HeldOut, alone: list, effects: list, mapped: str):
    rows = []
    for i, ev in enumerate(events):
        if not len(pb.events[i].starts):
            rows.append({**ev.as_dict(), "windows": 0, "verdict": "not_diagnosed", "effects": [], "gap_before": None,
                         "gap_after": None, "slip_stiffness": None,
                         "note": ev.skip or f"no prediction window of {pb.cfg.horizon_s:g} s after the drive "
                                            "settled"})
            continue
        g0, g1 = gap(before.mse[i]), gap(after.mse[i])
        f = alone[i]
        rows.append({**ev.as_dict(), "windows": len(pb.events[i].starts),
                     "verdict": verdict(effects, g0, g1, pb.cfg.ratio_explained, pb.cfg.gap_none),
                     "effects": [] if f is None else [{"effect": e, "params": effect_params(e, f.x, mapped)}
                                                       for e in effects],
                     "gap_before": g0, "gap_after": g1 if effects else g0,
                     "slip_stiffness": None if f is None else float(f.stiffness[0])})
    return rows


def _spread(alone: list, effects: list, mapped: str) -> dict:
    """Each shared parameter over the events fitted alone: per event, mean, std, min, max."""
    out = {}
    fits = [f for f in alone if f is not None]
    for e in effects:
        for name in effect_params(e, fits[0].x, mapped) if fits else {}:
            vals = np.array([effect_params(e, f.x, mapped)[name] for f in fits])
            out[f"{e}.{name}"] = {"per_event": vals.tolist(), "mean": float(vals.mean()),
                                  "std": float(vals.std(ddof=1)) if len(vals) > 1 else 0.0,
                                  "min": float(vals.min()), "max": float(vals.max())}
    return out


def _car(pb: Problem, whole, rolling) -> dict:
    radii = rolling.radii if rolling is not None else {c: whole.x[f"r_{c}"] for c in pb.corners()}
    out = {f"r_eff_{c}": radii[c] for c in CORNERS if c in radii}
    out.update({"radius_source": "free rolling" if rolling is not None else "events fit",
                "mapped_wheel": pb.mapped, "brake_balance": whole.x["balance"], "mass": pb.car.mass,
                "lf": pb.car.lf, "lr": pb.car.lr})
    if rolling is not None:
        out["free_rolling"] = rolling.summary({c: pb.base[f"r_{c}"] for c in CORNERS})
    return out


def _where(s, pb, events, skipped, rolling, check, before, after, alone, effects, whole, steps, warnings) -> dict:
    return {"time_base": {"origin": "first_sample", "offset_s": s.t_offset},
            "warnings": list(warnings),
            "session": session_summary(s, events, pb.cfg.rules),
            "events": _event_rows(events, pb, before, after, alone, effects, s.mapped),
            "skipped": skipped,
            "event_spread": _spread(alone, effects, s.mapped),
            "car": _car(pb, whole, rolling),
            "held_out": {"scheme": scheme(pb), "windows": int(sum(len(e.starts) for e in pb.events)),
                         "horizon_s": pb.events[0].horizon * s.dt},
            "noise_std": dict(pb.sigma),
            "a_x_check": check,
            "forward_selection": steps}
