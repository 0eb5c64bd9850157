"""Log files of the sim-to-real gap tool (DESIGN.md, "Log file"): the one reader and writer.

CSV in SI units: optional leading ``#`` lines, one header row, then rows. Quarter car: required ``t`` [s],
``T_b`` [N m] (commanded torque), ``omega`` [rad/s]; optional ``v`` [m/s], ``a_x`` [m/s^2]. Payload: ``t``,
``M``, ``f_x``, ``f_y`` (raw sensor readings), ``theta``, ``X``, ``Y`` (vision). Unknown extra columns are ignored
with a warning. Every error names the file, and where it can the line and the column.
"""

from __future__ import annotations

import os
import re
import warnings
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from fricenv.errors import InvalidInputError
from fricenv.plants.sui_johansen import RADIUS
from fricenv.utils import atomic_write

__all__ = [
    "PLANTS",
    "LogFormatError",
    "PayloadLog",
    "QuarterCarLog",
    "read_log",
    "write_log",
]

# Relative jitter allowed in the time step before the log counts as non-uniform.
_DT_REL_TOL = 1e-3
# Plausibility limits, chosen to catch a wrong unit (rpm for rad/s, km/h for m/s, degrees for rad), not noise.
_MAX_WHEEL_SURFACE_SPEED = 100.0  # |omega| r above this [m/s] (360 km/h) means omega is not in rad/s
_MAX_SPEED = 100.0  # [m/s]
_MAX_ACCEL = 30.0  # |a_x| [m/s^2], about 3 g
_MAX_TORQUE = 2.0e4  # |T_b| [N m]
# omega r / v while rolling, if v is logged: rpm gives ~9.5 and v in km/h ~0.28 or ~3.6; the upper bound leaves
# room for the traction overshoot of a wheel spinning up after a brake release (relaxation length at low speed)
_OMEGA_R_OVER_V = (0.5, 2.5)
_ROLLING_PERCENTILE = 95.0  # of omega r / v over the moving samples
# Payload: median rates; a pose in degrees or mm (with its vision noise) moves 57x or 1000x "faster".
_MAX_ANGULAR_RATE = 50.0  # median |theta'| [rad/s]
_MAX_LINEAR_RATE = 20.0  # median |X'|, |Y'| [m/s]
_NOMINAL_RADIUS = RADIUS  # [m], Sui & Johansen Table I; only used for the unit checks


# SI unit of each column; a header cell may carry it as "omega [rad/s]" or "omega (rad/s)".
_SI_UNITS = {"t": "s", "T_b": "N m", "omega": "rad/s", "v": "m/s", "a_x": "m/s^2",
             "M": "N m", "f_x": "N", "f_y": "N", "theta": "rad", "X": "m", "Y": "m"}
_HEADER_UNIT = re.compile(r"^(?P<name>[^\[\]()]+?)\s*(\[(?P<u1>[^\]]*)\]|\((?P<u2>[^)]*)\))$")
# A number as a CSV holds it: ASCII decimal, optional exponent, or nan/inf (rejected later with their line). Python's
# float() alone would also take "1_0" and non-ASCII digits.
_NUMBER = re.compile(r"^\s*[+-]?((\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|nan|inf|infinity)\s*$", re.IGNORECASE | re.ASCII)


def _unit_key(unit: str) -> str:
    """A unit spelling reduced for comparison: "N m", "N*m", "N.m" and "Nm" agree, so do "m/s^2" and "m/s2"."""
    return re.sub(r"[\s*.^]", "", unit).replace("\u00b2", "2")


class LogFormatError(InvalidInputError):
    """A log file that does not follow the DESIGN.md contract (a ``ValueError``; one line naming the file)."""


@dataclass(frozen=True)
class QuarterCarLog:
    """A quarter-car braking log; arrays share one length."""

    t: np.ndarray  # time [s], uniform step
    T_b: np.ndarray  # commanded brake torque [N m]
    omega: np.ndarray  # measured wheel speed [rad/s]
    v: np.ndarray | None = None  # reference ground speed [m/s]
    a_x: np.ndarray | None = None  # longitudinal acceleration [m/s^2], negative when braking
    comments: tuple[str, ...] = field(default=(), compare=False)  # the leading '#' lines, without '#'
    source: str = field(default="<memory>", compare=False)

    REQUIRED = ("t", "T_b", "omega")
    OPTIONAL = ("v", "a_x")

    @property
    def dt(self) -> float:
        """Sample time [s]."""
        return float(self.t[1] - self.t[0])

    def __len__(self) -> int:
        return len(self.t)


