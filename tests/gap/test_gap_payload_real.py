"""The payload diagnosis on real-like rig logs: a 30 Hz camera held between frames (its frame clock), a
low-passed force-moment sensor (flagged, its noise from the spectral density, its lag fitted), tracking glitches."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import butter, lfilter

from fricenv.gap.signals.sensors import band_noise, condition_channel, frame_times, looks_filtered

RNG = np.random.default_rng(15)


def _camera_rows(rate: float, cam: float, offset: float, n: int, drop: tuple[int, ...] = ()):
    """Rows at ``rate`` (some dropped) where a camera's frame first shows, and the frames' true times."""
    t = np.arange(n) / rate
    frames = offset + np.arange(int(t[-1] * cam) + 1) / cam
    frames = frames[frames <= t[-1]]
    first = np.searchsorted(t, frames - 1e-12)  # the first row at or after each frame
    for d in drop:  # a dropped row shows its frame one row later
        first[first == d] += 1
    fresh = np.zeros(n, dtype=bool)
    fresh[first] = True
    return t, fresh, frames, first


@pytest.mark.parametrize("rate, drop", [(100.0, ()), (182.0, ()), (100.0, (40, 133, 250))])
def test_frame_clock_recovers_the_capture_times_within_a_fifth_of_a_step(rate, drop):
    t, fresh, frames, first = _camera_rows(rate, 30.0, 0.0123, 900, drop)
    f = frame_times(t, fresh)
    assert f is not None
    # a row shows its frame up to a step late (two after a drop); the clock puts each frame within 0.2 steps
    np.testing.assert_array_less(np.abs(f[first] - frames), 0.2 / rate)
    assert np.max(t[first] - frames) > 0.5 / rate  # the rows themselves were that late


def test_rows_that_do_not_follow_a_clock_give_none():
    t = np.arange(900) / 100.0
    fresh = np.zeros(900, dtype=bool)
    fresh[np.cumsum(RNG.integers(2, 9, 150))[:120]] = True  # frames at random gaps of 2-8 rows
    assert frame_times(t, fresh) is None
    assert frame_times(t, np.ones(900, dtype=bool)) is None  # every row fresh: no slower camera


def test_a_glitch_on_a_fast_trend_is_an_outlier_and_a_step_is_not():
    h = 1.0 / 30.0
    x = 0.9 * np.sin(2.0 * np.arange(240) * h) + RNG.normal(0.0, 1e-4, 240)  # ~1 m/s pose at 30 frames/s
    x[100] += 0.005
    c = condition_channel(x, 1e-9, may_be_filtered=False)
    assert c.outliers.tolist() == [100]
    y = x.copy()
    y[100] -= 0.005
    y[150:] += 0.005  # a step is a change of level, not a glitch
    assert condition_channel(y, 1e-9, may_be_filtered=False).outliers.size == 0


def test_a_low_passed_force_channel_is_flagged_and_its_white_equivalent_noise_recovered():
    fs, n, sigma = 1000.0, 8000, 0.1
    t = np.arange(n) / fs
    signal = 2.0 * np.sin(3.0 * t) + 0.4 * np.sin(7.0 * t)
    white = RNG.normal(0.0, sigma, n)
    b, a = butter(2, 20.0, fs=fs)
    filtered = signal + lfilter(b, a, white)
    assert looks_filtered(filtered) and not looks_filtered(signal + white)
    # below the sensor's cut-off the filtered noise has white noise's density: the same white-equivalent std
    assert band_noise(filtered, fs, 8.0) == pytest.approx(sigma, rel=0.2)
    assert band_noise(signal + white, fs, 8.0) == pytest.approx(sigma, rel=0.2)


def test_a_held_pose_with_filtered_sensor_and_glitches_is_diagnosed_none(tmp_path):
    """A log with no effect, exported real-like (held 30 Hz pose, 20 Hz F/T filter, two 5 mm glitches, jitter and
    dropped rows): it used to come out ``unexplained`` with a gap of 3 or more."""
    from fricenv.gap.payload.diagnose import diagnose_payload
    from fricenv.gap.payload.validate import PayloadCase, simulate_payload_case
    from fricenv.logs import read_log
    from tests.real_artifacts import PayloadArtifacts, real_like_payload, write_export

    case = PayloadCase("none", (), None, "paper", 1e-3, 4242)
    log, _ = simulate_payload_case(case)
    clean = {k: np.asarray(getattr(log, k), dtype=float) for k in ("t", "M", "f_x", "f_y", "theta", "X", "Y")}
    export = real_like_payload(clean, np.random.default_rng(7), PayloadArtifacts(rate_hz=100.0))
    csv, mp = write_export(tmp_path / "rig", export)
    dg = diagnose_payload(read_log(csv, "payload", column_map=mp))
    sensors = dg.where["sensors"]
    assert dg.verdict == "none" and dg.gap_before < 1.1
    assert all(sensors[c]["filtered"] for c in ("M", "f_x", "f_y"))
    assert sensors["M"]["lag_s"] == pytest.approx(np.sqrt(2.0) / (2 * np.pi * 20.0), abs=0.004)  # 2nd-order group delay
    assert sensors[export.truth["glitch_axis"]]["outliers"] >= 2
    assert sensors["X"]["frame_rate_hz"] == pytest.approx(30.0, rel=0.01)


def _real_like_diagnosis(tmp_path, case):
    from fricenv.gap.payload.diagnose import diagnose_payload
    from fricenv.gap.payload.validate import simulate_payload_case
    from fricenv.logs import read_log
    from tests.real_artifacts import PayloadArtifacts, real_like_payload, write_export

    log, _ = simulate_payload_case(case)
    clean = {k: np.asarray(getattr(log, k), dtype=float) for k in ("t", "M", "f_x", "f_y", "theta", "X", "Y")}
    export = real_like_payload(clean, np.random.default_rng(7), PayloadArtifacts(rate_hz=100.0))
    csv, mp = write_export(tmp_path / "rig", export)
    return diagnose_payload(read_log(csv, "payload", column_map=mp))


@pytest.mark.parametrize("delay", [0.02, 0.05])
def test_a_vision_delay_behind_a_filtered_sensor_is_the_cameras_own(tmp_path, delay):
    """The 20 Hz F/T filter lags the wrench by about 11 ms, which shifts it against the pose like a negative vision
    delay: fitted as one net shift, the delay came out about 11 ms short (a 20 ms delay 55 % off). With the lag read
    from the sensor's noise, the delay is the camera's own within 15 %."""
    from fricenv.effects.payload import make_payload_effect
    from fricenv.gap.payload.validate import PayloadCase

    case = PayloadCase("vision_delay", (make_payload_effect("vision_delay", delay=delay),), None, "paper", 1e-3, 4243)
    dg = _real_like_diagnosis(tmp_path, case)
    lag = dg.where["sensors"]["M"]["lag_s"]
    assert lag == pytest.approx(np.sqrt(2.0) / (2 * np.pi * 20.0), rel=0.15)  # the filter's group delay
    assert dg.where["sensors"]["M"]["filter"]["order"] == 2
    assert dg.verdict == "vision_delay"
    assert dg.params["delay"] == pytest.approx(delay, rel=0.15)
