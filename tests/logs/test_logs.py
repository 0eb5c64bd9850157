"""The log contract (docs/contracts.md): round trip, and a clear error naming file, line and column."""

import numpy as np
import pytest

from fricenv.logs import LogFormatError, PayloadLog, QuarterCarLog, read_log, write_log

HEADER = "t,T_b,omega,v,a_x"


def _rows(n=20, dt=0.01, v=20.0, r=0.345):
    return [f"{k * dt:.4f},{100.0 * k:.1f},{v / r:.6f},{v:.3f},-0.5" for k in range(n)]


def _write(tmp_path, lines, name="log.csv"):
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def test_round_trip_with_comments(tmp_path):
    t = np.arange(50) * 0.01
    log = QuarterCarLog(t=t, T_b=np.linspace(0, 900, 50), omega=np.full(50, 57.0), v=np.full(50, 19.7), a_x=None)
    path = tmp_path / "out.csv"
    write_log(path, log, comments=("road: wet", "seed: 3"))
    back = read_log(path)
    assert back.comments == ("road: wet", "seed: 3")
    assert back.a_x is None
    np.testing.assert_allclose(back.t, t)
    np.testing.assert_allclose(back.T_b, log.T_b)
    assert back.dt == pytest.approx(0.01)
    assert "a_x" not in path.read_text().splitlines()[2]


def test_required_columns_only(tmp_path):
    path = _write(tmp_path, ["t,T_b,omega"] + [f"{k * 0.01:.2f},0,50" for k in range(10)])
    log = read_log(path)
    assert log.v is None and log.a_x is None and len(log) == 10


def test_missing_column_is_named(tmp_path):
    path = _write(tmp_path, ["t,omega"] + [f"{k * 0.01:.2f},50" for k in range(10)])
    with pytest.raises(LogFormatError, match=r"log\.csv: missing required column\(s\) T_b"):
        read_log(path)


def test_non_increasing_time_names_line(tmp_path):
    rows = _rows()
    rows[5], rows[6] = rows[6], rows[5]
    path = _write(tmp_path, ["# comment", HEADER] + rows)
    with pytest.raises(LogFormatError, match=r"log\.csv:9: column 't' is not increasing"):
        read_log(path)


def test_a_row_written_twice_is_dropped_with_a_warning(tmp_path):
    rows = _rows()
    clean = read_log(_write(tmp_path, [HEADER] + rows, "clean.csv"))
    with pytest.warns(Warning, match=r"t: 2 row\(s\) repeating the row before them in every column dropped "
                                     r"\(the first on line 7\)"):
        log = read_log(_write(tmp_path, [HEADER] + rows[:5] + rows[4:12] + rows[11:]))
    for name in ("t", "T_b", "omega", "v", "a_x"):
        np.testing.assert_array_equal(getattr(log, name), getattr(clean, name))
    assert log.warnings == ("t: 2 row(s) repeating the row before them in every column dropped (the first on line 7)",)


@pytest.mark.parametrize("row, edit, message", [
    (10, lambda rows: rows[10].replace("0.1000", "0.1040", 1),
     r"log\.csv:12: column 't': step 0\.014 s is 1\.4 median steps \(0\.01 s\): time-stamp jitter above 25% of the step"),
    (6, lambda rows: rows[5].replace(",57.971014,", ",58.0,"),  # the stamp of the row before, other values
     (r"log\.csv:8: column 't' is not increasing: the stamp repeats line 7's \(0\.050000000000000003 then "
      r"0\.050000000000000003 s\)$")),
])
def test_a_stamp_off_the_grid_is_named(tmp_path, row, edit, message):
    rows = _rows()
    rows[row] = edit(rows)
    path = _write(tmp_path, [HEADER] + rows)
    with pytest.raises(LogFormatError, match=message):
        read_log(path)


def test_nan_in_an_optional_channel_is_missing_in_t_or_torque_an_error(tmp_path):
    rows = _rows()
    rows[3] = rows[3].replace(",-0.5", ",nan")
    log = read_log(_write(tmp_path, [HEADER] + rows))
    assert np.isnan(log.a_x[3]) and np.isfinite(np.delete(log.a_x, 3)).all()
    assert log.missing == {"T_b": 0.0, "omega": 0.0, "v": 0.0, "a_x": 1 / 20}
    rows[3] = rows[3].replace(",300.0,", ",nan,")
    with pytest.raises(LogFormatError, match=r"torque\.csv:5: column 'T_b' is NaN or empty; it may never be missing"):
        read_log(_write(tmp_path, [HEADER] + rows, "torque.csv"))