@dataclass(frozen=True)
class PayloadLog:
    """A planar-payload log (raw force-moment sensor readings and vision pose)."""

    t: np.ndarray  # time [s], uniform step
    M: np.ndarray  # raw moment reading [N m]
    f_x: np.ndarray  # raw force reading, x [N]
    f_y: np.ndarray  # raw force reading, y [N]
    theta: np.ndarray  # vision orientation [rad]
    X: np.ndarray  # vision position, x [m]
    Y: np.ndarray  # vision position, y [m]
    comments: tuple[str, ...] = field(default=(), compare=False)
    source: str = field(default="<memory>", compare=False)

    REQUIRED = ("t", "M", "f_x", "f_y", "theta", "X", "Y")
    OPTIONAL = ()

    @property
    def dt(self) -> float:
        """Sample time [s]."""
        return float(self.t[1] - self.t[0])

    def __len__(self) -> int:
        return len(self.t)


PLANTS: dict[str, type] = {"quarter-car": QuarterCarLog, "payload": PayloadLog}


def _log_class(plant: str) -> type:
    try:
        return PLANTS[plant]
    except KeyError:
        raise ValueError(f"unknown plant {plant!r}; valid plants: {', '.join(PLANTS)}") from None


def _parse(path: Path):
    """Comments, header and a float table with the file line number of each row."""
    try:
        text = path.read_text(encoding="utf-8-sig")  # -sig: a leading byte-order mark is not part of the header
    except FileNotFoundError:
        raise LogFormatError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise LogFormatError(f"{path}: is a directory, expected a CSV file") from None
    except UnicodeDecodeError:
        raise LogFormatError(f"{path}: not a text (CSV) file") from None
    except OSError as exc:
        raise LogFormatError(f"{path}: cannot read the file ({exc.strerror})") from None
    comments: list[str] = []
    header: list[str] | None = None
    rows: list[list[float]] = []
    line_numbers: list[int] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if header is None:
            if line.startswith("#"):
                comments.append(line[1:].strip())
                continue
            header = [_column_name(path, lineno, cell) for cell in line.split(",")]
            if len(set(header)) != len(header):
                dup = sorted({h for h in header if header.count(h) > 1})
                raise LogFormatError(f"{path}:{lineno}: duplicate column(s) {', '.join(dup)} in header")
            continue
        cells = line.split(",")
        if len(cells) != len(header):
            raise LogFormatError(f"{path}:{lineno}: {len(cells)} values, the header has {len(header)} columns")
        for name, cell in zip(header, cells):
            if not _NUMBER.match(cell):
                raise LogFormatError(f"{path}:{lineno}: column {name!r}: {cell.strip()!r} is not a number")
        rows.append([float(cell) for cell in cells])
        line_numbers.append(lineno)
    if header is None:
        raise LogFormatError(f"{path}: no header row")
    if len(rows) < 3:
        raise LogFormatError(f"{path}: needs at least 3 data rows, found {len(rows)}")
    return comments, header, np.array(rows, dtype=float), np.array(line_numbers)


def _column_name(path: Path, lineno: int, cell: str) -> str:
    """The column name of a header cell; a unit in brackets is accepted if it is the column's SI unit."""
    cell = cell.strip()
    match = _HEADER_UNIT.match(cell)
    if match is None or match["name"].strip() not in _SI_UNITS:
        return cell
    name, unit = match["name"].strip(), (match["u1"] if match["u1"] is not None else match["u2"]).strip()
    if _unit_key(unit) != _unit_key(_SI_UNITS[name]):
        raise LogFormatError(f"{path}:{lineno}: column {cell!r}: unit {unit!r}, expected {_SI_UNITS[name]}; "
                             f"convert the column to SI units")
    return name


def _check_time(path: Path, t: np.ndarray, lines: np.ndarray) -> None:
    with np.errstate(over="ignore"):
        dt = np.diff(t)
    huge = np.flatnonzero(~np.isfinite(dt))
    if huge.size:
        i = huge[0] + 1
        raise LogFormatError(f"{path}:{lines[i]}: column 't' jumps from {t[i - 1]:.6g} to {t[i]:.6g}; "
                             f"expected a time in seconds")
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        i = bad[0] + 1
        raise LogFormatError(f"{path}:{lines[i]}: column 't' is not increasing ({t[i - 1]:.6g} then {t[i]:.6g})")
    step = float(np.median(dt))
    off = np.flatnonzero(np.abs(dt - step) > _DT_REL_TOL * step)
    if off.size:
        i = off[0] + 1
        raise LogFormatError(
            f"{path}:{lines[i]}: column 't' has a non-uniform step ({dt[i - 1]:.6g} s where the log's step is "
            f"{step:.6g} s); resample the log to a uniform step"
        )


def _check_range(path: Path, name: str, x: np.ndarray, lines: np.ndarray, limit: float, hint: str) -> None:
    bad = np.flatnonzero(np.abs(x) > limit)
    if bad.size:
        i = bad[0]
        raise LogFormatError(
            f"{path}:{lines[i]}: column {name!r}: value {x[i]:.6g} is implausible ({hint}, limit {limit:g})"
        )


