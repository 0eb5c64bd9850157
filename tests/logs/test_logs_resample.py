"""Resampling and held samples in the log reader (fricenv/resample.py through fricenv.logs.read_log), and the convert
round trip of a real-like export (validation/real_artifacts.py) back to the clean log."""

import numpy as np
import pytest

from fricenv import cli
from fricenv.logs import LogFormatError, read_log
from fricenv.logs.resample import MAX_FILL, MAX_JITTER
from validation.real_artifacts import (
    PayloadArtifacts,
    QuarterCarArtifacts,
    held_camera,
    real_like_payload,
    real_like_quarter_car,
    write_export,
)

H = 0.01  # step [s]
R = 0.345  # nominal radius [m]


def _write(tmp_path, header: str, rows, name="log.csv"):
    path = tmp_path / name
    path.write_text(header + "\n" + "\n".join(",".join(repr(float(x)) for x in row) for row in rows) + "\n")
    return path


def _omega(t):
    return 50.0 + 5.0 * np.sin(2 * np.pi * 1.0 * t)  # [rad/s], second derivative up to 5 (2 pi)^2


def test_a_jittered_sine_resampled_equals_the_truth(tmp_path):
    rng = np.random.default_rng(4)
    n = 300
    t = np.arange(n) * H + rng.uniform(-0.1, 0.1, n) * H  # instants within 10 % of the step
    t[0] = 0.0
    keep = np.ones(n, dtype=bool)
    keep[[50, 120, 121, 200]] = False  # one dropped row, two in a row, one more
    rows = np.column_stack([t, np.full(n, 300.0), _omega(t)])[keep]
    log = read_log(_write(tmp_path, "t,T_b,omega", rows))
    assert len(log) == n and log.resampled["filled"] == 4 and log.resampled["rows"] == n - 4
    np.testing.assert_allclose(np.diff(log.t), log.dt, rtol=1e-9)  # uniform grid
    assert log.t[0] == 0.0 and log.t[-1] == pytest.approx(t[-1], abs=1e-12)
    # linear interpolation error <= h_gap^2 / 8 max|x''|: the widest gap is 3 steps (two rows dropped)
    bound = (3 * 1.2 * H) ** 2 / 8 * 5.0 * (2 * np.pi) ** 2
    assert np.max(np.abs(log.omega - _omega(log.t))) <= bound
    assert log.missing["omega"] == 0.0


def _stamps_with_one_step(ratio: float, n=30) -> np.ndarray:
    """Uniform stamps but step 10 -> 11 is ``ratio`` steps long and the next one ``2 - ratio`` (a late stamp)."""
    t = np.arange(n) * H
    t[11] += (ratio - 1.0) * H
    return t


def _stamps_with_a_gap(missing: int, n=30) -> np.ndarray:
    """Uniform stamps with ``missing`` rows dropped before row 15."""
    t = np.arange(n) * H
    t[15:] += missing * H
    return t


def _log_at(tmp_path, t: np.ndarray, torque: float = 0.0):
    return _write(tmp_path, "t,T_b,omega", np.column_stack([t, np.full(len(t), torque), _omega(t)]))


@pytest.mark.parametrize("shift", [0.24, -0.24])
def test_jitter_just_below_the_bound_is_resampled(tmp_path, shift):
    log = read_log(_log_at(tmp_path, _stamps_with_one_step(1.0 + shift)))
    assert log.resampled["max_jitter"] == pytest.approx(abs(shift), rel=1e-9) and len(log) == 30


@pytest.mark.parametrize(("t", "message"), [
    (_stamps_with_one_step(1.26), (r"log\.csv:13: column 't': step 0\.0126 s is 1\.26 median steps \(0\.01 s\): "
                                   r"time-stamp jitter above 25% of the step")),
    (_stamps_with_a_gap(MAX_FILL + 1), (r"log\.csv:17: column 't': gap of 0\.05 s \(5 steps of 0\.01 s\): more than "
                                        r"3 missing samples in a row")),
], ids=["jitter above 25%", "4 rows missing"])
def test_a_step_beyond_the_bounds_names_file_line_and_column(tmp_path, t, message):
    assert MAX_JITTER == 0.25
    with pytest.raises(LogFormatError, match=message):
        read_log(_log_at(tmp_path, t))


def test_a_uniform_log_is_kept_exactly(tmp_path):
    t = np.arange(40) * H
    log = read_log(_log_at(tmp_path, t, 5.0))
    assert log.resampled is None
    np.testing.assert_array_equal(log.omega, _omega(t))


def test_the_torque_is_held_over_a_dropped_row(tmp_path):
    t = np.arange(20) * H + np.r_[0, np.full(19, 0.05 * H)]  # jitter: resampled
    torque = np.arange(20) * 100.0
    keep = np.arange(20) != 8
    log = read_log(_write(tmp_path, "t,T_b,omega", np.column_stack([t, torque, _omega(t)])[keep]))
    np.testing.assert_array_equal(log.T_b, np.r_[torque[:8], torque[7], torque[9:]])


