"""The column map of real exports (fricenv/logmap.py through fricenv.logs.read_log): every unit, header units, any
column order, several wheels, the pressure marker, and a wrong map named by its key."""

import json
import math

import numpy as np
import pytest

from fricenv.logs import TORQUE_FROM_PRESSURE, LogFormatError, read_log, write_log
from fricenv.logs.logmap import ColumnMapError, find_unit, split_header_cell
from fricenv.logs.sensor_filter import SensorFilter

N = 12
R = 0.3  # wheel radius given in the maps [m]
FACTOR = 2.0e-4  # brake torque per pressure [N m per Pa]
# SI truth of each channel
TRUTH = {"t": np.arange(N) * 0.01, "T_b": 100.0 + 20.0 * np.arange(N), "omega": 60.0 - 0.5 * np.arange(N),
         "v": 18.5 - 0.1 * np.arange(N), "a_x": -4.0 + 0.05 * np.arange(N)}
QC_MAP = {"t": {"column": "time", "unit": "s"}, "T_b": {"column": "torque", "unit": "N m"},
          "omega": {"column": "w", "unit": "rad/s"}, "v": {"column": "speed", "unit": "m/s"},
          "a_x": {"column": "acc", "unit": "m/s^2"}}
EPOCH = 1_700_000_123.25  # [s]


def _export(tmp_path, cols: dict, channels: dict, name="export", comments=("logger x",), plant="quarter-car"):
    """Write an export (columns in the given order) and its map; returns (csv, map) paths."""
    csv, mp = tmp_path / f"{name}.csv", tmp_path / f"{name}.map.json"
    lines = [f"# {c}" for c in comments] + [",".join(cols)]
    lines += [",".join(repr(float(x)) for x in row) for row in zip(*cols.values())]
    csv.write_text("\n".join(lines) + "\n")
    mp.write_text(json.dumps({"plant": plant, "channels": channels}))
    return csv, mp


def _si_export(tmp_path, replace: tuple[str, str, dict, np.ndarray] | None = None, **kw):
    """The SI truth as an export; ``replace`` = (channel, header cell, map entry, values) swaps one channel."""
    names = {"t": "time", "T_b": "torque", "omega": "w", "v": "speed", "a_x": "acc"}
    cols = {names[c]: TRUTH[c] for c in TRUTH}
    channels = {c: dict(e) for c, e in QC_MAP.items()}
    if replace is not None:
        channel, cell, entry, values = replace
        del cols[names[channel]]
        cols[cell] = values
        channels[channel] = entry
    return _export(tmp_path, cols, channels, **kw)


# (channel, map entry, source values from the SI truth)
UNIT_CASES = [
    ("t", {"unit": "ms"}, lambda x: x * 1e3),
    ("t", {"unit": "epoch_s"}, lambda x: x + EPOCH),
    ("t", {"unit": "epoch_ms"}, lambda x: (x + EPOCH) * 1e3),
    ("omega", {"unit": "rpm"}, lambda x: x * 60 / (2 * math.pi)),
    ("omega", {"unit": "km/h", "radius": R}, lambda x: x * R * 3.6),
    ("omega", {"unit": "m/s", "radius": R}, lambda x: x * R),
    ("v", {"unit": "km/h"}, lambda x: x * 3.6),
    ("a_x", {"unit": "g"}, lambda x: x / 9.80665),
    ("T_b", {"unit": "kPa", "factor": FACTOR}, lambda x: x / FACTOR / 1e3),
    ("T_b", {"unit": "bar", "factor": FACTOR}, lambda x: x / FACTOR / 1e5),
    ("T_b", {"unit": "MPa", "factor": FACTOR}, lambda x: x / FACTOR / 1e6),
    ("T_b", {"unit": "Pa", "factor": FACTOR}, lambda x: x / FACTOR),
]


@pytest.mark.parametrize(("channel", "entry", "to_source"), UNIT_CASES,
                         ids=[f"{c}-{e['unit']}" for c, e, _ in UNIT_CASES])
def test_every_unit_converts_to_si(tmp_path, channel, entry, to_source):
    csv, mp = _si_export(tmp_path, (channel, "src", {"column": "src", **entry}, to_source(TRUTH[channel])))
    log = read_log(csv, column_map=mp)
    for name, truth in TRUTH.items():  # epoch ms carries ~1e-4 ms of float rounding at 1.7e12
        np.testing.assert_allclose(getattr(log, name), truth, rtol=1e-12, atol=1e-6 if name == "t" else 1e-12)
    assert log.torque_from_pressure == (channel == "T_b" and entry["unit"] != "N m")
    assert log.resampled is None  # the stamps were uniform: nothing resampled


