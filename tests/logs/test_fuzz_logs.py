"""Fuzz the log reader (fricenv/logs.py): whatever the bytes, read_log gives a parsed log or a one-line
LogFormatError (a FricenvError and ValueError) that names the file, and the line and column where one applies."""

import math
import re
import string
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from fricenv.errors import FricenvError
from fricenv.logs import PLANTS, LogFormatError, read_log

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
R = 0.345  # nominal radius [m], for plausible quarter-car rows
SI_UNITS = {"t": "s", "T_b": "N m", "omega": "rad/s", "v": "m/s", "a_x": "m/s^2", "throttle": "%",
            "yaw_rate": "rad/s", "steer": "rad", **{w: "rad/s" for w in ("omega_fl", "omega_fr", "omega_rl", "omega_rr")},
            "M": "N m", "f_x": "N", "f_y": "N", "theta": "rad", "X": "m", "Y": "m"}


def _plausible(name: str, k: int, dt: float, rng: np.random.Generator) -> float:
    """A value a real log could hold in column ``name`` at sample ``k``."""
    if name == "t":
        return k * dt
    v = 20.0 - 0.05 * k
    if name.startswith("omega"):  # the mapped wheel and the other four
        return v / R * rng.uniform(0.9, 1.0)
    return {"T_b": rng.uniform(0, 1500), "v": v, "throttle": rng.uniform(0, 100), "yaw_rate": rng.uniform(-0.5, 0.5),
            "steer": rng.uniform(-0.3, 0.3),
            "a_x": rng.uniform(-9, 0), "theta": 0.01 * k, "X": 0.001 * k, "Y": 0.002 * k}.get(name,
                                                                                          rng.uniform(-5, 5))