def test_held_camera_samples_are_exactly_the_nan_ones(tmp_path):
    """A 30 Hz camera in a 100 Hz payload log: each repeated pose is NaN, each fresh one kept as logged."""
    rng = np.random.default_rng(11)
    n = 200
    t = np.arange(n) * H
    fine = np.arange(0, n * H + 0.1, 1e-3)
    pose = {"theta": 0.3 * fine + rng.normal(0, 1e-3, len(fine)), "X": 0.2 * fine + rng.normal(0, 1e-4, len(fine)),
            "Y": -0.1 * fine + rng.normal(0, 1e-4, len(fine))}
    held = {k: held_camera(fine, v, t, 30.0, 0.004) for k, v in pose.items()}
    rows = np.column_stack([t, rng.normal(0, 1, n), rng.normal(0, 1, n), rng.normal(0, 1, n),
                            held["theta"], held["X"], held["Y"]])
    log = read_log(_write(tmp_path, "t,M,f_x,f_y,theta,X,Y", rows), "payload")
    for name in ("theta", "X", "Y"):
        repeated = np.r_[False, held[name][1:] == held[name][:-1]]
        assert 0.6 < repeated.mean() < 0.75  # about 2 of every 3 rows repeat the last frame
        np.testing.assert_array_equal(np.isnan(getattr(log, name)), repeated)
        np.testing.assert_array_equal(getattr(log, name)[~repeated], held[name][~repeated])
        assert log.missing[name] == pytest.approx(repeated.mean(), abs=1e-12)
    assert log.missing["M"] == 0.0


def test_zeros_constants_and_long_runs_are_not_held(tmp_path):
    """A car at rest (v = 0), a constant channel and a reading constant for longer than a second stay measured."""
    n = 300
    t = np.arange(n) * H
    v = np.r_[np.linspace(5.0, 0.1, 100), np.zeros(200)]  # stops, then rests
    a_x = np.full(n, -2.0)
    omega = np.r_[np.linspace(5.0, 0.1, 100) / R, np.zeros(200)]
    log = read_log(_write(tmp_path, "t,T_b,omega,v,a_x", np.column_stack([t, np.zeros(n), omega, v, a_x])))
    assert not np.isnan(log.v).any() and not np.isnan(log.a_x).any()
    long_run = np.r_[np.linspace(0.0, 1.0, 50), np.full(150, 1.5), np.linspace(1.6, 2.0, 100)]  # 1.5 s constant
    log = read_log(_write(tmp_path, "t,T_b,omega,a_x", np.column_stack([t, np.zeros(n), omega, -long_run]), "b.csv"))
    assert not np.isnan(log.a_x).any()


def _clean_quarter_car(n=400):
    t = np.arange(n) * H
    v = 25.0 - 5.0 * t
    return {"t": t, "T_b": np.where(t > 0.5, 600.0, 0.0) + np.where(t > 2.0, 200.0, 0.0),
            "omega": v / R * (1 - 0.05 * np.sin(2 * np.pi * 0.5 * t) ** 2), "v": v, "a_x": np.full(n, -5.0)}


@pytest.mark.parametrize("rate", [25.0, 100.0, 200.0])
def test_convert_round_trip_of_a_real_like_export(tmp_path, rate):
    """`fricenv gap convert` of a real-like export (jitter, drops, epoch, km/h, kPa, g, quantised wheel) equals the
    clean log at the grid times within the artifacts' tolerance."""
    clean = _clean_quarter_car()
    spec = QuarterCarArtifacts(rate_hz=rate, imu_cutoff_hz=None, outliers=0, drop_prob=0.03)
    csv, mp = write_export(tmp_path / "run", real_like_quarter_car(clean, np.random.default_rng(int(rate)), spec))
    out = tmp_path / "contract.csv"
    assert cli.main(["-q", "gap", "convert", csv, "--map", mp, "--out", str(out)]) == 0
    log = read_log(out)
    assert log.torque_from_pressure and abs(1.0 / log.dt - rate) < 0.02 * rate
    assert any(c.startswith("resampled: ") and "zero-order hold for T_b" in c for c in log.comments)
    truth = {k: np.interp(log.t, clean["t"], clean[k]) for k in ("omega", "v", "a_x")}
    # km/h quantum / 2 as omega, plus linear interpolation over a gap of two steps at up to 140 rad/s^2 curvature
    omega_tol = 0.05 / 3.6 / R + (2.4 / rate) ** 2 / 8 * 140.0
    assert np.max(np.abs(log.omega - truth["omega"])) <= omega_tol
    # the epoch stamps are written to the microsecond: v (slope 5 m/s^2) is off by up to 2 x 5e-6 m/s
    np.testing.assert_allclose(log.v, truth["v"], atol=2e-5)
    np.testing.assert_allclose(log.a_x, truth["a_x"], atol=1e-9)
    held = np.interp(log.t, clean["t"], clean["T_b"])
    steps = np.abs(log.T_b - held) > 1e-6  # the torque steps twice: at most a sample late or early at each
    assert np.count_nonzero(steps) <= 2 * 2


