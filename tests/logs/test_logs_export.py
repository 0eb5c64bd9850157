"""Exports as they are: a header written as the last '#' line, time in any base re-based to the first sample with
its offset kept, full precision through every writer, a car's optional channels, and the racecar export."""

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from fricenv.commands.gap_convert import convert
from fricenv.logs import LogFormatError, QuarterCarLog, read_log, write_log

R = 0.33
ROOT = Path(__file__).resolve().parents[2]
AV21 = ROOT.parent / "shared" / "realdata" / "av21" / "LVMS_23_01_04_B.csv"
AV21_FALLBACK = Path("/work/shared/realdata/av21/LVMS_23_01_04_B.csv")
AV21_MAP = ROOT / "validation" / "maps" / "av21.json"


def _rows(t, v):
    omega = v / R * 0.99
    return [f"{ti!r},{100.0 * k % 700!r},{w!r},{vi!r}" for k, (ti, w, vi) in
            enumerate(zip(t.tolist(), omega.tolist(), v.tolist()))]


def test_header_in_the_last_comment_line(tmp_path):
    t = np.arange(50) * 0.01
    path = tmp_path / "export.csv"
    path.write_text("# logger v2\n# t,T_b,omega,v\n" + "\n".join(_rows(t, np.linspace(20, 15, 50))) + "\n")
    log = read_log(path)
    assert len(log) == 50 and log.comments == ("logger v2",) and log.v[0] == 20.0


def test_a_comment_that_does_not_name_the_columns_is_a_comment(tmp_path):
    t = np.arange(50) * 0.01
    rows = _rows(t, np.linspace(20, 15, 50))
    path = tmp_path / "export.csv"
    path.write_text("# a, b\nt,T_b,omega,v\n" + "\n".join(rows) + "\n")  # two cells: not the header
    assert read_log(path).comments == ("a, b",)
    path.write_text("# 1,2,3,4\n" + "\n".join(rows) + "\n")  # numbers: a commented-out row, not a header
    with pytest.raises(LogFormatError, match="header"):
        read_log(path)


@pytest.mark.parametrize("t0, step", [(1.7e9, 0.04), (1.7e9 + 0.123456, 0.001), (0.0, 0.001), (5123.25, 0.04)])
def test_time_is_rebased_and_written_at_full_precision(tmp_path, t0, step):
    """Epoch seconds at 40 ms and at 1 kHz: the stamps' steps survive a write and a read, exactly."""
    n = 400
    t = t0 + np.arange(n) * step
    v = 20.0 - 0.01 * np.arange(n) + 1e-9 * np.sin(np.arange(n))  # digits beyond ten significant ones
    path = tmp_path / "export.csv"
    path.write_text("t,T_b,omega,v\n" + "\n".join(_rows(t, v)) + "\n")
    log = read_log(path)
    assert log.t[0] == 0.0 and log.t_offset == t[0] and log.resampled is None
    np.testing.assert_array_equal(log.t, t - t[0])
    np.testing.assert_array_equal(log.v, v)
    write_log(tmp_path / "again.csv", log)
    back = read_log(tmp_path / "again.csv")
    np.testing.assert_array_equal(back.t, log.t)
    np.testing.assert_array_equal(back.v, log.v)
    np.testing.assert_array_equal(back.T_b, log.T_b)
    assert back.t_offset == log.t_offset
    assert (f"t_offset_s: {float(t[0])!r}" in back.comments) == (t0 != 0.0)


def test_epoch_time_through_a_map_keeps_its_offset(tmp_path):
    t = 1672875115.41200042 + np.arange(300) * 0.039999961853027344
    path = tmp_path / "export.csv"
    path.write_text("# time(s),p(kPa),w(kmph),vx(m/s)\n" + "\n".join(
        f"{ti!r},{500.0 * (k > 100)!r},{3.6 * (20 - 0.01 * k)!r},{20 - 0.01 * k!r}" for k, ti in enumerate(t.tolist())) + "\n")
    cmap = tmp_path / "map.json"
    cmap.write_text(json.dumps({"channels": {"t": {"column": "time", "unit": "epoch_s"},
                                             "T_b": {"column": "p", "factor": 3e-4},
                                             "omega": {"column": "w", "radius": R}, "v": "vx"}}))
    out = tmp_path / "log.csv"
    log = convert(path, cmap, "quarter-car", out)
    assert log.t_offset == t[0] and log.t[0] == 0.0
    np.testing.assert_array_equal(log.t, t - t[0])
    back = read_log(out)
    assert back.t_offset == t[0]
    np.testing.assert_array_equal(back.t, log.t)
    assert f"t_offset_s: {float(t[0])!r}" in Path(out).read_text()


