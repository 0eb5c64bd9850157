"""The braking events of a car's session: runs of samples with the brake applied, no drive, fast enough, lasting
long enough; those on a path straight enough are diagnosed, the others found and reported with why; and why every
other braking stretch was skipped.

A brake is applied when ``T_b`` is above its resting level (the 1st percentile over the moving samples: a pedal at
rest is its lowest reading) by more than its resting noise (:func:`applied`); the same rule with ``throttle`` finds a
drive. The path is straight enough when the lateral acceleration ``v |yaw rate|`` (else ``v^2 |steer| / L``)
stays below ``max_lateral`` [m/s^2] over the event. A braking run that turns into a corner (a road course's braking
zone ends in a turn-in) keeps each straight part of ``min_duration`` or more as an event, and its cornering part is
skipped with why; a run without such a part is one event, found and not diagnosed.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from fricenv.gap.car.session import Session

REST_PERCENTILE = 1.0  # a pedal's or a line's resting level: this percentile of its moving samples [%]
REST_BAND = 0.05  # samples within this share of the largest excursion above rest give the resting noise [-]
REST_SIGMAS = 4.0  # applied: above the resting level by this many resting noise std [-]

__all__ = ["Event", "EventRules", "applied", "find_events", "lateral_acceleration", "runs", "session_summary"]


@dataclass(frozen=True)
class EventRules:
    """What makes a braking event (thresholds in SI units)."""

    min_speed: float = 5.0  # fast enough [m/s]
    min_duration: float = 1.0  # long enough [s]
    brake_share: float = 1e-6  # applied: above rest by at least this share of the largest excursion [-]
    throttle_share: float = 1e-6  # a drive: the same for the throttle [-]
    # straight enough: lateral acceleration below this [m/s^2]; beyond, combined slip leaves the longitudinal model
    max_lateral: float = 6.0
    # the drive's torque outlasts its command: an event is fitted from this long after the last drive sample [s]
    # (this car's deceleration reaches 90 % of its coasting level about 0.6 s after a throttle release)
    drive_settle: float = 0.6


DEFAULT_RULES = EventRules()


@dataclass(frozen=True)
class Event:
    """One braking event: samples ``start`` to ``stop`` (exclusive) of the session; the model is fitted from
    ``fit_start`` on (the drive settled)."""

    index: int
    start: int
    stop: int
    t_start: float
    t_end: float
    v_start: float
    v_end: float
    max_lateral: float
    fit_start: int
    t_fit_start: float
    skip: str | None = None  # why the event is found but not diagnosed (cornering), None when it is

    def as_dict(self) -> dict:
        return {"t_start": self.t_start, "t_end": self.t_end, "v_start": self.v_start, "v_end": self.v_end,
                "max_lateral_accel": self.max_lateral, "t_fit_start": self.t_fit_start}


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """The (start, stop) index pairs of the True runs of ``mask``."""
    m = np.diff(np.r_[0, np.asarray(mask, dtype=np.int8), 0])
    return list(zip(np.flatnonzero(m == 1).tolist(), np.flatnonzero(m == -1).tolist()))


def applied(x: np.ndarray, moving: np.ndarray, share: float) -> np.ndarray:
    """Samples where ``x`` is above its resting level by more than ``REST_SIGMAS`` times its resting noise and at
    least ``share`` of its largest excursion. The resting samples are the ``moving`` ones (else all) within
    ``REST_BAND`` of the largest excursion above their ``REST_PERCENTILE``; their median is the level and 1.4826 times
    their median absolute deviation the noise. A command that rests at exactly zero is applied at any positive
    value."""
    x = np.nan_to_num(np.asarray(x, dtype=float), nan=-np.inf)
    finite = np.isfinite(x)
    base = x[moving & finite] if np.any(moving & finite) else x[finite]
    low = float(np.percentile(base, REST_PERCENTILE)) if base.size else 0.0
    top = float(np.max(x[finite])) - low if np.any(finite) else 0.0
    if top <= 0:
        return np.zeros(len(x), dtype=bool)
    near = base[base <= low + REST_BAND * top]
    rest = float(np.median(near)) if near.size else low
    noise = 1.4826 * float(np.median(np.abs(near - rest))) if near.size else 0.0
    return x > rest + max(REST_SIGMAS * noise, share * top)


def lateral_acceleration(s: Session, wheelbase: float | None) -> np.ndarray:
    """The lateral acceleration [m/s^2] from the yaw rate, else the steering angle, else zeros."""
    if s.yaw_rate is not None:
        return np.abs(s.v * np.nan_to_num(s.yaw_rate))
    if s.steer is not None and wheelbase:
        return s.v ** 2 * np.abs(np.nan_to_num(s.steer)) / wheelbase
    return np.zeros(len(s))


def _states(s: Session, rules: EventRules) -> dict:
    moving = np.nan_to_num(s.v) > rules.min_speed
    brake = applied(s.T_b, moving, rules.brake_share)
    drive = applied(s.throttle, moving, rules.throttle_share) if s.throttle is not None else np.zeros(len(s), bool)
    return {"moving": moving, "brake": brake, "drive": drive}


def find_events(s: Session, rules: EventRules = DEFAULT_RULES, wheelbase: float | None = None):
    """The braking events of a session, and the braking stretches skipped with why.

    :return: (events, skipped): an event too far from straight has ``skip`` set (found, not diagnosed);
        ``skipped`` is a list of ``{"t_start", "t_end", "reason"}`` (times relative to the first sample) covering
        every sample with the brake applied that is in no event.
    """
    st = _states(s, rules)
    lat = lateral_acceleration(s, wheelbase)
    t = s.t - s.t[0]
    drive_at = np.flatnonzero(st["drive"])
    settle = int(np.ceil(rules.drive_settle / s.dt - 1e-9))
    events, skipped = [], []
    in_event = np.zeros(len(s), dtype=bool)
    for a, b in runs(st["brake"] & ~st["drive"] & st["moving"]):
        duration = (b - a) * s.dt
        if duration < rules.min_duration - 1e-9:
            skipped.append(_skip(t, a, b, f"shorter than {rules.min_duration:g} s ({duration:.2f} s)"))
        else:
            parts = _straight_parts(lat[a:b] <= rules.max_lateral, s.dt, rules.min_duration)
            for x, y in parts or [(0, b - a)]:  # no straight part of min_duration: the whole run, not diagnosed
                events.append(_event(len(events), s, t, lat, a + x, a + y, drive_at[drive_at < a + x], settle,
                                     rules))
            kept = np.zeros(b - a, dtype=bool)
            for x, y in parts:
                kept[x:y] = True
            for x, y in runs(~kept) if parts else []:
                top = float(np.max(lat[a + x:a + y]))
                reason = (f"cornering: lateral acceleration {top:.2f} m/s^2 > {rules.max_lateral:g}" if
                          top > rules.max_lateral else
                          f"shorter than {rules.min_duration:g} s ({(y - x) * s.dt:.2f} s) beside cornering")
                skipped.append(_skip(t, a + x, a + y, reason))
        in_event[a:b] = True
    for a, b in runs(st["brake"] & ~in_event):
        why = np.where(st["drive"][a:b], 0, 1)  # what is left: a drive, or too slow
        for k, (x, y) in _split(why):
            reason = ("throttle applied", f"slower than {rules.min_speed:g} m/s")[k]
            skipped.append(_skip(t, a + x, a + y, reason))
    skipped.sort(key=lambda r: r["t_start"])
    return events, skipped


def _event(index: int, s: Session, t: np.ndarray, lat: np.ndarray, a: int, b: int, drives_before: np.ndarray,
           settle: int, rules: EventRules) -> Event:
    """The event of samples ``a`` to ``b`` (``t`` the times from the first sample): fitted from ``settle`` samples after
    the last drive before it; marked cornering (found, not diagnosed) when its lateral acceleration exceeds
    ``max_lateral``."""
    top = float(np.max(lat[a:b]))
    fit_start = min(max(a, int(drives_before[-1]) + 1 + settle if drives_before.size else a), b - 1)
    corner = (f"cornering: lateral acceleration {top:.2f} m/s^2 > {rules.max_lateral:g}, outside the longitudinal "
              "model") if top > rules.max_lateral else None
    return Event(index, a, b, float(t[a]), float(t[b - 1]), float(s.v[a]), float(s.v[b - 1]), top, fit_start,
                 float(t[fit_start]), corner)


def _straight_parts(straight: np.ndarray, dt: float, min_duration: float) -> list[tuple[int, int]]:
    """The runs of ``straight`` (a braking run's samples, ``dt`` apart) that last ``min_duration`` or more, by the
    rule that makes a braking run long enough: [(0, n)] for a run straight throughout, [] when no straight part is
    long enough."""
    return [(x, y) for x, y in runs(straight) if (y - x) * dt >= min_duration - 1e-9]


def _split(codes: np.ndarray):
    """(code, (start, stop)) of the constant runs of ``codes``."""
    edges = np.flatnonzero(np.diff(codes)) + 1
    bounds = np.r_[0, edges, len(codes)]
    return [(int(codes[x]), (int(x), int(y))) for x, y in pairwise(bounds)]


def _skip(t: np.ndarray, a: int, b: int, reason: str) -> dict:
    return {"t_start": float(t[a]), "t_end": float(t[b - 1]), "reason": reason}


def session_summary(s: Session, events: list, rules: EventRules = DEFAULT_RULES) -> dict:
    """Seconds of the session by state: standing or slow, driving, braking in an event, braking skipped, coasting."""
    st = _states(s, rules)
    in_event = np.zeros(len(s), dtype=bool)
    for e in events:
        in_event[e.start:e.stop] = True
    slow = ~st["moving"]
    drive = st["moving"] & st["drive"]
    skipped = st["brake"] & ~in_event & ~slow & ~drive
    coast = st["moving"] & ~st["brake"] & ~st["drive"]
    return {"duration_s": float(len(s) * s.dt), "events": len(events),
            "seconds": {name: float(np.count_nonzero(m) * s.dt) for name, m in
                        (("slow", slow & ~in_event), ("driving", drive), ("braking_events", in_event),
                         ("braking_skipped", skipped), ("coasting", coast))}}