def test_payload_round_trip_keeps_fresh_frames_and_marks_held_ones(tmp_path):
    n = 500
    t = np.arange(n) * H
    clean = {"t": t, "M": 0.2 * np.sin(t), "f_x": np.cos(t), "f_y": 0.5 + 0.0 * t, "theta": 0.1 + 0.4 * t,
             "X": 0.3 + 0.05 * t, "Y": 0.1 - 0.02 * t}  # never exactly 0: a pose at 0.0 is never "held"
    spec = PayloadArtifacts(ft_cutoff_hz=None, glitches=0)
    export = real_like_payload(clean, np.random.default_rng(3), spec)
    csv, mp = write_export(tmp_path / "rig", export)
    log = read_log(csv, "payload", column_map=mp)
    for name, speed in (("theta", 0.4), ("X", 0.05), ("Y", 0.02)):
        x = getattr(log, name)
        assert 0.55 < np.isnan(x).mean() < 0.8  # a 30 Hz camera in a 100 Hz log, after resampling
        fresh = ~np.isnan(x)
        # a fresh sample is a frame at most one log step (plus jitter) old
        assert np.max(np.abs(x[fresh] - np.interp(log.t[fresh], t, clean[name]))) <= speed * 1.3 * H
    np.testing.assert_allclose(log.f_x, np.cos(log.t), atol=(1.2 * 2 * H) ** 2 / 8 + 1e-9)


def test_a_wrong_map_on_the_command_line_is_one_line(tmp_path, capsys):
    csv, mp = write_export(tmp_path / "run", real_like_quarter_car(_clean_quarter_car(), np.random.default_rng(1)))
    from pathlib import Path

    mp_text = Path(mp).read_text().replace('"wheel_rl"', '"wheel_rx"')
    (tmp_path / "bad.json").write_text(mp_text)
    code = cli.main(["gap", "convert", csv, "--map", str(tmp_path / "bad.json"), "--out", str(tmp_path / "o.csv")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err
    assert "bad.json: channels.omega.column: 'wheel_rx': no such column in" in err
    code = cli.main(["gap", "diagnose", csv, "--map", str(tmp_path / "bad.json"), "--out", str(tmp_path / "rep")])
    assert code == 2 and "channels.omega.column: 'wheel_rx'" in capsys.readouterr().err


@pytest.mark.slow
def test_diagnose_with_a_map_reads_the_export_and_keeps_the_converted_log(tmp_path):
    csv, mp = write_export(tmp_path / "run", real_like_quarter_car(_clean_quarter_car(), np.random.default_rng(2),
                                                                   QuarterCarArtifacts(rate_hz=50.0)))
    out = tmp_path / "report"
    assert cli.main(["-q", "gap", "diagnose", csv, "--map", mp, "--out", str(out), "--no-plots", "--jobs", "1"]) == 0
    assert (out / "report.json").is_file()
    log = read_log(out / "log.contract.csv")
    assert log.torque_from_pressure and abs(1.0 / log.dt - 50.0) < 1.0


def test_a_resampled_held_channel_keeps_its_fresh_samples_unmixed(tmp_path):
    """Jittered stamps (so the log is resampled) and a held 30 Hz pose: each fresh frame keeps exactly the value it
    was logged with, at its row's grid point (interpolating towards the next frame, rows away, would mix two)."""
    rng = np.random.default_rng(12)
    n = 200
    t = np.arange(n) * H + rng.uniform(-0.05, 0.05, n) * H
    t[0] = 0.0
    fine = np.arange(0, n * H + 0.1, 1e-3)
    held = {k: held_camera(fine, s * fine + 0.1, t, 30.0, 0.004) for k, s in (("theta", 0.3), ("X", 0.2), ("Y", -0.1))}
    rows = np.column_stack([t, rng.normal(0, 1, n), rng.normal(0, 1, n), rng.normal(0, 1, n),
                            held["theta"], held["X"], held["Y"]])
    log = read_log(_write(tmp_path, "t,M,f_x,f_y,theta,X,Y", rows), "payload")
    assert log.resampled is not None and len(log) == n
    for name in ("theta", "X", "Y"):
        fresh = np.r_[True, held[name][1:] != held[name][:-1]]
        np.testing.assert_array_equal(np.isnan(getattr(log, name)), ~fresh)
        np.testing.assert_array_equal(getattr(log, name)[fresh], held[name][fresh])