def test_a_cars_channels_through_a_map(tmp_path):
    n = 200
    t = np.arange(n) * 0.02
    v = np.linspace(25.0, 15.0, n)
    cols = {"time": t, "brake": np.full(n, 800.0), "thr": np.zeros(n), "yaw": np.full(n, 3.0) + 0.01 * t,
            "steer": np.linspace(-2.0, 2.0, n), "vx": v,
            **{f"w_{c}": 3.6 * v * (1.0 + 0.001 * i) for i, c in enumerate(("fl", "fr", "rl", "rr"))}}
    path = tmp_path / "export.csv"
    path.write_text(",".join(cols) + "\n" + "\n".join(",".join(repr(float(cols[k][i])) for k in cols)
                                                      for i in range(n)) + "\n")
    wheels = {f"omega_{c}": {"column": f"w_{c}", "unit": "km/h", "radius": 0.3 + 0.01 * i}
              for i, c in enumerate(("fl", "fr", "rl", "rr"))}
    cmap = tmp_path / "map.json"
    cmap.write_text(json.dumps({"channels": {
        "t": "time", "T_b": {"column": "brake", "unit": "bar", "factor": 1e-5},
        "omega": {"column": "w_fl", "unit": "km/h", "radius": 0.3}, "v": "vx",
        "throttle": {"column": "thr", "unit": "N m"}, "yaw_rate": {"column": "yaw", "unit": "deg/s"},
        "steer": {"column": "steer", "unit": "deg"}, **wheels}}))
    log = read_log(path, column_map=cmap)
    np.testing.assert_allclose(log.yaw_rate, np.radians(cols["yaw"]))
    np.testing.assert_allclose(log.steer, np.radians(cols["steer"]))
    for i, c in enumerate(("fl", "fr", "rl", "rr")):
        np.testing.assert_allclose(getattr(log, f"omega_{c}"), v * (1.0 + 0.001 * i) / (0.3 + 0.01 * i))
    assert log.throttle_unit == "N m" and log.T_b[0] == pytest.approx(800.0)
    write_log(tmp_path / "log.csv", log)
    back = read_log(tmp_path / "log.csv")
    for name in ("t", "T_b", "omega", "v", "throttle", "yaw_rate", "steer", "omega_fl", "omega_fr", "omega_rl",
                 "omega_rr"):
        np.testing.assert_array_equal(getattr(back, name), getattr(log, name))
    assert back.throttle_unit == "N m"
    radii = {"omega": 0.3, **{f"omega_{c}": 0.3 + 0.01 * i for i, c in enumerate(("fl", "fr", "rl", "rr"))}}
    assert log.radii == radii and back.radii == radii  # the radii the map converted with, through a written log
    bare = QuarterCarLog(t=t, T_b=np.zeros(n), omega=v / R)
    assert all(getattr(bare, name) is None for name in ("throttle", "yaw_rate", "steer", "omega_fl", "omega_rr"))


def test_a_yaw_rate_in_degrees_read_as_radians_is_caught(tmp_path):
    path = tmp_path / "export.csv"
    path.write_text("t,T_b,omega,yaw_rate\n" + "\n".join(f"{k * 0.01!r},0.0,{50.0 + k * 0.1!r},{30.0 + k!r}"
                                                         for k in range(50)) + "\n")
    with pytest.raises(LogFormatError, match=r"column 'yaw_rate'.*deg/s"):
        read_log(path)


def _av21() -> Path:
    for path in (AV21, AV21_FALLBACK):
        if path.is_file():
            return path
    pytest.skip("the racecar export is not here (GPL data, kept outside the repository)")


def test_the_racecar_export_reads_with_its_map(tmp_path):
    """The AV-21 export as published: its header in a comment, epoch seconds, a filtered and delayed a_x."""
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        log = convert(_av21(), AV21_MAP, "quarter-car", tmp_path / "av21.csv")
    assert len(log) == 16791 and 1.0 / log.dt == pytest.approx(25.0, rel=1e-5)
    assert log.t_offset == pytest.approx(1672875115.412, abs=1e-3) and log.t[0] == 0.0
    assert log.a_x is None and [w.split(":")[0] for w in log.warnings] == ["a_x"]
    assert "trails the slope of v by 1." in log.warnings[0] and len(seen) == 1
    assert all(getattr(log, n) is not None for n in ("throttle", "yaw_rate", "steer", "omega_fl", "omega_rr"))
    assert log.torque_from_pressure
    back = read_log(tmp_path / "av21.csv")
    assert back.t_offset == log.t_offset and back.warnings == log.warnings
    np.testing.assert_array_equal(back.t, log.t)