def test_payload_units_deg_mm_and_header_units(tmp_path):
    t = np.arange(N) * 0.01
    theta, X, Y = 0.1 + 0.02 * np.arange(N), 0.5 + 1e-3 * np.arange(N), -0.2 + 2e-3 * np.arange(N)
    cols = {"yaw(deg)": np.degrees(theta), "x [mm]": X * 1e3, "y (cm)": Y * 1e2, "stamp[ms]": t * 1e3,
            "Mz": np.full(N, 0.5) + 0.01 * np.arange(N), "Fx": 1.0 + 0.1 * np.arange(N), "Fy": 2.0 - 0.1 * np.arange(N)}
    channels = {"t": {"column": "stamp"}, "theta": {"column": "yaw"}, "X": {"column": "x"}, "Y": {"column": "y"},
                "M": "Mz", "f_x": "Fx", "f_y": "Fy"}
    csv, mp = _export(tmp_path, cols, channels, plant="payload")
    log = read_log(csv, "payload", column_map=mp)
    np.testing.assert_allclose(log.t, t, atol=1e-12)
    for got, truth in ((log.theta, theta), (log.X, X), (log.Y, Y), (log.f_x, cols["Fx"])):
        np.testing.assert_allclose(got, truth, rtol=1e-12)


def test_any_column_order_extra_columns_and_comments(tmp_path):
    names = {"t": "time", "T_b": "torque", "omega": "w", "v": "speed", "a_x": "acc"}
    order = ["acc", "gear", "w", "time", "speed", "torque", "steer"]
    src = {names[c]: TRUTH[c] for c in TRUTH} | {"gear": np.full(N, 3.0), "steer": np.linspace(0, 1, N)}
    csv, mp = _export(tmp_path, {k: src[k] for k in order}, QC_MAP, comments=("CAN export", "car 7"))
    log = read_log(csv, column_map=mp)
    assert log.comments[:2] == ("CAN export", "car 7")
    for name, truth in TRUTH.items():
        np.testing.assert_array_equal(getattr(log, name), truth)


def test_the_map_picks_one_wheel_among_several(tmp_path):
    rim = TRUTH["omega"] * R * 3.6
    cols = {"time": TRUTH["t"], "torque": TRUTH["T_b"], "wheel_fl(kmph)": rim * 1.05, "wheel_rl(kmph)": rim,
            "wheel_rr(kmph)": rim * 0.97}
    channels = {"t": "time", "T_b": "torque", "omega": {"column": "wheel_rl", "radius": R}}  # unit from the header
    csv, mp = _export(tmp_path, cols, channels)
    np.testing.assert_allclose(read_log(csv, column_map=mp).omega, TRUTH["omega"], rtol=1e-12)


def test_torque_from_pressure_survives_the_contract_file(tmp_path):
    csv, mp = _si_export(tmp_path, ("T_b", "p", {"column": "p", "unit": "bar", "factor": FACTOR},
                                    TRUTH["T_b"] / FACTOR / 1e5))
    log = read_log(csv, column_map=mp)
    assert log.torque_from_pressure and TORQUE_FROM_PRESSURE in log.comments
    write_log(tmp_path / "contract.csv", log)
    back = read_log(tmp_path / "contract.csv")
    assert back.torque_from_pressure
    np.testing.assert_allclose(back.T_b, TRUTH["T_b"], rtol=1e-9)
    plain = read_log(_si_export(tmp_path, name="plain")[0], column_map=_si_export(tmp_path, name="plain")[1])
    assert not plain.torque_from_pressure


def test_a_stated_sensor_filter_survives_the_contract_file(tmp_path):
    """The map's ``filter`` (a data sheet's IMU filter) becomes a ``sensor_filter:`` comment of the contract CSV,
    which the reader turns back into ``sensor_filters``; a log without one has none."""
    entry = {"column": "acc", "unit": "m/s^2", "filter": {"order": 2, "cutoff_hz": 5}}
    csv, mp = _si_export(tmp_path, ("a_x", "acc", entry, TRUTH["a_x"]))
    log = read_log(csv, column_map=mp)
    assert log.sensor_filters == {"a_x": SensorFilter(2, 5.0)}
    assert "sensor_filter: a_x butterworth order=2 cutoff_hz=5" in log.comments
    write_log(tmp_path / "contract.csv", log)
    assert read_log(tmp_path / "contract.csv").sensor_filters == {"a_x": SensorFilter(2, 5.0)}
    assert read_log(_si_export(tmp_path, name="plain")[0], column_map=_si_export(tmp_path, name="plain")[1]) \
        .sensor_filters == {}


def test_a_malformed_sensor_filter_line_is_a_clear_error(tmp_path):
    path = tmp_path / "log.csv"
    rows = "\n".join(f"{t},{T},{w}" for t, T, w in zip(TRUTH["t"], TRUTH["T_b"], TRUTH["omega"]))
    path.write_text(f"# sensor_filter: a_x butterworth order=two cutoff_hz=5\nt,T_b,omega\n{rows}\n")
    with pytest.raises(LogFormatError, match=r"log\.csv: comment line: .*order must be an integer"):
        read_log(path)


