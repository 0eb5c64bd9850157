"""The effect grid: each library effect of the quarter car at a low and a high size, for robustness measurements.

| effect              | low                              | high                             |
| ------------------- | -------------------------------- | -------------------------------- |
| ``brake_lag``        | ``tau`` 0.02 s                   | 0.08 s                           |
| ``brake_delay``      | ``delay`` 0.02 s                 | 0.06 s                           |
| ``brake_gain``       | ``gain`` 0.80                    | 1.25                             |
| ``radius_error``     | ``r_eff`` 0.97 r                 | 1.04 r                           |
| ``relaxation_length``| ``sigma`` 0.3 m                  | 0.6 m                            |
| ``drag``             | ``c0`` 60 N, ``c2`` 0.3 N s^2/m^2 | 150 N, 0.6 N s^2/m^2             |
| ``mu_change``        | ``theta_after`` 0.6 theta        | 1.3 theta (at mid-stop)          |

``r`` is the vehicle's nominal rolling radius, ``theta`` the road's peak factor and mid-stop the time half-way
through the stop; :func:`grid_effect` turns an entry into an effect spec for one road, vehicle and stop. Real
brakes lag by 20-80 ms (the brake-lag sizes); the other sizes span what the gap tool finds on real logs.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

from fricenv.effects.quarter_car import make_effect

__all__ = ["EFFECT_GRID", "GRID_SIZES", "GridEntry", "grid_effect", "grid_effects"]

GRID_SIZES = ("low", "high")


@dataclass(frozen=True)
class GridEntry:
    """One effect of the grid at its two sizes.

    :param effect: the effect's library name.
    :param low: parameters of the low size (relative ones as factors, see ``relative_to``).
    :param high: parameters of the high size.
    :param relative_to: parameter -> what its value multiplies: ``"r"`` (nominal radius [m]), ``"theta"`` (the
        road's peak factor [-]); a parameter not listed is absolute (SI units).
    :param at_mid_stop: the effect's switching time ``t_change`` is the stop's mid time.
    """

    effect: str
    low: Mapping[str, float]
    high: Mapping[str, float]
    relative_to: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))
    at_mid_stop: bool = False

    def params(self, size: str, r: float, theta: float, t_mid: float | None = None) -> dict[str, float]:
        """The absolute parameters at ``size`` for a vehicle of radius ``r`` on a road of peak factor ``theta``.

        :param size: ``"low"`` or ``"high"``.
        :param r: nominal rolling radius [m].
        :param theta: the road's peak factor [-].
        :param t_mid: the stop's mid time [s] (needed when :attr:`at_mid_stop`).
        :raises ValueError: unknown size, or a mid-stop effect without ``t_mid``.
        """
        if size not in GRID_SIZES:
            raise ValueError(f"grid size must be one of {', '.join(GRID_SIZES)}, got {size!r}")
        scale = {"r": float(r), "theta": float(theta)}
        out = {k: float(v) * scale.get(self.relative_to.get(k, ""), 1.0) for k, v in getattr(self, size).items()}
        if self.at_mid_stop:
            if t_mid is None:
                raise ValueError(f"{self.effect} switches at mid-stop: give t_mid [s]")
            out["t_change"] = float(t_mid)
        return out


def _entry(effect: str, low: dict, high: dict, relative_to: dict | None = None, at_mid_stop: bool = False):
    return GridEntry(effect, MappingProxyType(low), MappingProxyType(high), MappingProxyType(relative_to or {}),
                     at_mid_stop)


EFFECT_GRID: Mapping[str, GridEntry] = MappingProxyType({e.effect: e for e in (
    _entry("brake_lag", {"tau": 0.02}, {"tau": 0.08}),
    _entry("brake_delay", {"delay": 0.02}, {"delay": 0.06}),
    _entry("brake_gain", {"gain": 0.80}, {"gain": 1.25}),
    _entry("radius_error", {"r_eff": 0.97}, {"r_eff": 1.04}, {"r_eff": "r"}),
    _entry("relaxation_length", {"sigma": 0.3}, {"sigma": 0.6}),
    _entry("drag", {"c0": 60.0, "c2": 0.3}, {"c0": 150.0, "c2": 0.6}),
    _entry("mu_change", {"theta_after": 0.6}, {"theta_after": 1.3}, {"theta_after": "theta"}, at_mid_stop=True),
)})


def grid_effect(effect: str, size: str, r: float, theta: float, t_mid: float | None = None):
    """The effect spec of one grid cell (see :meth:`GridEntry.params`).

    :raises ValueError: an effect that is not in the grid (lists the grid's effects).
    """
    if effect not in EFFECT_GRID:
        raise ValueError(f"effect {effect!r} is not in the grid; grid effects: {', '.join(EFFECT_GRID)}")
    return make_effect(effect, **EFFECT_GRID[effect].params(size, r, theta, t_mid))


def grid_effects(size: str, r: float, theta: float, t_mid: float | None = None) -> dict[str, object]:
    """Every grid effect at ``size``: effect name -> spec (one effect per plant; see :func:`grid_effect`)."""
    return {name: grid_effect(name, size, r, theta, t_mid) for name in EFFECT_GRID}
