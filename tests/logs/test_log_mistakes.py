"""Ten mistakes a person or a logger makes in a quarter-car export with a pressure-derived torque: each is caught by
the reader before any long work, as a one-line error (exit 2 on the command line) or a warning kept on the log."""

import json

import numpy as np
import pytest

from fricenv import cli
from fricenv.gap.quarter_car.simulate import simulate_log
from fricenv.logs import LogCheckWarning, read_log
from fricenv.plants.tire import ROADS

FACTOR = 2.0e-4  # nominal brake torque per line pressure [N m per Pa]
T0 = 1234.56  # the logger's clock at the first sample [s]
HEADER = "stamp,p_brake,wheel,speed,ax"  # the units are in the map only
MAP = {"plant": "quarter-car",
       "channels": {"t": {"column": "stamp", "unit": "s"}, "T_b": {"column": "p_brake", "unit": "kPa",
                                                                    "factor": FACTOR},
                    "omega": {"column": "wheel", "unit": "rad/s"}, "v": {"column": "speed", "unit": "m/s"},
                    "a_x": {"column": "ax", "unit": "m/s^2"}}}


@pytest.fixture(scope="module")
def export():
    """The columns of a clean export: an ABS stop on a dry road, the torque logged as a line pressure [kPa]."""
    log, _ = simulate_log([], ROADS["dry"], "abs", seed=5, duration=4.0)
    return {"stamp": T0 + log.t, "p_brake": log.T_b / FACTOR / 1e3, "wheel": log.omega, "speed": log.v,
            "ax": log.a_x}


def _write(tmp_path, cols: dict, cmap: dict = MAP, header: str = HEADER):
    table = np.column_stack([cols[k] for k in ("stamp", "p_brake", "wheel", "speed", "ax")])
    path = tmp_path / "export.csv"
    path.write_text(header + "\n" + "\n".join(",".join(map(repr, row)) for row in table.tolist()) + "\n")
    map_path = tmp_path / "export.map.json"
    map_path.write_text(json.dumps(cmap))
    return path, map_path


def _with(cols, **changes):
    return {**cols, **changes}


def _swapped(cols):
    return _with(cols, wheel=cols["speed"], speed=cols["wheel"])


def _gap(cols):
    stamp = cols["stamp"].copy()
    stamp[len(stamp) // 2:] += 5.0
    return _with(cols, stamp=stamp)


def _map_unit(unit):
    return {**MAP, "channels": {**MAP["channels"], "t": {"column": "stamp", "unit": unit}}}


# name -> (columns, map, what the one line must say: an error's text, or the channel of a warning)
MISTAKES = {
    "ms for s": (lambda c: _with(c, stamp=c["stamp"] * 1e3), MAP, "error", r"column 't'.*0\.1 Hz.*ms"),
    "s for ms": (lambda c: c, _map_unit("ms"), "error", r"column 't'.*1e\+05 Hz.*s read as ms"),
    "km/h for m/s": (lambda c: _with(c, speed=c["speed"] * 3.6), MAP, "error",
                     r"column 'v'.*is it in km/h|'omega' and 'v' disagree"),
    "negated v": (lambda c: _with(c, speed=-c["speed"]), MAP, "error", r"column 'v' is negative"),
    "negated a_x": (lambda c: _with(c, ax=-c["ax"]), MAP, "warning", r"a_x: its sign disagrees"),
    "negated omega": (lambda c: _with(c, wheel=-c["wheel"]), MAP, "error", r"column 'omega' is negative"),
    "bar for kPa": (lambda c: _with(c, p_brake=c["p_brake"] / 100.0), MAP, "error",
                    r"column 'T_b': its size cannot be a brake torque"),
    "v and omega swapped": (_swapped, MAP, "error", r"'omega' and 'v' disagree"),
    "5 s gap in t": (_gap, MAP, "error", r"column 't': gap of 5\.01 s"),
    "constant omega": (lambda c: _with(c, wheel=np.full_like(c["wheel"], c["wheel"][0])), MAP, "error",
                       r"column 'omega' is constant"),
}


def test_the_clean_export_reads_without_a_warning(tmp_path, export, recwarn):
    path, map_path = _write(tmp_path, export)
    log = read_log(path, column_map=map_path)
    assert log.warnings == () and not [w for w in recwarn if issubclass(w.category, LogCheckWarning)]
    assert log.t[0] == 0.0 and log.t_offset == T0 and log.a_x is not None and log.torque_from_pressure


def test_ten_mistakes_each_give_one_line(tmp_path, export, capsys):
    """Through ``fricenv gap convert``: an error is one line on stderr and exit 2, a warning one line on stderr, the
    converted log's comments and the log object's ``warnings`` (the channel leading)."""
    import re

    for name, (change, cmap, kind, said) in MISTAKES.items():
        folder = tmp_path / name.replace(" ", "_").replace("/", "_")
        folder.mkdir()
        path, map_path = _write(folder, change(export), cmap)
        out = folder / "log.csv"
        code = cli.main(["gap", "convert", str(path), "--map", str(map_path), "--out", str(out)])
        err = capsys.readouterr().err.strip().splitlines()
        if kind == "error":
            assert code == 2 and len(err) == 1 and re.search(said, err[0]), (name, code, err)
            assert str(path) in err[0] and not out.exists(), name
        else:
            assert code == 0 and len(err) == 1 and err[0].startswith("warning: ") and re.search(said, err[0]), (
                name, err)
            with pytest.warns(LogCheckWarning, match=said):
                direct = read_log(path, column_map=map_path)
            assert [w.split(":")[0] for w in direct.warnings] == ["a_x"] and direct.a_x is None, name
            assert read_log(out).warnings == direct.warnings, name  # carried by the converted log


def test_diagnose_stops_on_a_mistake_before_any_work(tmp_path, export, capsys):
    path, map_path = _write(tmp_path, _with(export, stamp=export["stamp"] * 1e3))
    code = cli.main(["gap", "diagnose", str(path), "--map", str(map_path), "--out", str(tmp_path / "rep"),
                     "--no-plots"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "outside 10 Hz - 1 kHz" in err[0]
    assert not (tmp_path / "rep" / "report.json").exists()
