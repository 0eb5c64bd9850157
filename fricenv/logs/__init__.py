"""Log files of the sim-to-real gap tool (DESIGN.md, "Log file"): the one reader and writer.

CSV in SI units: optional leading ``#`` lines, one header row, then rows. Quarter car: required ``t`` [s],
``T_b`` [N m] (commanded torque), ``omega`` [rad/s]; optional ``v`` [m/s], ``a_x`` [m/s^2]. Payload: ``t``,
``M``, ``f_x``, ``f_y`` (raw sensor readings), ``theta``, ``X``, ``Y`` (vision). Unknown extra columns are ignored
with a warning. Every error names the file, and where it can the line and the column.

Real exports (docs/contracts.md, section 1): ``read_log(path, plant, column_map=MAP)`` reads any CSV whose columns
a column map (:mod:`fricenv.logs.logmap`) names, in the map's units. Jittered time stamps and dropped rows are
resampled onto a uniform grid, held samples of a slower channel are marked missing (NaN), and the log records what was done
(``resampled``, ``missing``, ``torque_from_pressure``); the rules are in :mod:`fricenv.logs.resample`.
"""

from __future__ import annotations

import os
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fricenv.errors import InvalidInputError
from fricenv.logs import resample as rs
from fricenv.logs.logmap import HEADER_UNIT as _HEADER_UNIT
from fricenv.logs.logmap import SI_UNITS as _SI_UNITS
from fricenv.logs.logmap import UNITS, ColumnMap, ColumnMapError, apply_map, load_map
from fricenv.logs.logmap import unit_key as _unit_key
from fricenv.logs.sensor_filter import SensorFilter, parse_comment
from fricenv.plants.sui_johansen import RADIUS
from fricenv.utils import atomic_write

__all__ = [
    "PLANTS",
    "TORQUE_FROM_PRESSURE",
    "ColumnMapError",
    "LogFormatError",
    "PayloadLog",
    "QuarterCarLog",
    "log_notes",
    "read_log",
    "write_log",
]

# The comment line that marks a brake torque computed from a line pressure with a nominal factor.
TORQUE_FROM_PRESSURE = "torque_source: pressure"
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


# A number as a CSV holds it: ASCII decimal, optional exponent, or nan/inf (rejected later with their line). Python's
# float() alone would also take "1_0" and non-ASCII digits.
_NUMBER = re.compile(r"^\s*[+-]?((\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|nan|inf|infinity)\s*$", re.IGNORECASE | re.ASCII)


class LogFormatError(InvalidInputError):
    """A log file that does not follow the DESIGN.md contract (a ``ValueError``; one line naming the file)."""


@dataclass(frozen=True)
class QuarterCarLog:
    """A quarter-car braking log; arrays share one length. A missing or held sample is NaN in ``v`` or ``a_x``,
    never in ``t`` or ``T_b`` (``omega`` is filled, see :mod:`fricenv.logs.resample`)."""

    t: np.ndarray  # time [s], uniform step
    T_b: np.ndarray  # commanded brake torque [N m]
    omega: np.ndarray  # measured wheel speed [rad/s]
    v: np.ndarray | None = None  # reference ground speed [m/s]
    a_x: np.ndarray | None = None  # longitudinal acceleration [m/s^2], negative when braking
    # what the log records besides its channels (compare=False: logs with equal data are equal)
    comments: tuple[str, ...] = field(default=(), compare=False)  # the leading '#' lines, without '#'
    source: str = field(default="<memory>", compare=False)
    torque_from_pressure: bool = field(default=False, compare=False)  # T_b = pressure x nominal factor: expect a gain
    resampled: dict | None = field(default=None, compare=False)  # resample.Grid.summary(); None: not needed
    missing: dict[str, float] = field(default_factory=dict, compare=False)  # channel -> share of NaN samples
    # channel -> its low-pass as the user stated it (a "sensor_filter:" comment line, fricenv.logs.sensor_filter)
    sensor_filters: dict[str, SensorFilter] = field(default_factory=dict, compare=False)

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
    """A planar-payload log (raw force-moment sensor readings and vision pose); a missing or held sample is NaN in
    its channel, never in ``t``."""

    t: np.ndarray  # time [s], uniform step
    M: np.ndarray  # raw moment reading [N m]
    f_x: np.ndarray  # raw force reading, x [N]
    f_y: np.ndarray  # raw force reading, y [N]
    theta: np.ndarray  # vision orientation [rad]
    X: np.ndarray  # vision position, x [m]
    Y: np.ndarray  # vision position, y [m]
    comments: tuple[str, ...] = field(default=(), compare=False)
    source: str = field(default="<memory>", compare=False)
    resampled: dict | None = field(default=None, compare=False)
    missing: dict[str, float] = field(default_factory=dict, compare=False)

    REQUIRED = ("t", "M", "f_x", "f_y", "theta", "X", "Y")
    OPTIONAL = ()

    @property
    def dt(self) -> float:
        """Sample time [s]."""
        return float(self.t[1] - self.t[0])

    def __len__(self) -> int:
        return len(self.t)


