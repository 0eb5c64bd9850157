"""Log files of the sim-to-real gap tool (docs/contracts.md, section 1): the one reader and writer.

CSV in SI units: optional leading ``#`` lines, one header row, then rows. Quarter car: required ``t`` [s],
``T_b`` [N m] (commanded torque), ``omega`` [rad/s]; optional ``v`` [m/s], ``a_x`` [m/s^2]. Payload: ``t``,
``M``, ``f_x``, ``f_y`` (raw sensor readings), ``theta``, ``X``, ``Y`` (vision). Unknown extra columns are ignored
with a warning. Every error names the file, and where it can the line and the column.

Real exports (docs/contracts.md, section 1): ``read_log(path, plant, column_map=MAP)`` reads any CSV whose columns
a column map (:mod:`fricenv.logs.logmap`) names, in the map's units. Jittered time stamps and dropped rows are
resampled onto a uniform grid, held samples of a slower channel are marked missing (NaN), and the log records what was done
(``resampled``, ``missing``, ``torque_from_pressure``); the rules are in :mod:`fricenv.logs.resample`.

A header written as the last ``#`` line before the data is read as the header (:mod:`fricenv.logs.csvfile`); time is
re-based to the first sample (``t_offset``); a car's session may add ``throttle``, ``yaw_rate``, ``steer`` and the four
wheels; :mod:`fricenv.logs.checks` catches a person's or a logger's mistakes before any long work (``warnings``).
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fricenv.logs import checks
from fricenv.logs import resample as rs
from fricenv.logs.checks import LogCheckWarning
from fricenv.logs.csvfile import LogFormatError, parse
from fricenv.logs.logmap import UNITS, WHEELS, ColumnMap, ColumnMapError, apply_map, load_map, time_offset
from fricenv.logs.sensor_filter import SensorFilter, parse_comment
from fricenv.plants.sui_johansen import RADIUS
from fricenv.utils import atomic_write

__all__ = [
    "PLANTS",
    "TORQUE_FROM_PRESSURE",
    "ColumnMapError",
    "LogCheckWarning",
    "LogFormatError",
    "PayloadLog",
    "QuarterCarLog",
    "log_notes",
    "read_log",
    "write_log",
]

# The comment line that marks a brake torque computed from a line pressure with a nominal factor.
TORQUE_FROM_PRESSURE = "torque_source: pressure"
# Comment lines: the first sample's time in the original base, a drive torque as throttle, a check's warning.
# a wheel channel converted from a rim speed, and the radius [m] it was converted with
WHEEL_RADIUS = "wheel_radius:"
T_OFFSET = "t_offset_s:"
THROTTLE_UNIT = "throttle_unit:"
WARNING = "warning:"
# Plausibility limits, chosen to catch a wrong unit (rpm for rad/s, km/h for m/s, degrees for rad), not noise.
_MAX_WHEEL_SURFACE_SPEED = 100.0  # |omega| r above this [m/s] (360 km/h) means omega is not in rad/s
_MAX_SPEED = 100.0  # [m/s]
_MAX_ACCEL = 30.0  # |a_x| [m/s^2], about 3 g
_MAX_TORQUE = 2.0e4  # |T_b| [N m], also a drive torque as throttle
_MAX_YAW_RATE = 10.0  # |yaw_rate| [rad/s]: 570 deg/s
_MAX_STEER = 4.0 * np.pi  # |steer| [rad]: two turns of a hand wheel
_MAX_THROTTLE = 100.5  # [%]
# omega r / v while rolling, if v is logged: rpm gives ~9.5 and v in km/h ~0.28 or ~3.6; the upper bound leaves
# room for the traction overshoot of a wheel spinning up after a brake release (relaxation length at low speed)
_OMEGA_R_OVER_V = (0.5, 2.5)
_ROLLING_PERCENTILE = 95.0  # of omega r / v over the moving samples
# Payload: median rates; a pose in degrees or mm (with its vision noise) moves 57x or 1000x "faster".
_MAX_ANGULAR_RATE = 50.0  # median |theta'| [rad/s]
_MAX_LINEAR_RATE = 20.0  # median |X'|, |Y'| [m/s]
_NOMINAL_RADIUS = RADIUS  # [m], Sui & Johansen Table I; only used for the unit checks


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
    # a car's session: drive, yaw rate, steering and the other wheels (None: not logged)
    throttle: np.ndarray | None = None  # throttle [%] or drive torque [N m] (throttle_unit)
    yaw_rate: np.ndarray | None = None  # [rad/s]
    steer: np.ndarray | None = None  # steering angle [rad]
    omega_fl: np.ndarray | None = None  # wheel speeds [rad/s]: front left, front right, rear left, rear right
    omega_fr: np.ndarray | None = None
    omega_rl: np.ndarray | None = None
    omega_rr: np.ndarray | None = None
    throttle_unit: str = field(default="%", compare=False)  # "%" or "N m"
    t_offset: float = field(default=0.0, compare=False)  # the first sample's time in the log's original base [s]
    warnings: tuple[str, ...] = field(default=(), compare=False)  # the checks' findings, "<channel>: ..."
    # wheel channel -> the radius [m] the column map converted its rim speed with (a "wheel_radius:" line)
    radii: dict[str, float] = field(default_factory=dict, compare=False)

    REQUIRED = ("t", "T_b", "omega")
    OPTIONAL = ("v", "a_x", "throttle", "yaw_rate", "steer", *WHEELS)

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
    t_offset: float = field(default=0.0, compare=False)  # the first sample's time in the log's original base [s]
    warnings: tuple[str, ...] = field(default=(), compare=False)

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
_HOLD = ("T_b", "throttle")  # commands: resampled by zero-order hold
_NOT_HELD = ("t", *_HOLD, *_FILLED, *WHEELS)  # never marked held: commands and wheel speeds (exact repeats are real)


def _log_class(plant: str) -> type:
    try:
        return PLANTS[plant]
    except KeyError:
        raise ValueError(f"unknown plant {plant!r}; valid plants: {', '.join(PLANTS)}") from None


def _check_time(path: Path, t: np.ndarray, lines: np.ndarray, offset: float = 0.0) -> rs.Grid | None:
    """Increasing, finite steps at 10 Hz - 1 kHz; the resampling grid (None: already uniform). ``offset``: what was
    subtracted from the stamps (a mapped log's first stamp), added back in the messages."""
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
        was = "repeats" if t[i] == t[i - 1] else "goes back from"
        raise LogFormatError(f"{path}:{lines[i]}: column 't' is not increasing: the stamp {was} line "
                             f"{lines[i - 1]}'s ({offset + float(t[i - 1]):.17g} then {offset + float(t[i]):.17g} s)")
    checks.check_rate(path, float(np.median(dt)), int(lines[0]))
    try:
        return rs.plan_grid(t)
    except rs.StepError as exc:
        raise LogFormatError(f"{path}:{lines[exc.row]}: column 't': {exc}") from None


def _drop_repeated_rows(table: np.ndarray, lines: np.ndarray) -> tuple[np.ndarray, np.ndarray, str | None]:
    """Rows equal to the row before them in every cell, time stamp included (a logger writing one record twice),
    dropped; the finding for the log's warnings (None: there were none)."""
    same = np.all((table[1:] == table[:-1]) | (np.isnan(table[1:]) & np.isnan(table[:-1])), axis=1)
    if not same.any():
        return table, lines, None
    keep = np.concatenate([[True], ~same])
    first = int(lines[1:][same][0])
    finding = (f"t: {int(same.sum())} row(s) repeating the row before them in every column dropped (the first on "
               f"line {first})")
    return table[keep], lines[keep], finding


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
    for name, limit, hint in (("yaw_rate", _MAX_YAW_RATE, "expected rad/s; is it in deg/s?"),
                              ("steer", _MAX_STEER, "expected rad; is it in degrees?")):
        if name in cols:
            _check_range(path, name, cols[name], lines, limit, hint)


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


@dataclass
class _Mapped:
    """What the column map tells besides the channels: the first stamp, the wheels' radii, the throttle's unit."""

    offset: float = 0.0  # [s] the first time stamp, subtracted from t
    radii: dict[str, float] = field(default_factory=dict)
    throttle_unit: str = "%"
    comments: list[str] = field(default_factory=list)


def _columns(path: Path, plant: str, header: list[str], table: np.ndarray,
             column_map: ColumnMap | str | os.PathLike | None) -> tuple[dict[str, np.ndarray], _Mapped]:
    """The contract channels of the table (through the column map if one is given; then with the time re-based
    to its first stamp), and what the map adds (comment lines among it)."""
    cls = _log_class(plant)
    if column_map is not None:
        cmap = column_map if isinstance(column_map, ColumnMap) else load_map(
            column_map, plant, cls.REQUIRED + cls.OPTIONAL, cls.REQUIRED)
        cols, sources = apply_map(cmap, header, table, str(path))
        info = _Mapped(time_offset(header, table, sources))
        info.radii = {name: e.radius for name, e in cmap.channels.items()
                      if e.radius is not None and UNITS[sources[name][1]].kind == "speed"}
        if "throttle" in sources and UNITS[sources["throttle"][1]].kind == "torque":
            info.throttle_unit = "N m"
        info.comments = [f"converted from {path.name} with the column map {Path(cmap.source).name}"]
        if "T_b" in sources and UNITS[sources["T_b"][1]].kind == "pressure":
            factor = cmap.channels["T_b"].factor
            stated = f"T_b = {sources['T_b'][0]} x {factor:g} N m per Pa (a nominal factor: expect a brake_gain)"
            info.comments += [TORQUE_FROM_PRESSURE, stated]
        info.comments += [e.filter.comment(name) for name, e in cmap.channels.items() if e.filter is not None]
        return cols, info
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
    return {name: table[:, header.index(name)] for name in header if name in known}, _Mapped()


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
        if name not in _NOT_HELD:
            held = rs.held_mask(x, step)
            cols[name] = np.where(held, np.nan, x)
            if held.any():
                slow.append(name)
    return tuple(slow)


def read_log(path: str | os.PathLike, plant: str = "quarter-car",
             column_map: ColumnMap | str | os.PathLike | None = None) -> QuarterCarLog | PayloadLog:
    """Read and validate a log file; resample it onto a uniform grid if its stamps jitter or rows were dropped.

    Time is re-based to the first sample (``log.t_offset`` keeps that sample's time in the original base, and a
    ``t_offset_s:`` comment line carries it through a written log). The checks of :mod:`fricenv.logs.checks` run
    here: an error stops the reading, a warning is issued as a :class:`LogCheckWarning` and kept in ``log.warnings``
    (with those a written log carries as ``warning:`` comment lines).

    :param path: CSV file in the docs/contracts.md format, or any export that ``column_map`` describes.
    :param plant: ``"quarter-car"`` or ``"payload"``.
    :param column_map: a column map (file or :class:`fricenv.logs.logmap.ColumnMap`; docs/contracts.md,
        "Column map").
    :return: a :class:`QuarterCarLog` or :class:`PayloadLog`; held or missing samples are NaN (see the classes).
    :raises LogFormatError: naming the file, line and column of the first problem.
    :raises ColumnMapError: naming the map file and key.
    """
    cls = _log_class(plant)
    path = Path(path)
    comments, header, table, lines = parse(path, raw_header=column_map is not None)
    table, lines, repeated = _drop_repeated_rows(table, lines)
    cols, info = _columns(path, plant, header, table, column_map)
    _check_values(path, cls, cols, lines)
    grid = _check_time(path, cols["t"], lines, info.offset)
    if column_map is None:  # a mapped time is re-based already, in its own unit (apply_map)
        info.offset = float(cols["t"][0])
        cols["t"] = cols["t"] - info.offset
    if plant == "quarter-car":
        checks.check_speeds(path, cols, info.radii.get("omega", _NOMINAL_RADIUS))
    _PLANT_CHECKS[plant](path, cols, lines)  # on the values as logged, held ones included
    step = grid.median_step if grid is not None else float(np.median(np.diff(cols["t"])))
    slow = _mark_held(cols, step)
    if grid is not None:
        cols = rs.resample(cols["t"], cols, grid, hold=_HOLD, keep=slow)
    old, kept = _carried(path, comments)
    found = [repeated] if repeated else []
    if plant == "quarter-car":
        info.throttle_unit = old.get("throttle_unit", info.throttle_unit)
        _check_throttle(path, cols, info.throttle_unit)
        found += checks.check_session(path, cols, float(cols["t"][1] - cols["t"][0]), info.radii, _NOMINAL_RADIUS)
    for line in found:
        warnings.warn(LogCheckWarning(f"{path}: {line}"), stacklevel=2)
    offset = old.get("t_offset", 0.0) + info.offset
    found = list(old.get("warnings", ())) + [w for w in found if w not in old.get("warnings", ())]
    added = ([f"{T_OFFSET} {offset!r}"] if offset != 0.0 else []) + info.comments + [f"{WARNING} {w}" for w in found]
    notes = {"comments": tuple(kept) + tuple(c for c in added if c not in kept), "source": str(path),
             "resampled": None if grid is None else grid.summary(),
             "missing": {name: float(np.mean(np.isnan(x))) for name, x in cols.items() if name != "t"},
             "t_offset": offset, "warnings": tuple(found)}
    if plant == "quarter-car":
        notes["torque_from_pressure"] = TORQUE_FROM_PRESSURE in notes["comments"]
        notes["sensor_filters"] = _stated_filters(path, notes["comments"], cols)
        notes["throttle_unit"] = info.throttle_unit
        notes["radii"] = {**old.get("radii", {}), **info.radii}
        notes["comments"] += tuple(f"{WHEEL_RADIUS} {c} {r!r}" for c, r in notes["radii"].items())
        if info.throttle_unit != "%":
            notes["comments"] += (f"{THROTTLE_UNIT} {info.throttle_unit}",)
    return cls(**cols, **notes)


def _carried(path: Path, comments: list[str]) -> tuple[dict, list[str]]:
    """What a written log's comment lines carry (``t_offset``, ``throttle_unit``, ``radii``, ``warnings``) and the
    other comment lines. The time offset, throttle unit and wheel radius lines are taken out (the reader writes them
    afresh)."""
    found: dict = {"warnings": []}
    kept = []
    for line in comments:
        if line.startswith(T_OFFSET):
            try:
                found["t_offset"] = float(line[len(T_OFFSET):])
            except ValueError:
                raise LogFormatError(f"{path}: comment line {line!r}: expected a time in seconds") from None
        elif line.startswith(WHEEL_RADIUS):
            try:
                channel, radius = line[len(WHEEL_RADIUS):].split()
                found.setdefault("radii", {})[channel] = float(radius)
            except ValueError:
                raise LogFormatError(f"{path}: comment line {line!r}: expected '{WHEEL_RADIUS} <channel> <radius m>'"
                                     ) from None
        elif line.startswith(THROTTLE_UNIT):
            unit = line[len(THROTTLE_UNIT):].strip()
            if unit not in ("%", "N m"):
                raise LogFormatError(f"{path}: comment line {line!r}: the throttle unit is '%' or 'N m'")
            found["throttle_unit"] = unit
        else:
            if line.startswith(WARNING):
                found["warnings"].append(line[len(WARNING):].strip())
            kept.append(line)
    return found, kept


def _check_throttle(path: Path, cols: dict[str, np.ndarray], unit: str) -> None:
    if "throttle" in cols:
        limit, hint = (_MAX_THROTTLE, "expected %") if unit == "%" else (_MAX_TORQUE, "expected N m")
        bad = np.flatnonzero(np.abs(cols["throttle"]) > limit)
        if bad.size:
            raise LogFormatError(f"{path}: column 'throttle': value {cols['throttle'][bad[0]]:.6g} is implausible "
                                 f"({hint}, limit {limit:g})")


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
    """Write a log atomically in the docs/contracts.md format, every value at full precision (the shortest decimal that
    reads back to the same float); optional columns that are ``None`` are left out, a missing sample is written
    ``nan``, a torque from pressure is marked by the :data:`TORQUE_FROM_PRESSURE` line, a stated sensor filter by its
    ``sensor_filter:`` line, a time offset by its ``t_offset_s:`` line, a drive torque as throttle by
    ``throttle_unit: N m``, and each warning by a ``warning:`` line.

    :param path: destination CSV.
    :param log: the log to write.
    :param comments: lines written first, each behind ``# `` (defaults to ``log.comments``).
    """
    names = [name for name in (*log.REQUIRED, *log.OPTIONAL) if getattr(log, name) is not None]
    table = np.column_stack([np.asarray(getattr(log, name), dtype=float) for name in names])
    lines = [c for c in (comments or log.comments) if not c.startswith((T_OFFSET, THROTTLE_UNIT, WHEEL_RADIUS))]
    if getattr(log, "t_offset", 0.0):
        lines.append(f"{T_OFFSET} {float(log.t_offset)!r}")
    lines += [f"{WHEEL_RADIUS} {c} {r!r}" for c, r in getattr(log, "radii", {}).items()]
    if getattr(log, "throttle", None) is not None and log.throttle_unit != "%":
        lines.append(f"{THROTTLE_UNIT} {log.throttle_unit}")
    if getattr(log, "torque_from_pressure", False) and TORQUE_FROM_PRESSURE not in lines:
        lines.append(TORQUE_FROM_PRESSURE)
    lines += [f.comment(c) for c, f in getattr(log, "sensor_filters", {}).items() if f.comment(c) not in lines]
    lines += [f"{WARNING} {w}" for w in getattr(log, "warnings", ()) if f"{WARNING} {w}" not in lines]
    with atomic_write(path) as fh:
        for line in lines:
            fh.write(f"# {line}\n")
        fh.write(",".join(names) + "\n")
        fh.writelines(",".join(map(repr, row)) + "\n" for row in table.tolist())


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
