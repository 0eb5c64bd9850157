"""Braking events of a car's session: every run of the brake applied with no throttle, above the speed floor, for at
least the shortest duration, is found; every other braking stretch is skipped with its reason."""

import numpy as np
import pytest

from fricenv.errors import InvalidInputError
from fricenv.gap.car.events import EventRules, applied, find_events, runs
from fricenv.gap.car.session import CarParams, Session, load_car_params

DT = 0.04


def _session(n=2000, **kw) -> Session:
    t = np.arange(n) * DT
    base = {"t": t, "T_b": np.zeros(n), "v": np.full(n, 15.0), "wheels": {"fl": np.full(n, 15.0 / 0.33)},
            "mapped": "fl", "throttle": np.full(n, 20.0), "yaw_rate": np.zeros(n)}
    base.update(kw)
    return Session(**base)


def _brake(s: Session, t0: float, t1: float, level=300.0, throttle=0.0, yaw=None):
    k = (s.t >= t0 - 1e-9) & (s.t < t1 - 1e-9)
    s.T_b[k] = level
    s.throttle[k] = throttle
    if yaw is not None:
        s.yaw_rate[k] = yaw
    return k


def test_runs_gives_start_stop_pairs():
    assert runs(np.array([0, 1, 1, 0, 1], bool)) == [(1, 3), (4, 5)]
    assert runs(np.zeros(3, bool)) == []


def test_applied_reads_a_rest_level_above_zero():
    x = np.r_[np.full(90, 50.0), np.full(10, 900.0)]  # a sensor resting at 50 kPa
    assert applied(x, np.ones(100, bool), 1e-3).sum() == 10


def test_every_event_of_one_second_or_more_is_found_and_the_rest_skipped_with_why():
    s = _session()
    _brake(s, 4.0, 5.0)  # exactly 1 s: an event
    _brake(s, 10.0, 10.96)  # 0.96 s: too short
    _brake(s, 20.0, 23.0, throttle=5.0)  # with throttle: not an event
    _brake(s, 30.0, 33.0, yaw=0.5)  # 7.5 m/s^2 lateral: cornering, found and not diagnosed
    k = _brake(s, 40.0, 44.0)
    s.v[k] = np.linspace(15.0, 3.0, k.sum())  # crosses the floor: the event ends there
    events, skipped = find_events(s, EventRules(), 2.98)
    assert [round(e.t_start, 2) for e in events] == [4.0, 30.0, 40.0]
    assert round(events[0].t_end - events[0].t_start + DT, 2) == 1.0
    assert events[1].skip.startswith("cornering") and events[0].skip is None  # found, not diagnosed
    assert events[2].v_end > 5.0 and events[2].stop < np.flatnonzero(k)[-1]
    reasons = {round(x["t_start"]): x["reason"] for x in skipped}
    assert reasons[10].startswith("shorter than 1 s")
    assert reasons[20] == "throttle applied"
    assert any(x["reason"].startswith("slower than 5") and x["t_start"] > 40 for x in skipped)


def test_a_braking_run_that_turns_into_a_corner_keeps_its_straight_part_as_an_event():
    s = _session()
    _brake(s, 4.0, 8.0)
    s.yaw_rate[(s.t >= 6.4 - 1e-9) & (s.t < 8.0 - 1e-9)] = 0.5  # 7.5 m/s^2 lateral from 6.4 s: the turn-in
    _brake(s, 20.0, 23.0)
    s.yaw_rate[(s.t >= 20.4 - 1e-9) & (s.t < 22.2 - 1e-9)] = 0.5  # straight 0.4 s, corner 1.8 s, straight 0.8 s
    events, skipped = find_events(s, EventRules(), 2.98)
    assert [(round(e.t_start, 2), round(e.t_end + DT, 2), e.skip) for e in events] == [(4.0, 6.4, None),
                                                                                       (20.0, 23.0, events[1].skip)]
    assert events[1].skip.startswith("cornering")  # no straight part of 1 s: found, not diagnosed
    corner = [x for x in skipped if x["reason"].startswith("cornering")]
    assert [(round(x["t_start"], 2), round(x["t_end"] + DT, 2)) for x in corner] == [(6.4, 8.0)]
    assert "7.50 m/s^2 > 6" in corner[0]["reason"]


def test_an_event_is_split_by_a_throttle_blip():
    s = _session()
    _brake(s, 4.0, 8.0)
    s.throttle[(s.t >= 5.96) & (s.t < 6.04)] = 3.0
    events, skipped = find_events(s, EventRules(), 2.98)
    assert len(events) == 2 and any(x["reason"] == "throttle applied" for x in skipped)


def test_car_section_of_params(tmp_path):
    f = tmp_path / "p.json"
    f.write_text('{"r": 0.33, "car": {"mass": 790.0, "lf": 1.248, "lr": 1.7328}}')
    p, car = load_car_params(f)
    assert p.r == 0.33 and car == CarParams(790.0, 1.248, 1.7328)
    assert car.front_share == pytest.approx(1.7328 / 2.9808)
    f.write_text('{"r": 0.33, "car": {"mass": 790.0, "lf": 1.248}}')
    with pytest.raises(InvalidInputError, match="missing lr"):
        load_car_params(f)
    f.write_text('{"r": 0.33, "car": {"mass": 790.0, "lf": 1.248, "lr": 1.7, "cg": 1}}')
    with pytest.raises(InvalidInputError, match="unknown key"):
        load_car_params(f)


def test_session_of_finds_the_mapped_corner_and_the_maps_radii():
    import types

    from fricenv.gap.car.model import nominal_params
    from fricenv.gap.car.session import session_of

    n = 50
    w = {c: np.full(n, 40.0 + i) for i, c in enumerate(("fl", "fr", "rl", "rr"))}
    log = types.SimpleNamespace(t=np.arange(n) * DT, T_b=np.zeros(n), v=np.full(n, 13.0), omega=w["rl"].copy(),
                                **{f"omega_{c}": x for c, x in w.items()}, radii={"omega": 0.34, "omega_fl": 0.33})
    s = session_of(log, CarParams(790.0, 1.248, 1.7328))
    assert s.mapped == "rl" and s.radii == {"fl": 0.33, "rl": 0.34}
    x = nominal_params(0.3, CarParams(790.0, 1.248, 1.7328), s.radii)
    assert (x["r_fl"], x["r_fr"], x["r_rl"]) == (0.33, 0.3, 0.34)


def test_a_noisy_resting_sensor_is_not_a_brake():
    rng = np.random.default_rng(0)
    x = 30.0 + 2.0 * rng.standard_normal(1000)  # a pressure sensor resting at 30 kPa with 2 kPa of noise
    x[500:520] = 400.0
    on = applied(x, np.ones(1000, bool), 1e-6)
    assert on[500:520].all() and on.sum() <= 22
    assert applied(np.r_[np.zeros(99), 1e-3], np.ones(100, bool), 1e-6)[-1]  # a command resting at exactly 0


def test_an_event_right_after_the_throttle_is_fitted_once_the_drive_settled():
    s = _session()
    _brake(s, 10.0, 13.0)
    s.throttle[(s.t >= 3.0) & (s.t < 10.0)] = 0.0  # coasting before the brake
    _brake(s, 20.0, 23.0)  # the throttle held up to the brake
    (a, b), _ = find_events(s, EventRules(drive_settle=0.6), 2.98)
    assert a.fit_start == a.start
    assert b.fit_start - b.start == 15 and b.t_start == pytest.approx(20.0)
