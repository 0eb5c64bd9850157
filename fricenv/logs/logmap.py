"""The column map of real exports: which source column feeds each contract channel, in which unit (docs/contracts.md,
"Column map").

A map is a JSON object::

    {"plant": "quarter-car",
     "channels": {"t":     {"column": "timestamp", "unit": "epoch_s"},
                  "T_b":   {"column": "p_brake_rl", "unit": "kPa", "factor": 1.5e-4},
                  "omega": {"column": "wheel_rl", "unit": "km/h", "radius": 0.345},
                  "v":     {"column": "speed", "unit": "km/h"},
                  "a_x":   {"column": "ax", "unit": "g"}}}

``factor`` is the brake torque per line pressure [N m per Pa] (whatever unit the pressure column is in); ``radius``
[m] turns a wheel's rim speed into ``omega`` (or ``omega_fl``, ``omega_fr``, ``omega_rl``, ``omega_rr``, the other
wheels); the optional ``throttle`` (% or a drive torque in N m), ``yaw_rate`` and ``steer`` describe a car's session; ``filter`` (``v``, ``a_x``) states the sensor's low-pass,
``{"order": 2, "cutoff_hz": 5.0}`` (:mod:`fricenv.logs.sensor_filter`). A ``unit`` left out is taken from the header
cell (``wheel_rl(kmph)``), else the channel's SI unit. Every error is a :class:`ColumnMapError` naming the map file and key.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fricenv.errors import InvalidInputError
from fricenv.logs import sensor_filter
from fricenv.logs.sensor_filter import SensorFilter
from fricenv.utils import read_json_object

__all__ = [
    "CHANNEL_KINDS",
    "HEADER_UNIT",
    "SI_UNITS",
    "UNITS",
    "ChannelSource",
    "ColumnMap",
    "ColumnMapError",
    "Unit",
    "apply_map",
    "find_unit",
    "load_map",
    "parse_map",
    "split_header_cell",
    "time_offset",
    "unit_key",
]

STANDARD_GRAVITY = 9.80665  # [m/s^2 per g]


@dataclass(frozen=True)
class Unit:
    """A unit: the kind of quantity it measures and the SI value of one unit."""

    kind: str
    scale: float


# Canonical spelling -> unit. Lookup goes through unit_key (spaces, '*', '.', '^' dropped; case folded) and ALIASES.
UNITS: dict[str, Unit] = {
    "s": Unit("time", 1.0), "ms": Unit("time", 1e-3), "us": Unit("time", 1e-6),
    "epoch_s": Unit("epoch", 1.0), "epoch_ms": Unit("epoch", 1e-3),  # seconds since 1970: the first stamp is t = 0
    "rad/s": Unit("angular_speed", 1.0), "rpm": Unit("angular_speed", 2.0 * math.pi / 60.0),
    "deg/s": Unit("angular_speed", math.pi / 180.0),
    "m/s": Unit("speed", 1.0), "km/h": Unit("speed", 1.0 / 3.6), "mph": Unit("speed", 0.44704),
    "m/s^2": Unit("acceleration", 1.0), "g": Unit("acceleration", STANDARD_GRAVITY),
    "N m": Unit("torque", 1.0), "N": Unit("force", 1.0),
    "Pa": Unit("pressure", 1.0), "kPa": Unit("pressure", 1e3), "bar": Unit("pressure", 1e5),
    "MPa": Unit("pressure", 1e6), "psi": Unit("pressure", 6894.757293168),
    "rad": Unit("angle", 1.0), "deg": Unit("angle", math.pi / 180.0),
    "m": Unit("length", 1.0), "cm": Unit("length", 1e-2), "mm": Unit("length", 1e-3),
    "%": Unit("percent", 1.0),  # a throttle pedal or command, kept in percent
}
ALIASES = {"sec": "s", "msec": "ms", "epoch": "epoch_s", "kmph": "km/h", "kph": "km/h", "km/hr": "km/h",
           "1/min": "rpm", "mps": "m/s", "percent": "%", "ms-2": "m/s^2",
           "degree": "deg", "degrees": "deg", "radians": "rad"}
# The wheels besides the mapped one (front/rear, left/right), each mapped like omega (with its radius).
WHEELS = ("omega_fl", "omega_fr", "omega_rl", "omega_rr")
# The SI unit of each contract channel (a throttle stays in percent) and the kinds of source unit it accepts.
SI_UNITS = {"t": "s", "T_b": "N m", "omega": "rad/s", "v": "m/s", "a_x": "m/s^2",
            "throttle": "%", "yaw_rate": "rad/s", "steer": "rad", **{w: "rad/s" for w in WHEELS},
            "M": "N m", "f_x": "N", "f_y": "N", "theta": "rad", "X": "m", "Y": "m"}
CHANNEL_KINDS = {"t": ("time", "epoch"), "T_b": ("torque", "pressure"), "omega": ("angular_speed", "speed"),
                 "v": ("speed",), "a_x": ("acceleration",), "throttle": ("percent", "torque"),
                 "yaw_rate": ("angular_speed",), "steer": ("angle",),
                 **{w: ("angular_speed", "speed") for w in WHEELS},
                 "M": ("torque",), "f_x": ("force",), "f_y": ("force",), "theta": ("angle",), "X": ("length",),
                 "Y": ("length",)}
ENTRY_KEYS = ("column", "unit", "factor", "radius", "filter")
# A header cell "name [unit]" or "name (unit)".
HEADER_UNIT = re.compile(r"^(?P<name>[^\[\]()]+?)\s*(\[(?P<u1>[^\]]*)\]|\((?P<u2>[^)]*)\))$")


class ColumnMapError(InvalidInputError):
    """A column map that does not fit its log (a ``ValueError``; one line naming the map file and key)."""


def unit_key(unit: str) -> str:
    """A unit spelling reduced for comparison: "N m", "N*m", "N.m" and "Nm" agree, so do "m/s^2" and "m/s2"."""
    return re.sub(r"[\s*.^]", "", unit).replace("\u00b2", "2").lower()


_LOOKUP = {unit_key(name): name for name in UNITS} | {unit_key(a): c for a, c in ALIASES.items()}


def find_unit(spelling: str) -> str | None:
    """The canonical name of a unit spelling (``"kmph"`` -> ``"km/h"``), or None if unknown."""
    return _LOOKUP.get(unit_key(spelling))


def split_header_cell(cell: str) -> tuple[str, str | None]:
    """``"wheel_rl(kmph)"`` -> ``("wheel_rl", "kmph")``; a cell without a unit gives ``(cell, None)``."""
    cell = cell.strip()
    match = HEADER_UNIT.match(cell)
    if match is None:
        return cell, None
    return match["name"].strip(), (match["u1"] if match["u1"] is not None else match["u2"]).strip()


@dataclass(frozen=True)
class ChannelSource:
    """Where a contract channel comes from: the source column, its unit (None: from the header) and factors."""

    channel: str
    column: str
    unit: str | None = None
    factor: float | None = None  # brake torque per pressure [N m per Pa]
    radius: float | None = None  # wheel radius for a rim speed [m]
    filter: SensorFilter | None = None  # the sensor's low-pass, as its data sheet states it (sensor_filter)


@dataclass(frozen=True)
class ColumnMap:
    """A parsed column map (:func:`load_map`)."""

    channels: dict[str, ChannelSource]
    plant: str | None = None
    source: str = "<memory>"


def _fail(source: str, key: str, problem: str) -> ColumnMapError:
    return ColumnMapError(f"{source}: {key}: {problem}")


def _positive(source: str, key: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise _fail(source, key, f"must be a positive number, got {value!r}")
    return float(value)


def _unit_for(source: str, key: str, channel: str, spelling) -> str:
    """The canonical unit ``spelling`` names, checked against what ``channel`` accepts."""
    name = find_unit(spelling) if isinstance(spelling, str) else None
    valid = [u for u, spec in UNITS.items() if spec.kind in CHANNEL_KINDS[channel]]
    if name is None or UNITS[name].kind not in CHANNEL_KINDS[channel]:
        raise _fail(source, key, f"{spelling!r} is not a unit of {channel!r}; valid units: {', '.join(valid)}")
    return name


def _entry(source: str, channel: str, raw) -> ChannelSource:
    key = f"channels.{channel}"
    if isinstance(raw, str):  # shorthand: just the column name, SI unit or the header's
        raw = {"column": raw}
    if not isinstance(raw, dict):
        raise _fail(source, key, f"must be an object like {{\"column\": NAME, \"unit\": UNIT}}, got {raw!r}")
    unknown = sorted(set(raw) - set(ENTRY_KEYS))
    if unknown:
        raise _fail(source, f"{key}.{unknown[0]}", f"unknown key; valid keys: {', '.join(ENTRY_KEYS)}")
    column = raw.get("column")
    if not isinstance(column, str) or not column.strip():
        raise _fail(source, f"{key}.column", "the source column's name is required (a non-empty string)")
    unit = None if raw.get("unit") is None else _unit_for(source, f"{key}.unit", channel, raw["unit"])
    factor = None if raw.get("factor") is None else _positive(source, f"{key}.factor", raw["factor"])
    radius = None if raw.get("radius") is None else _positive(source, f"{key}.radius", raw["radius"])
    filt = None
    if raw.get("filter") is not None:
        try:
            filt = sensor_filter.parse_entry(channel, raw["filter"])
        except (TypeError, ValueError) as exc:
            raise _fail(source, f"{key}.filter", str(exc)) from None
    return ChannelSource(channel, column.strip(), unit, factor, radius, filt)


def parse_map(raw, plant: str, channels: tuple[str, ...], required: tuple[str, ...],
              source: str = "<memory>") -> ColumnMap:
    """Check a map's JSON object against a plant (without the log: columns and header units come later).

    :param raw: the JSON object.
    :param plant: the plant the log is read for; a map naming another plant is an error.
    :param channels: the plant's channels; ``required`` those the map must name.
    :param source: the map's file name, for the messages.
    :raises ColumnMapError: naming the key.
    """
    if not isinstance(raw, dict):
        raise ColumnMapError(f"{source}: a column map is a JSON object with a \"channels\" object")
    unknown = sorted(set(raw) - {"plant", "channels", "comment"})
    if unknown:
        raise _fail(source, unknown[0], "unknown key; valid keys: plant, channels, comment")
    if raw.get("plant") is not None and raw["plant"] != plant:
        raise _fail(source, "plant", f"the map is for {raw['plant']!r}, the log is read as {plant!r}")
    body = raw.get("channels")
    if not isinstance(body, dict):
        raise _fail(source, "channels", "required: an object mapping contract channels to source columns")
    for name in body:
        if name not in channels:
            raise _fail(source, f"channels.{name}", f"unknown channel; valid channels: {', '.join(channels)}")
    absent = [name for name in required if name not in body]
    if absent:
        raise _fail(source, f"channels.{absent[0]}", f"required for a {plant} log (required: {', '.join(required)})")
    return ColumnMap({name: _entry(source, name, body[name]) for name in body}, raw.get("plant"), source)


def load_map(path: str | os.PathLike, plant: str, channels: tuple[str, ...], required: tuple[str, ...]) -> ColumnMap:
    """Read and check a map file (:func:`parse_map`)."""
    return parse_map(read_json_object(path, "column map"), plant, channels, required, str(Path(path)))


def _column_index(cmap: ColumnMap, entry: ChannelSource, header: list[str], log_name: str) -> tuple[int, str | None]:
    """The header position of ``entry.column`` and the unit its header cell carries (if any)."""
    key = f"channels.{entry.channel}.column"
    if entry.column in header:
        i = header.index(entry.column)
        return i, split_header_cell(header[i])[1]
    hits = [i for i, cell in enumerate(header) if split_header_cell(cell)[0] == entry.column]
    if len(hits) == 1:
        return hits[0], split_header_cell(header[hits[0]])[1]
    shown = ", ".join(header[:12]) + (", ..." if len(header) > 12 else "")
    problem = "matches several columns" if hits else "no such column"
    raise _fail(cmap.source, key, f"{entry.column!r}: {problem} in {log_name} (columns: {shown})")


def _same_unit(header_unit: str | None, map_unit: str) -> bool:
    """A header unit agrees with the map's: unknown, equal, or a time in seconds the map calls epoch seconds (the
    reader re-bases every time to its first sample, so the two read alike)."""
    if header_unit is None or header_unit == map_unit:
        return True
    a, b = UNITS[header_unit], UNITS[map_unit]
    return {a.kind, b.kind} == {"time", "epoch"} and a.scale == b.scale


def _resolved_unit(cmap: ColumnMap, entry: ChannelSource, header_unit: str | None) -> str:
    """The entry's unit: the map's, else the header cell's, else the channel's SI unit."""
    key = f"channels.{entry.channel}.unit"
    if entry.unit is not None:
        if header_unit is not None and not _same_unit(find_unit(header_unit), entry.unit):
            raise _fail(cmap.source, key, f"{entry.unit!r}, but the column header says {header_unit!r}")
        return entry.unit
    if header_unit is not None:
        return _unit_for(cmap.source, key + " (from the column header)", entry.channel, header_unit)
    return SI_UNITS[entry.channel]


def _convert(cmap: ColumnMap, entry: ChannelSource, unit: str, x: np.ndarray) -> np.ndarray:
    """Source values -> SI contract values (eq.: omega = v_rim / r; T_b = p [Pa] * factor). A time is re-based to
    its first stamp (:func:`time_offset` gives that stamp in seconds)."""
    spec, key = UNITS[unit], f"channels.{entry.channel}"
    y = x * spec.scale
    if spec.kind in ("epoch", "time"):
        return (x - x[0]) * spec.scale  # difference first: an epoch stamp times 1e-3 would lose digits
    if entry.channel in ("omega", *WHEELS) and spec.kind == "speed":
        if entry.radius is None:
            raise _fail(cmap.source, f"{key}.radius", f"required for a wheel rim speed in {unit} (the radius [m])")
        return y / entry.radius
    if spec.kind == "pressure":
        if entry.factor is None:
            raise _fail(cmap.source, f"{key}.factor",
                        f"required for a brake pressure in {unit}: the brake torque per pressure [N m per Pa]")
        return y * entry.factor
    return y


def time_offset(header: list[str], table: np.ndarray, sources: dict[str, tuple[str, str]]) -> float:
    """The first time stamp of a mapped export in seconds (what :func:`apply_map` subtracted from ``t``)."""
    cell, unit = sources["t"]
    return float(table[0, header.index(cell)]) * UNITS[unit].scale


def apply_map(cmap: ColumnMap, header: list[str], table: np.ndarray, log_name: str
              ) -> tuple[dict[str, np.ndarray], dict[str, tuple[str, str]]]:
    """The contract channels of a parsed export, in SI units.

    :param header: the export's header cells as written.
    :param table: its rows (NaN where a cell was empty).
    :param log_name: the export's file name, for the messages.
    :return: channel -> values, and channel -> (source header cell, its canonical unit).
    """
    cols: dict[str, np.ndarray] = {}
    sources: dict[str, tuple[str, str]] = {}
    for name, entry in cmap.channels.items():
        i, header_unit = _column_index(cmap, entry, header, log_name)
        unit = _resolved_unit(cmap, entry, header_unit)
        cols[name] = _convert(cmap, entry, unit, table[:, i])
        sources[name] = (header[i], unit)
    return cols, sources