PLANTS: dict[str, type] = {"quarter-car": QuarterCarLog, "payload": PayloadLog}
# Channels that must be finite in every row; the others may be missing (NaN). Filled: short NaN runs interpolated.
_NEVER_MISSING = ("t", "T_b")
_FILLED = ("omega",)
_HOLD = ("T_b",)  # resampled by zero-order hold


def _log_class(plant: str) -> type:
    try:
        return PLANTS[plant]
    except KeyError:
        raise ValueError(f"unknown plant {plant!r}; valid plants: {', '.join(PLANTS)}") from None


def _read_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8-sig")  # -sig: a leading byte-order mark is not part of the header
    except FileNotFoundError:
        raise LogFormatError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise LogFormatError(f"{path}: is a directory, expected a CSV file") from None
    except UnicodeDecodeError:
        raise LogFormatError(f"{path}: not a text (CSV) file") from None
    except OSError as exc:
        raise LogFormatError(f"{path}: cannot read the file ({exc.strerror})") from None


def _row(path: Path, lineno: int, line: str, header: list[str]) -> list[float]:
    """The values of a data row; an empty cell is NaN (a missing sample)."""
    cells = line.split(",")
    if len(cells) != len(header):
        raise LogFormatError(f"{path}:{lineno}: {len(cells)} values, the header has {len(header)} columns")
    empty = [not cell.strip(" \t") for cell in cells]  # ASCII blanks only: a no-break space is not "empty"
    for name, cell, blank in zip(header, cells, empty):
        if not blank and not _NUMBER.match(cell):
            raise LogFormatError(f"{path}:{lineno}: column {name!r}: {cell.strip()!r} is not a number")
    return [np.nan if blank else float(cell) for cell, blank in zip(cells, empty)]


def _parse(path: Path, raw_header: bool = False):
    """Comments, header and a float table with the file line number of each row.

    :param raw_header: keep the header cells as written (a column map names them); else reduce ``name [SI unit]``.
    """
    comments: list[str] = []
    header: list[str] | None = None
    rows: list[list[float]] = []
    line_numbers: list[int] = []
    for lineno, raw in enumerate(_read_text(path).splitlines(), start=1):
        line = raw.strip(" \t")  # ASCII blanks only: a no-break space at an end is a bad cell, not nothing
        if not line:
            continue
        if header is None:
            if line.startswith("#"):
                comments.append(line[1:].strip())
                continue
            header = [c.strip() if raw_header else _column_name(path, lineno, c) for c in line.split(",")]
            if len(set(header)) != len(header):
                dup = sorted({h for h in header if header.count(h) > 1})
                raise LogFormatError(f"{path}:{lineno}: duplicate column(s) {', '.join(dup)} in header")
            continue
        rows.append(_row(path, lineno, line, header))
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
                             f"convert the column to SI units or give a column map (--map)")
    return name


def _check_time(path: Path, t: np.ndarray, lines: np.ndarray) -> rs.Grid | None:
    """Increasing, finite steps; the resampling grid (None: already uniform)."""
    with np.errstate(over="ignore", invalid="ignore"):
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
    try:
        return rs.plan_grid(t)
    except rs.StepError as exc:
        raise LogFormatError(f"{path}:{lines[exc.row]}: column 't': {exc}") from None