def _map_error(tmp_path, channels: dict, cols=None, plant="quarter-car", read_plant="quarter-car") -> str:
    base = {"time": TRUTH["t"], "torque": TRUTH["T_b"], "w": TRUTH["omega"], "wheel_rl(kmph)": TRUTH["omega"]}
    csv, mp = _export(tmp_path, cols or base, channels, plant=plant)
    with pytest.raises(ColumnMapError) as info:
        read_log(csv, read_plant, column_map=mp)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(str(mp)), msg
    return msg


OK = {"t": "time", "T_b": "torque", "omega": "w"}
WRONG_MAPS = [
    ({**OK, "wheel": "w"}, "channels.wheel: unknown channel; valid channels: t, T_b, omega, v, a_x"),
    ({"t": "time", "T_b": "torque"}, "channels.omega: required for a quarter-car log"),
    ({**OK, "omega": {"column": "w", "unit": "kmh/s"}}, "channels.omega.unit: 'kmh/s' is not a unit of 'omega'"),
    ({**OK, "v": {"column": "w", "unit": "g"}}, "channels.v.unit: 'g' is not a unit of 'v'; valid units: m/s, km/h"),
    ({**OK, "omega": {"column": "w", "unit": "km/h"}}, "channels.omega.radius: required for a wheel rim speed"),
    ({**OK, "T_b": {"column": "torque", "unit": "kPa"}}, "channels.T_b.factor: required for a brake pressure in kPa"),
    ({**OK, "T_b": {"column": "torque", "unit": "kPa", "factor": -1}}, "channels.T_b.factor: must be a positive"),
    ({**OK, "omega": {"column": "w", "colum": "w"}}, "channels.omega.colum: unknown key; valid keys: column, unit"),
    ({**OK, "omega": "wheel_fr"}, "channels.omega.column: 'wheel_fr': no such column in "),
    ({**OK, "omega": {"column": "wheel_rl", "unit": "rpm"}}, "channels.omega.unit: 'rpm', but the column header says"),
    ({**OK, "omega": {"column": "w", "unit": 3}}, "channels.omega.unit: 3 is not a unit of 'omega'"),
    ({**OK, "omega": {"column": "w", "filter": {"order": 2, "cutoff_hz": 5}}},
     "channels.omega.filter: a stated sensor filter is used for v, a_x only, not 'omega'"),
    ({**OK, "a_x": {"column": "w", "filter": {"order": 2}}}, "channels.a_x.filter: 'cutoff_hz' is required"),
    ({**OK, "a_x": {"column": "w", "filter": {"order": 2, "cutoff": 5}}},
     "channels.a_x.filter: unknown key 'cutoff'; valid keys: order, cutoff_hz"),
    ({**OK, "a_x": {"column": "w", "filter": {"order": 2.5, "cutoff_hz": 5}}},
     "channels.a_x.filter: order must be an integer from 1 to 8, got 2.5"),
    ({**OK, "v": {"column": "w", "filter": {"order": 2, "cutoff_hz": 0}}},
     "channels.v.filter: cutoff_hz must be a positive number of Hz, got 0"),
    ({**OK, "v": {"column": "w", "filter": "5 Hz"}}, "channels.v.filter: must be an object like"),
]


@pytest.mark.parametrize(("channels", "expected"), WRONG_MAPS, ids=[e.split(":")[0] for _, e in WRONG_MAPS])
def test_a_wrong_map_is_one_line_naming_the_key(tmp_path, channels, expected):
    assert expected in _map_error(tmp_path, channels)


def test_a_map_for_another_plant_or_without_channels(tmp_path):
    assert ": plant: the map is for 'payload', the log is read as 'quarter-car'" in _map_error(tmp_path, OK,
                                                                                               plant="payload")
    mp = tmp_path / "bad.map.json"
    mp.write_text(json.dumps({"columns": OK}))
    csv = _export(tmp_path, {"time": TRUTH["t"]}, OK)[0]
    with pytest.raises(ColumnMapError, match=r"bad\.map\.json: columns: unknown key; valid keys: plant, channels"):
        read_log(csv, column_map=mp)


def test_unit_spellings_and_header_cells():
    assert [find_unit(u) for u in ("kmph", "KPH", "km/h", "N*m", "Nm", "m/s2", "m/s²", "MPA", "1/min", "furlong")] == \
        ["km/h", "km/h", "km/h", "N m", "N m", "m/s^2", "m/s^2", "MPa", "rpm", None]
    assert split_header_cell("wheel_rl(kmph)") == ("wheel_rl", "kmph")
    assert split_header_cell(" p_brake [kPa] ") == ("p_brake", "kPa")
    assert split_header_cell("timestamp") == ("timestamp", None)
