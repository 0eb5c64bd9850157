"""The car's parameters pooled over the events of simulated sessions (tests/gap/car_sim.py: four wheels with their
inertia and a Pacejka tire, integrated independently of the diagnosis' quasi-static model): the shared brake gain,
radius and drag are recovered, held out by event from three events on and by blocks below."""

import json
import types

import gymnasium as gym
import numpy as np
import pytest

import fricenv  # noqa: F401  (registers the envs)
from fricenv.gap.car.config import CarConfig
from fricenv.gap.car.diagnose import diagnose_session
from fricenv.gap.car.report import write_session_report
from fricenv.gap.car.session import CarParams, session_of
from fricenv.gap.core.report import REPORT_KEYS
from fricenv.plants import quarter_car as qc
from tests.gap import car_sim

GAIN = 1.4  # the true brake torque over the map's nominal factor
CAR = CarParams(car_sim.MASS, car_sim.LF, car_sim.LR, wheel_inertia=car_sim.J, brake_balance=car_sim.FRONT_SHARE)
CFG = CarConfig(candidates=("brake_gain", "radius_error", "drag", "brake_lag"))
P = qc.QuarterCarParams(r=0.33)


@pytest.fixture(scope="module")
def session():
    log, segs = car_sim.simulate(brakes=(1.2e6, 0.8e6, 1.5e6), gain=GAIN, seed=3, drive=5.0, coast=3.0, hold=2.0)
    return log, segs


@pytest.fixture(scope="module")
def three(session):
    return diagnose_session(session_of(session[0], CAR), CAR, P, CFG)


def _cut(log, t_end: float):
    keep = log.t < t_end
    return types.SimpleNamespace(**{k: (v[keep] if isinstance(v, np.ndarray) and v.shape == log.t.shape else v)
                                    for k, v in vars(log).items()})


def _drag(c0, c2, v=15.0):
    return c0 + c2 * v * v


def test_three_events_recover_the_cars_shared_parameters(three):
    dg = three
    assert dg.where["held_out"]["scheme"] == "event" and len(dg.where["events"]) == 3
    fx = {e["effect"]: e["params"] for e in dg.effects}
    assert fx["brake_gain"]["gain"] == pytest.approx(GAIN, rel=0.03)
    assert fx["radius_error"]["r_eff"] == pytest.approx(car_sim.RADII["fl"], rel=1e-3)
    for c, r in car_sim.RADII.items():
        assert dg.where["car"][f"r_eff_{c}"] == pytest.approx(r, rel=1e-3)
    assert _drag(**fx["drag"]) == pytest.approx(_drag(car_sim.C0, car_sim.C2), rel=0.05)
    assert dg.gap_after <= 0.5 * dg.gap_before
    spread = dg.where["event_spread"]["brake_gain.gain"]
    assert len(spread["per_event"]) == 3 and all(abs(g / GAIN - 1) < 0.05 for g in spread["per_event"])


def test_events_are_the_simulated_brake_applications(three, session):
    brakes = [s for s in session[1] if s[0] == "brake"]
    for row, (_, a, b, _) in zip(three.where["events"], brakes):
        assert abs(row["t_start"] - a) <= 0.1
        assert row["t_end"] <= b and row["v_end"] >= 5.0
        assert row["gap_after"] < row["gap_before"]


def test_two_events_hold_out_by_blocks(session):
    log, segs = session
    second_end = [s for s in segs if s[0] == "brake"][1][2]
    dg = diagnose_session(session_of(_cut(log, second_end + 0.5), CAR), CAR, P, CFG)
    assert dg.where["held_out"]["scheme"] == "blocks" and len(dg.where["events"]) == 2
    gain = next(e["params"]["gain"] for e in dg.effects if e["effect"] == "brake_gain")
    assert gain == pytest.approx(GAIN, rel=0.05)


def test_calibrations_enter_together_and_are_tested_on_held_out_events(three):
    """The measured radii and drag and the nominal factor's gain enter first, together, and beat the nominal car on
    held-out events; the brake's lag (absent from the simulation) is not added."""
    first = three.where["forward_selection"][0]
    assert first["calibration"] and set(first["added"].split("+")) == {"radius_error", "drag", "brake_gain"}
    assert first["z_paired"] > 3.0
    assert "brake_lag" not in [e["effect"] for e in three.effects]


def test_report_keeps_the_contract_and_drives_the_env(three, tmp_path):
    report = write_session_report(three, tmp_path, plots=True)
    assert tuple(report) == REPORT_KEYS
    on_disk = json.loads((tmp_path / "report.json").read_text())
    assert on_disk["where"]["time_base"] == {"origin": "first_sample", "offset_s": 0.0}
    for row in on_disk["where"]["events"]:
        assert {"t_start", "t_end", "verdict", "effects", "gap_before", "gap_after"} <= set(row)
    assert (tmp_path / "timeline.png").exists() and "### Event 3" in (tmp_path / "report.md").read_text()
    env = gym.make("fricenv/Braking-v0", effects=str(tmp_path / "report.json"))
    env.reset(seed=0)
    env.close()


def test_a_cornering_event_is_found_and_not_diagnosed(session):
    log, segs = session
    third = [s for s in segs if s[0] == "brake"][2]
    turning = types.SimpleNamespace(**vars(log))
    turning.yaw_rate = np.where((log.t >= third[1]) & (log.t < third[2]), 1.0, 0.0)  # 9.7 m/s^2 at 9.7 m/s
    dg = diagnose_session(session_of(turning, CAR), CAR, P, CFG)
    rows = dg.where["events"]
    assert len(rows) == 3 and rows[2]["verdict"] == "not_diagnosed" and rows[2]["note"].startswith("cornering")
    assert dg.where["held_out"]["scheme"] == "blocks"  # two diagnosed events