def _check_range(path: Path, name: str, x: np.ndarray, lines: np.ndarray, limit: float, hint: str) -> None:
    bad = np.flatnonzero(np.abs(x) > limit)  # NaN compares False: a missing sample is not implausible
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
    # the fresh samples only: a missing one (NaN) or a repeated one (a held camera frame) has no rate of its own
    keep = ~np.isnan(x) & np.concatenate([[True], x[1:] != x[:-1]])
    if np.count_nonzero(keep) < 2:
        return
    x, t, lines = x[keep], t[keep], lines[keep]
    with np.errstate(over="ignore", invalid="ignore"):  # a jump too large for a float is an infinite rate
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


_PLANT_CHECKS = {"quarter-car": _check_quarter_car, "payload": _check_payload}


def _columns(path: Path, plant: str, header: list[str], table: np.ndarray,
             column_map: ColumnMap | str | os.PathLike | None) -> tuple[dict[str, np.ndarray], list[str]]:
    """The contract channels of the table (through the column map if one is given) and comment lines to add."""
    cls = _log_class(plant)
    if column_map is not None:
        cmap = column_map if isinstance(column_map, ColumnMap) else load_map(
            column_map, plant, cls.REQUIRED + cls.OPTIONAL, cls.REQUIRED)
        cols, sources = apply_map(cmap, header, table, str(path))
        added = [f"converted from {path.name} with the column map {Path(cmap.source).name}"]
        if "T_b" in sources and UNITS[sources["T_b"][1]].kind == "pressure":
            factor = cmap.channels["T_b"].factor
            added += [TORQUE_FROM_PRESSURE,
                      f"T_b = {sources['T_b'][0]} x {factor:g} N m per Pa (a nominal factor: expect a brake_gain)"]
        added += [e.filter.comment(name) for name, e in cmap.channels.items() if e.filter is not None]
        return cols, added
    missing = [name for name in cls.REQUIRED if name not in header]
    if missing:
        raise LogFormatError(
            f"{path}: missing required column(s) {', '.join(missing)} for a {plant} log "
            f"(required: {', '.join(cls.REQUIRED)}; optional: {', '.join(cls.OPTIONAL) or 'none'})"
        )
    known = set(cls.REQUIRED) | set(cls.OPTIONAL)
    extra = [name for name in header if name not in known]
    if extra:
        warnings.warn(f"{path}: ignoring unknown column(s) {', '.join(extra)}", stacklevel=3)
    return {name: table[:, header.index(name)] for name in header if name in known}, []


def _check_values(path: Path, cls: type, cols: dict[str, np.ndarray], lines: np.ndarray) -> None:
    """No infinite value; no missing value in t or T_b; short gaps of omega filled; a channel with fewer than 3
    values is an error if required, left out (with a warning) if optional. Changes ``cols`` in place."""
    for name in list(cols):
        x = cols[name]
        inf = np.flatnonzero(np.isinf(x))
        if inf.size:
            raise LogFormatError(f"{path}:{lines[inf[0]]}: column {name!r} is infinite")
        nan = np.flatnonzero(np.isnan(x))
        if nan.size and name in _NEVER_MISSING:
            raise LogFormatError(f"{path}:{lines[nan[0]]}: column {name!r} is NaN or empty; it may never be missing")
        if name in _FILLED:
            cols[name], bad = rs.fill_short_gaps(x)
            if bad is not None:
                raise LogFormatError(f"{path}:{lines[bad]}: column {name!r} is NaN or empty here; only interior gaps "
                                     f"of up to {rs.MAX_FILL} rows are filled")
        elif len(x) - nan.size < 3:
            if name in cls.REQUIRED:
                raise LogFormatError(f"{path}: column {name!r} has {len(x) - nan.size} values; needs at least 3")
            warnings.warn(f"{path}: column {name!r} has fewer than 3 values; left out", stacklevel=3)
            del cols[name]


def _mark_held(cols: dict[str, np.ndarray], step: float) -> tuple[str, ...]:
    """Held samples (:func:`fricenv.logs.resample.held_mask`) become NaN, in every channel but t, T_b and omega.
    Returns the channels that had held samples (a slower sensor)."""
    slow = []
    for name, x in cols.items():
        if name not in ("t", *_HOLD, *_FILLED):
            held = rs.held_mask(x, step)
            cols[name] = np.where(held, np.nan, x)
            if held.any():
                slow.append(name)
    return tuple(slow)