def _check_quarter_car(path: Path, cols: dict[str, np.ndarray], lines: np.ndarray) -> None:
    r = _NOMINAL_RADIUS
    _check_range(path, "omega", cols["omega"], lines, _MAX_WHEEL_SURFACE_SPEED / r,
                 "expected rad/s; is it in rpm?")
    _check_range(path, "T_b", cols["T_b"], lines, _MAX_TORQUE, "expected N m")
    if "v" in cols:
        _check_range(path, "v", cols["v"], lines, _MAX_SPEED, "expected m/s; is it in km/h?")
        moving = cols["v"] > 1.0
        if np.count_nonzero(moving) >= 3:
            # A high percentile, not the median: a braking log may keep the wheel locked (ratio 0) most of the
            # time, but some stretch rolls freely (ratio ~1), while rpm gives ~9.5 and km/h ~0.28 throughout.
            ratio = float(np.percentile(cols["omega"][moving] * r / cols["v"][moving], _ROLLING_PERCENTILE))
            lo, hi = _OMEGA_R_OVER_V
            if not lo <= ratio <= hi:
                raise LogFormatError(
                    f"{path}: columns 'omega' and 'v' disagree: omega*r/v = {ratio:.3g} while rolling "
                    f"({_ROLLING_PERCENTILE:g}th percentile, r = {r} m; expected near 1); check the units "
                    f"(rad/s and m/s)"
                )
    if "a_x" in cols:
        _check_range(path, "a_x", cols["a_x"], lines, _MAX_ACCEL, "expected m/s^2")


def _check_rate(path: Path, name: str, x: np.ndarray, t: np.ndarray, lines: np.ndarray, limit: float,
                hint: str) -> None:
    """The median rate |dx/dt| must be plausible; a median, so a free body may drift far over a long log."""
    with np.errstate(over="ignore"):  # a jump too large for a float is an infinite rate, flagged below
        rates = np.abs(np.diff(x)) / np.diff(t)
    rate = float(np.median(rates))
    if rate > limit:
        first = int(np.flatnonzero(rates > limit)[0]) + 1
        raise LogFormatError(f"{path}:{lines[first]}: column {name!r}: median rate {rate:.4g} per s is implausible "
                             f"({hint}, limit {limit:g}; first exceeded here)")


def _check_payload(path: Path, cols: dict[str, np.ndarray], lines: np.ndarray) -> None:
    t = cols["t"]
    _check_rate(path, "theta", cols["theta"], t, lines, _MAX_ANGULAR_RATE, "expected rad; is it in degrees?")
    for name in ("X", "Y"):
        _check_rate(path, name, cols[name], t, lines, _MAX_LINEAR_RATE, "expected m; is it in mm?")


def read_log(path: str | os.PathLike, plant: str = "quarter-car") -> QuarterCarLog | PayloadLog:
    """Read and validate a log file.

    :param path: CSV file in the DESIGN.md format.
    :param plant: ``"quarter-car"`` or ``"payload"``.
    :return: a :class:`QuarterCarLog` or :class:`PayloadLog`.
    :raises LogFormatError: naming the file, line and column of the first problem.
    """
    cls = _log_class(plant)
    path = Path(path)
    comments, header, table, lines = _parse(path)
    missing = [name for name in cls.REQUIRED if name not in header]
    if missing:
        raise LogFormatError(
            f"{path}: missing required column(s) {', '.join(missing)} for a {plant} log "
            f"(required: {', '.join(cls.REQUIRED)}; optional: {', '.join(cls.OPTIONAL) or 'none'})"
        )
    known = set(cls.REQUIRED) | set(cls.OPTIONAL)
    extra = [name for name in header if name not in known]
    if extra:
        warnings.warn(f"{path}: ignoring unknown column(s) {', '.join(extra)}", stacklevel=2)
    cols = {name: table[:, header.index(name)] for name in header if name in known}
    for name, x in cols.items():
        bad = np.flatnonzero(~np.isfinite(x))
        if bad.size:
            raise LogFormatError(f"{path}:{lines[bad[0]]}: column {name!r} is NaN or infinite")
    _check_time(path, cols["t"], lines)
    (_check_quarter_car if plant == "quarter-car" else _check_payload)(path, cols, lines)
    return cls(**cols, comments=tuple(comments), source=str(path))


def write_log(path: str | os.PathLike, log: QuarterCarLog | PayloadLog, comments: tuple[str, ...] = ()) -> None:
    """Write a log atomically in the DESIGN.md format; optional columns that are ``None`` are left out.

    :param path: destination CSV.
    :param log: the log to write.
    :param comments: lines written first, each behind ``# `` (defaults to ``log.comments``).
    """
    names = [f.name for f in fields(log) if f.name not in ("comments", "source")]
    names = [name for name in names if getattr(log, name) is not None]
    table = np.column_stack([np.asarray(getattr(log, name), dtype=float) for name in names])
    with atomic_write(path) as fh:
        for line in comments or log.comments:
            fh.write(f"# {line}\n")
        fh.write(",".join(names) + "\n")
        np.savetxt(fh, table, delimiter=",", fmt="%.10g")