def test_the_car_params_file_reads_as_quarter_car_params():
    from fricenv.gap.quarter_car.diagnose import load_params

    assert load_params(ROOT / "validation" / "maps" / "av21_params.json").r == 0.33


def _car_export(tmp_path, wheel_rr, radius_rr=0.34):
    """A coasting car (no brake, no throttle) then a stop; the rear-right wheel as given."""
    n = 600
    t = np.arange(n) * 0.02
    v = np.where(t < 6.0, 25.0 - 0.1 * t, 24.4 - 6.0 * (t - 6.0))
    v = np.maximum(v, 1.0)
    brake = np.where(t < 6.0, 0.0, 2000.0)
    cols = {"time": t, "brake": brake, "thr": np.zeros(n), "vx": v, "w_fl": 3.6 * v * 1.01, "w_rr": wheel_rr(v)}
    path = tmp_path / "car.csv"
    path.write_text(",".join(cols) + "\n" + "\n".join(",".join(repr(float(cols[k][i])) for k in cols)
                                                      for i in range(n)) + "\n")
    cmap = tmp_path / "car.map.json"
    cmap.write_text(json.dumps({"channels": {
        "t": "time", "T_b": {"column": "brake", "unit": "kPa", "factor": 3.4e-4},
        "omega": {"column": "w_fl", "unit": "km/h", "radius": 0.33}, "v": "vx", "throttle": "thr",
        "omega_rr": {"column": "w_rr", "unit": "km/h", "radius": radius_rr}}}))
    return path, cmap


def _read_car(tmp_path, wheel_rr):
    path, cmap = _car_export(tmp_path, wheel_rr)
    return read_log(path, column_map=cmap)


def test_a_wheel_off_v_while_rolling_freely_is_a_warning(tmp_path):
    """A rim speed 8 % above v while coasting: its radius or unit is to be checked; the wheel is kept."""
    with pytest.warns(Warning, match=r"omega_rr: wheel speed x radius / v = 1\.08"):
        log = _read_car(tmp_path, lambda v: 3.6 * v * 1.08)
    assert log.omega_rr is not None and [w.split(":")[0] for w in log.warnings] == ["omega_rr"]
    assert "median of 300 samples" in log.warnings[0]


def test_a_clean_car_export_has_no_warning(tmp_path, recwarn):
    log = _read_car(tmp_path, lambda v: 3.6 * v * 1.01)
    assert log.warnings == () and log.omega_rr is not None and len(recwarn) == 0


@pytest.mark.parametrize("wheel, said", [(lambda v: -3.6 * v, "negative in 100%"),
                                         (lambda v: np.full_like(v, 80.0), "constant"),
                                         (lambda v: v, r"x r / v = 0\.278")])
def test_another_wheel_that_cannot_be_one_is_left_out(tmp_path, wheel, said):
    with pytest.warns(Warning, match=said):
        log = _read_car(tmp_path, wheel)
    assert log.omega_rr is None and log.warnings[0].startswith("omega_rr: ") and log.warnings[0].endswith("left out")


def test_a_session_without_a_braking_event_is_an_error_naming_the_export(tmp_path, capsys):
    """The converted log (OUT/log.contract.csv) is the tool's file: an error about the whole session names the
    export the user gave."""
    from fricenv.cli import main

    path, cmap = _car_export(tmp_path, lambda v: 3.6 * v * 1.01)
    text = path.read_text().splitlines()
    rows = [line.split(",") for line in text[1:]]
    for row in rows:
        row[1] = "0.0"  # no brake anywhere
    path.write_text("\n".join([text[0]] + [",".join(row) for row in rows]) + "\n")
    params = tmp_path / "params.json"
    params.write_text(json.dumps({"r": 0.33, "car": {"mass": 790.0, "lf": 1.248, "lr": 1.7328}}))
    out = tmp_path / "out"
    code = main(["gap", "diagnose", str(path), "--map", str(cmap), "--params", str(params), "--out", str(out),
                 "--no-plots"])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert code == 2
    assert err.startswith(f"fricenv gap diagnose: error: {path}: no braking event"), err
    assert err.endswith(f"(converted to {out / 'log.contract.csv'})"), err
