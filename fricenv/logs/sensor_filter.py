"""A sensor's low-pass filter, stated by the user (docs/contracts.md, "Column map" and "Log format").

An IMU driver or a logger often low-passes ``v`` and ``a_x``. When its data sheet or its configuration gives the
filter, the column map can say so: ``"a_x": {"column": "ax", "unit": "g", "filter": {"order": 2, "cutoff_hz": 5}}``
(a Butterworth low-pass of that order and cut-off). The converted contract CSV carries it as a comment line::

    # sensor_filter: a_x butterworth order=2 cutoff_hz=5

and :func:`fricenv.logs.read_log` reads it into ``QuarterCarLog.sensor_filters``. The diagnosis then undoes that
filter instead of reading one from the channel's noise (:mod:`fricenv.gap.signals.sensors`), whose roll-off gives the
filter's order and lag only roughly.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

__all__ = [
    "FILTERABLE",
    "FILTER_KEYS",
    "MAX_ORDER",
    "SENSOR_FILTER",
    "SensorFilter",
    "parse_comment",
    "parse_entry",
]

FILTERABLE = ("v", "a_x")  # the channels whose stated filter the diagnosis uses
FILTER_KEYS = ("order", "cutoff_hz")
MAX_ORDER = 8  # highest Butterworth order accepted [-]
SENSOR_FILTER = "sensor_filter:"  # the comment line's prefix
_LINE = re.compile(r"^sensor_filter:\s*(?P<channel>\w+)\s+butterworth\s+order=(?P<order>\S+)\s+cutoff_hz=(?P<fc>\S+)$")


@dataclass(frozen=True)
class SensorFilter:
    """A Butterworth low-pass (analog response) of ``order`` and cut-off ``cutoff_hz`` [Hz]."""

    order: int
    cutoff_hz: float

    def __post_init__(self) -> None:
        if isinstance(self.order, bool) or not isinstance(self.order, int) or not 1 <= self.order <= MAX_ORDER:
            raise ValueError(f"order must be an integer from 1 to {MAX_ORDER}, got {self.order!r}")
        if isinstance(self.cutoff_hz, bool) or not isinstance(self.cutoff_hz, (int, float)) \
                or not math.isfinite(self.cutoff_hz) or self.cutoff_hz <= 0:
            raise ValueError(f"cutoff_hz must be a positive number of Hz, got {self.cutoff_hz!r}")

    def comment(self, channel: str) -> str:
        """The contract CSV's comment line for ``channel`` (without the ``#``)."""
        return f"{SENSOR_FILTER} {channel} butterworth order={self.order} cutoff_hz={self.cutoff_hz:g}"

    def as_dict(self) -> dict:
        return {"order": self.order, "cutoff_hz": float(self.cutoff_hz)}


def parse_entry(channel: str, raw) -> SensorFilter:
    """A column map entry's ``filter`` object.

    :raises ValueError: a one-line reason (the map reader prefixes the map file and key); TypeError if ``raw`` is
        not an object.
    """
    if channel not in FILTERABLE:
        raise ValueError(f"a stated sensor filter is used for {', '.join(FILTERABLE)} only, not {channel!r}")
    if not isinstance(raw, dict):
        raise TypeError(f"must be an object like {{\"order\": 2, \"cutoff_hz\": 5.0}}, got {raw!r}")
    unknown = sorted(set(raw) - set(FILTER_KEYS))
    if unknown:
        raise ValueError(f"unknown key {unknown[0]!r}; valid keys: {', '.join(FILTER_KEYS)}")
    absent = [k for k in FILTER_KEYS if k not in raw]
    if absent:
        raise ValueError(f"{absent[0]!r} is required (keys: {', '.join(FILTER_KEYS)})")
    return SensorFilter(raw["order"], raw["cutoff_hz"])


def parse_comment(line: str) -> tuple[str, SensorFilter] | None:
    """``(channel, filter)`` of a ``sensor_filter:`` comment line (without ``#``); None for any other line.

    :raises ValueError: a ``sensor_filter:`` line that does not follow the format.
    """
    if not line.startswith(SENSOR_FILTER):
        return None
    m = _LINE.match(line.strip())
    if m is None:
        raise ValueError(f"{line!r} does not read 'sensor_filter: CHANNEL butterworth order=N cutoff_hz=F'")
    if m["channel"] not in FILTERABLE:
        raise ValueError(f"{line!r}: a stated sensor filter is used for {', '.join(FILTERABLE)} only")
    try:
        order, fc = int(m["order"]), float(m["fc"])
    except ValueError:
        raise ValueError(f"{line!r}: order must be an integer and cutoff_hz a number") from None
    return m["channel"], SensorFilter(order, fc)