def test_non_numeric_cell(tmp_path):
    rows = _rows()
    rows[2] = rows[2].replace(",-0.5", ",oops")
    path = _write(tmp_path, [HEADER] + rows)
    with pytest.raises(LogFormatError, match=r"log\.csv:4: column 'a_x': 'oops' is not a number"):
        read_log(path)


def test_omega_in_rpm_is_caught(tmp_path):
    rpm = 20.0 / 0.345 * 60 / (2 * np.pi)
    rows = [f"{k * 0.01:.2f},0,{rpm:.3f},20.0,0" for k in range(20)]
    path = _write(tmp_path, [HEADER] + rows)
    with pytest.raises(LogFormatError, match=r"omega.*(rpm|units)"):
        read_log(path)


def test_mostly_locked_log_is_valid(tmp_path):
    rows = [f"{k * 0.01:.2f},0,{20.0 / 0.345:.3f},20.0,0" for k in range(10)]  # free rolling first
    rows += [f"{k * 0.01:.2f},3000,0,{20.0 - 0.05 * (k - 10):.3f},-7" for k in range(10, 100)]  # then locked
    log = read_log(_write(tmp_path, [HEADER] + rows))
    assert len(log) == 100


def test_speed_in_kmh_is_caught(tmp_path):
    rows = [f"{k * 0.01:.2f},0,{20.0 / 0.345:.3f},72.0,0" for k in range(20)]
    with pytest.raises(LogFormatError, match="disagree.*units"):
        read_log(_write(tmp_path, [HEADER] + rows))


def test_omega_in_rpm_caught_without_v(tmp_path):
    rpm = 30.0 / 0.345 * 60 / (2 * np.pi)  # 830 rpm at 30 m/s
    path = _write(tmp_path, ["t,T_b,omega"] + [f"{k * 0.01:.2f},0,{rpm:.3f}" for k in range(20)])
    with pytest.raises(LogFormatError, match=r"log\.csv:2: column 'omega'.*rpm"):
        read_log(path)


def test_unknown_column_warns(tmp_path):
    path = _write(tmp_path, ["t,T_b,omega,temperature"] + [f"{k * 0.01:.2f},0,50,20" for k in range(10)])
    with pytest.warns(UserWarning, match="ignoring unknown column.*temperature"):
        read_log(path)


def test_unknown_plant_lists_valid():
    with pytest.raises(ValueError, match="valid plants: quarter-car, payload"):
        read_log("x.csv", plant="bicycle")


def test_missing_file(tmp_path):
    with pytest.raises(LogFormatError, match="no such file"):
        read_log(tmp_path / "absent.csv")


def test_payload_log_and_degree_check(tmp_path):
    header = "t,M,f_x,f_y,theta,X,Y"
    rows = [f"{k * 0.001:.3f},0.1,1,2,{0.01 * k:.3f},0.01,0.02" for k in range(20)]
    log = read_log(_write(tmp_path, [header] + rows), plant="payload")
    assert isinstance(log, PayloadLog) and log.dt == pytest.approx(0.001)
    deg = [f"{k * 0.001:.3f},0.1,1,2,{np.degrees(0.01 * k):.4f},0.01,0.02" for k in range(20)]
    with pytest.raises(LogFormatError, match=r"column 'theta'.*degrees"):
        read_log(_write(tmp_path, [header] + deg, "deg.csv"), plant="payload")
    mm = [f"{k * 0.001:.3f},0.1,1,2,0.0,{1000 * 0.5 * k * 0.001:.4f},0.0" for k in range(20)]  # 0.5 m/s in mm
    with pytest.raises(LogFormatError, match=r"column 'X'.*mm"):
        read_log(_write(tmp_path, [header] + mm, "mm.csv"), plant="payload")


def test_long_drifting_payload_log_is_valid(tmp_path):
    header = "t,M,f_x,f_y,theta,X,Y"
    rows = [f"{k * 0.01:.2f},0.1,1,2,{0.65 * k * 0.01:.4f},{0.2 * k * 0.01:.4f},0.0" for k in range(30000)]
    log = read_log(_write(tmp_path, [header] + rows), plant="payload")  # 300 s: theta 195 rad, X 60 m
    assert log.theta[-1] > 190


def test_failed_write_leaves_previous_file(tmp_path):
    path = tmp_path / "keep.csv"
    path.write_text("old\n")
    bad = QuarterCarLog(t=np.arange(3.0), T_b=np.zeros(3), omega=np.zeros(2))  # ragged: column_stack fails
    with pytest.raises(ValueError):
        write_log(path, bad)
    assert path.read_text() == "old\n"
    assert list(tmp_path.iterdir()) == [path]