@st.composite
def valid_logs(draw):
    """(plant, header, table): a valid log with its columns in random order and maybe extra ones."""
    plant = draw(st.sampled_from(sorted(PLANTS)))
    cls = PLANTS[plant]
    names = list(cls.REQUIRED) + [n for n in cls.OPTIONAL if draw(st.booleans())]
    names += draw(st.lists(st.sampled_from(["temperature", "note_1", "rpm"]), unique=True, max_size=2))
    names = draw(st.permutations(names))
    n = draw(st.integers(3, 40))
    dt = draw(st.sampled_from([0.001, 0.01, 0.02]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    table = np.array([[_plausible(c, k, dt, rng) for c in names] for k in range(n)])
    return plant, names, table


def _text(header, table, *, bom=False, crlf=False, comments=(), units=False):
    head = [f"{c} [{SI_UNITS[c]}]" if units and c in SI_UNITS else c for c in header]
    lines = [f"# {c}" for c in comments] + [",".join(head)] + [",".join(f"{x:.10g}" for x in row) for row in table]
    return ("\ufeff" if bom else "") + ("\r\n" if crlf else "\n").join(lines) + "\n"


def _read(path, plant):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # unknown columns are ignored with a warning, by contract
        warnings.simplefilter("error", RuntimeWarning)  # an overflow or NaN warning on the way is a defect
        return read_log(path, plant)


def _check_error(exc: BaseException, path) -> str:
    assert isinstance(exc, LogFormatError) and isinstance(exc, FricenvError) and isinstance(exc, ValueError)
    msg = str(exc)
    assert "\n" not in msg and msg.startswith(str(path)), msg
    return msg


@FUZZ
@given(valid_logs(), st.booleans(), st.booleans(), st.booleans(),
       st.lists(st.text(string.printable.replace("\n", "").replace("\r", "").replace("\x0b", "").replace("\x0c", "")
                        .replace("\x1c", ""), max_size=20), max_size=3))
def test_valid_logs_read_back_whatever_the_column_order(tmp_path, log, bom, crlf, units, comments):
    plant, header, table = log
    path = tmp_path / "log.csv"
    path.write_bytes(_text(header, table, bom=bom, crlf=crlf, comments=comments, units=units).encode())
    back = _read(path, plant)
    cls = PLANTS[plant]
    for name in (*cls.REQUIRED, *cls.OPTIONAL):
        column = getattr(back, name)
        if name in header:
            np.testing.assert_allclose(column, table[:, header.index(name)], rtol=1e-9, atol=0)
        else:
            assert column is None
    assert back.comments == tuple(c.strip() for c in comments)


BAD_CELLS = ["inf", "-inf", "1e400", "-1e999", "abc", "1,5", "0x10", "1e", "--1", "\u00a0", "12 3", "1_0", "∞", "１２"]
MISSING_CELLS = ["nan", "NaN", "", " "]  # a missing sample: an error in t and T_b only (omega: filled inside)


@FUZZ
@given(valid_logs(), st.data())
def test_a_bad_cell_is_named_by_line_and_column(tmp_path, log, data):
    plant, header, table = log
    required = list(PLANTS[plant].REQUIRED)
    row = data.draw(st.integers(0, len(table) - 1), label="row")
    col = header.index(data.draw(st.sampled_from(required), label="column"))
    cell = data.draw(st.sampled_from(BAD_CELLS + MISSING_CELLS), label="cell")
    lines = _text(header, table).splitlines()
    cells = lines[1 + row].split(",")
    cells[col] = cell
    lines[1 + row] = ",".join(cells)
    path = tmp_path / "log.csv"
    path.write_text("\n".join(lines) + "\n")
    name = header[col]
    if cell in MISSING_CELLS and name not in ("t", "T_b", "omega") and len(table) == 3:
        if name in PLANTS[plant].OPTIONAL:  # too few values left to read the channel: left out, or an error
            assert getattr(_read(path, plant), name) is None
            return
        with pytest.raises(LogFormatError, match=rf"^{re.escape(str(path))}: column {name!r} has 2 values; needs "):
            _read(path, plant)
        return
    if cell in MISSING_CELLS and (name not in ("t", "T_b", "omega") or name == "omega" and 0 < row < len(table) - 1):
        back = _read(path, plant)  # a missing sample where the contract allows one: NaN, or filled in omega
        assert np.isfinite(back.omega[row]) if name == "omega" else np.isnan(getattr(back, name)[row])
        assert back.missing[name] == (0.0 if name == "omega" else 1 / len(table))
        return
    with pytest.raises(LogFormatError) as info:
        _read(path, plant)
    msg = _check_error(info.value, path)
    if "," in cell:
        assert f"{path}:{row + 2}: {len(cells) + 1} values, the header has {len(header)} columns" in msg
    else:
        assert msg.startswith(f"{path}:{row + 2}: column {header[col]!r}"), msg


@FUZZ
@given(valid_logs(), st.data())
def test_a_truncated_line_is_named(tmp_path, log, data):
    plant, header, table = log
    text = _text(header, table)
    lines = text.splitlines()
    row = data.draw(st.integers(1, len(lines) - 1), label="line")
    cut = data.draw(st.integers(0, len(lines[row]) - 1), label="cut")
    if row == len(lines) - 1 and data.draw(st.booleans(), label="at end of file"):
        lines = lines[:row] + [lines[row][:cut]]  # a log cut off while being written
    else:
        lines[row] = lines[row][:cut]
    assume(lines[row].count(",") < len(header) - 1)
    path = tmp_path / "log.csv"
    path.write_text("\n".join(lines))
    try:
        _read(path, plant)
    except LogFormatError as exc:
        msg = _check_error(exc, path)
        if lines[row].strip():
            assert msg.startswith(f"{path}:{row + 1}:"), msg
    else:  # only an emptied last line can still leave a valid log
        assert not lines[row].strip()


@FUZZ
@given(st.binary(max_size=400), st.sampled_from(sorted(PLANTS)))
@example(b"", "quarter-car")
@example(b"t,T_b,omega\n", "quarter-car")
@example(b"\xef\xbb\xbf", "payload")
@example(b"t,T_b,omega\r\n0,0,50\r\n0.01,0,50\r\n", "quarter-car")
@example(b"\x00\x01\x02", "quarter-car")
@example(b"t,T_b,omega\n1e308,0,0\n-1e308,0,0\n1e308,0,0\n", "quarter-car")
@example(b"t,T_b,omega\n-1e308,0,0\n1e308,0,0\n1.1e308,0,0\n", "quarter-car")
@example(b"t,M,f_x,f_y,theta,X,Y\n0,0,0,0,-1e308,0,0\n1,0,0,0,1e308,0,0\n2,0,0,0,0,0,0\n", "payload")
@example(b"t,T_b,omega,v\n0,0,0,1e-300\n1,0,1e300,1e-300\n2,0,0,1.5\n3,0,0,2\n4,0,1,2\n", "quarter-car")
def test_any_bytes_give_a_log_or_one_line_error(tmp_path, raw, plant):
    path = tmp_path / "log.csv"
    path.write_bytes(raw)
    try:
        log = _read(path, plant)
    except LogFormatError as exc:
        _check_error(exc, path)
    else:
        assert len(log) >= 3 and all(math.isfinite(x) for x in log.t)


@FUZZ
@given(valid_logs(), st.data())
def test_text_and_huge_values_anywhere(tmp_path, log, data):
    """Random cells anywhere (header included) replaced by random text or huge numbers: a log or a one-line error
    naming the file and, when it is about one line, that line."""
    plant, header, table = log
    lines = _text(header, table).splitlines()
    for _ in range(data.draw(st.integers(1, 4), label="replacements")):
        row = data.draw(st.integers(0, len(lines) - 1))  # 0: the header
        cells = lines[row].split(",")
        col = data.draw(st.integers(0, len(cells) - 1))
        cells[col] = data.draw(st.one_of(
            st.text(alphabet=st.characters(blacklist_categories=("Cs",), blacklist_characters="\n\r,\x0b\x0c\x1c"
                                                                                                "\x1d\x1e\x85\u2028\u2029"),
                    max_size=8),
            st.floats(allow_nan=True, allow_infinity=True).map(repr),
            st.integers(-10**400, 10**400).map(str)))
        lines[row] = ",".join(cells)
    path = tmp_path / "log.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    try:
        _read(path, plant)
    except LogFormatError as exc:
        msg = _check_error(exc, path)
        located = re.match(rf"{re.escape(str(path))}(:\d+)?: ", msg)
        assert located, msg


def test_units_in_the_header_must_be_si(tmp_path):
    rows = [f"{k * 0.01:.2f},0,{20.0 / R:.3f}" for k in range(5)]
    path = tmp_path / "log.csv"
    path.write_text("t [s],T_b (N*m),omega [rad/s]\n" + "\n".join(rows) + "\n")
    assert len(read_log(path)) == 5
    path.write_text("t [s],T_b [N m],omega [rpm]\n" + "\n".join(rows) + "\n")
    with pytest.raises(LogFormatError, match=r"log\.csv:1: column 'omega \[rpm\]': unit 'rpm', expected rad/s"):
        read_log(path)