def read_log(path: str | os.PathLike, plant: str = "quarter-car",
             column_map: ColumnMap | str | os.PathLike | None = None) -> QuarterCarLog | PayloadLog:
    """Read and validate a log file; resample it onto a uniform grid if its stamps jitter or rows were dropped.

    :param path: CSV file in the DESIGN.md format, or any export that ``column_map`` describes.
    :param plant: ``"quarter-car"`` or ``"payload"``.
    :param column_map: a column map (file or :class:`fricenv.logs.logmap.ColumnMap`; docs/contracts.md,
        "Column map").
    :return: a :class:`QuarterCarLog` or :class:`PayloadLog`; held or missing samples are NaN (see the classes).
    :raises LogFormatError: naming the file, line and column of the first problem.
    :raises ColumnMapError: naming the map file and key.
    """
    cls = _log_class(plant)
    path = Path(path)
    comments, header, table, lines = _parse(path, raw_header=column_map is not None)
    cols, added = _columns(path, plant, header, table, column_map)
    _check_values(path, cls, cols, lines)
    grid = _check_time(path, cols["t"], lines)
    _PLANT_CHECKS[plant](path, cols, lines)  # on the values as logged, held ones included
    slow = _mark_held(cols, grid.median_step if grid is not None else float(np.median(np.diff(cols["t"]))))
    if grid is not None:
        cols = rs.resample(cols["t"], cols, grid, hold=_HOLD, keep=slow)
    notes = {"comments": tuple(comments) + tuple(c for c in added if c not in comments), "source": str(path),
             "resampled": None if grid is None else grid.summary(),
             "missing": {name: float(np.mean(np.isnan(x))) for name, x in cols.items() if name != "t"}}
    if plant == "quarter-car":
        notes["torque_from_pressure"] = TORQUE_FROM_PRESSURE in notes["comments"]
        notes["sensor_filters"] = _stated_filters(path, notes["comments"], cols)
    return cls(**cols, **notes)


def _stated_filters(path: Path, comments: tuple[str, ...], cols: dict) -> dict[str, SensorFilter]:
    """The sensor filters the ``sensor_filter:`` comment lines state, for the channels the log has."""
    out = {}
    for line in comments:
        try:
            found = parse_comment(line)
        except ValueError as exc:
            raise LogFormatError(f"{path}: comment line: {exc}") from None
        if found is not None and found[0] in cols:
            out[found[0]] = found[1]
    return out


def write_log(path: str | os.PathLike, log: QuarterCarLog | PayloadLog, comments: tuple[str, ...] = ()) -> None:
    """Write a log atomically in the DESIGN.md format; optional columns that are ``None`` are left out, a missing
    sample is written ``nan``, a torque from pressure is marked by the :data:`TORQUE_FROM_PRESSURE` line and a
    stated sensor filter by its ``sensor_filter:`` line.

    :param path: destination CSV.
    :param log: the log to write.
    :param comments: lines written first, each behind ``# `` (defaults to ``log.comments``).
    """
    names = [name for name in (*log.REQUIRED, *log.OPTIONAL) if getattr(log, name) is not None]
    table = np.column_stack([np.asarray(getattr(log, name), dtype=float) for name in names])
    lines = list(comments or log.comments)
    if getattr(log, "torque_from_pressure", False) and TORQUE_FROM_PRESSURE not in lines:
        lines.append(TORQUE_FROM_PRESSURE)
    lines += [f.comment(c) for c, f in getattr(log, "sensor_filters", {}).items() if f.comment(c) not in lines]
    with atomic_write(path) as fh:
        for line in lines:
            fh.write(f"# {line}\n")
        fh.write(",".join(names) + "\n")
        np.savetxt(fh, table, delimiter=",", fmt="%.10g")


def log_notes(log: QuarterCarLog | PayloadLog) -> tuple[str, ...]:
    """What the reader did to a log, one line each (for a converted log's comments and the reports)."""
    notes = []
    if log.resampled is not None:
        r = log.resampled
        notes.append(f"resampled: {r['rows']} rows onto a uniform grid of {r['samples']} samples, step "
                     f"{r['step']:.6g} s ({r['method']}); largest jitter {r['max_jitter']:.0%} of the step, "
                     f"{r['filled']} dropped sample(s) filled")
    partial = {name: share for name, share in log.missing.items() if share > 0}
    if partial:
        notes.append("missing (held or absent, nan): " + ", ".join(f"{n} {s:.1%}" for n, s in partial.items()))
    return tuple(notes)
