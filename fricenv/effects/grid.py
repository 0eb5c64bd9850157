"""The effect grid: each library effect of the quarter car at two sizes, for robustness studies.

==================== ================== ================================ ================================
effect               parameter(s)       low                              high
==================== ================== ================================ ================================
``brake_lag``        ``tau``            0.02 s                           0.08 s
``brake_delay``      ``delay``          0.02 s                           0.06 s
``brake_gain``       ``gain``           0.80                             1.25
``radius_error``     ``r_eff``          0.97 r                           1.04 r
``relaxation_length````sigma``          0.3 m                            0.6 m
``drag``             ``c0``, ``c2``     60 N, 0.3 N s^2/m^2              150 N, 0.6 N s^2/m^2
``mu_change``        ``theta_after``    0.6 theta (at mid-stop)          1.3 theta (at mid-stop)
==================== ================== ================================ ================================

:data:`EFFECT_GRID` holds the table as ``{effect: (low_params, high_params)}``. Two entries are relative to the
scenario and are resolved by :func:`grid_effect`: ``r_eff`` is a factor of the nominal radius ``r`` and
``theta_after`` a factor of the peak factor ``theta`` of the road the stop starts on; ``mu_change``'s ``t_change``
is the middle of the stop, ``v0 / (2 mu_max g)`` (the stop at the road's peak friction).

:func:`grid_cells` lists the nominal plant and every (effect, size); :func:`grid_randomization` gives the
``effects_randomization`` argument of the braking envs over the grid's ranges: each range spans the nominal value
and both sizes, so a two-sided effect (brake gain, radius) is drawn from both sides of nominal and a one-sided one
(a lag) from nominal to its high size (a lag's and a relaxation length's nominal end is 1 ms and 1 mm: they must
be > 0).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import ROADS, MagicFormula

__all__ = [
    "EFFECT_GRID",
    "GRID_SIZES",
    "NOMINAL",
    "NOMINAL_VALUES",
    "RELATIVE_PARAMS",
    "GridCell",
    "cell_effects",
    "grid_cells",
    "grid_effect",
    "grid_randomization",
]

G = 9.81  # [m/s^2]
GRID_SIZES = ("low", "high")
NOMINAL = "nominal"

EFFECT_GRID: dict[str, tuple[dict[str, float], dict[str, float]]] = {
    "brake_lag": ({"tau": 0.02}, {"tau": 0.08}),
    "brake_delay": ({"delay": 0.02}, {"delay": 0.06}),
    "brake_gain": ({"gain": 0.80}, {"gain": 1.25}),
    "radius_error": ({"r_eff": 0.97}, {"r_eff": 1.04}),
    "relaxation_length": ({"sigma": 0.3}, {"sigma": 0.6}),
    "drag": ({"c0": 60.0, "c2": 0.3}, {"c0": 150.0, "c2": 0.6}),
    "mu_change": ({"theta_after": 0.6}, {"theta_after": 1.3}),
}
# Parameters given as a factor of a scenario quantity: (effect, parameter) -> "r" (nominal radius) or "theta".
RELATIVE_PARAMS: dict[tuple[str, str], str] = {("radius_error", "r_eff"): "r", ("mu_change", "theta_after"): "theta"}
# The value of each grid parameter that is the nominal plant (relative parameters as factors). A lag and a relaxation
# length must be > 0: their nominal end is 1 ms and 1 mm, no effect at the 10 ms sample of the braking env.
NOMINAL_VALUES: dict[str, dict[str, float]] = {
    "brake_lag": {"tau": 0.001},
    "brake_delay": {"delay": 0.0},
    "brake_gain": {"gain": 1.0},
    "radius_error": {"r_eff": 1.0},
    "relaxation_length": {"sigma": 0.001},
    "drag": {"c0": 0.0, "c2": 0.0},
    "mu_change": {"theta_after": 1.0},
}


@dataclass(frozen=True)
class GridCell:
    """One column of a robustness matrix: the nominal plant or one effect at one size.

    :param effect: effect name, or ``nominal``.
    :param size: ``low``, ``high`` or ``""`` for the nominal plant.
    """

    effect: str
    size: str = ""

    @property
    def label(self) -> str:
        """``nominal`` or ``effect:size`` (e.g. ``brake_lag:high``)."""
        return NOMINAL if self.effect == NOMINAL else f"{self.effect}:{self.size}"


def _start_road(road: str | MagicFormula) -> MagicFormula:
    """The road a stop starts on: a preset, a MagicFormula, or the first road of a ``a->b`` change."""
    if isinstance(road, MagicFormula):
        return road
    name = str(road).split("->")[0].strip()
    if name not in ROADS:
        raise ValueError(f"the effect grid needs a preset road to scale its effects, got {road!r}; valid: "
                         f"{', '.join(ROADS)}")
    return ROADS[name]


def grid_effect(effect: str, size: str, road: str | MagicFormula, v0: float,
                p: qc.QuarterCarParams = qc.PAPER_PARAMS) -> dict[str, Any]:
    """The ``{"effect", "params"}`` entry of one grid cell for a stop on ``road`` from ``v0``.

    :param effect: a key of :data:`EFFECT_GRID`.
    :param size: ``low`` or ``high``.
    :param road: the road (preset name, ``a->b`` change, or MagicFormula) the stop starts on.
    :param v0: initial speed [m/s].
    :param p: nominal vehicle parameters (radius).
    :raises ValueError: an unknown effect or size.
    """
    if effect not in EFFECT_GRID:
        raise ValueError(f"unknown grid effect {effect!r}; valid: {', '.join(EFFECT_GRID)}")
    if size not in GRID_SIZES:
        raise ValueError(f"unknown grid size {size!r}; valid: {', '.join(GRID_SIZES)}")
    start = _start_road(road)
    params = dict(EFFECT_GRID[effect][GRID_SIZES.index(size)])
    scale = {"r": p.r, "theta": float(start.theta)}
    for (eff, name), what in RELATIVE_PARAMS.items():
        if eff == effect:
            params[name] = params[name] * scale[what]
    if effect == "mu_change":
        params["t_change"] = float(v0) / (2.0 * start.mu_max * G)
    return {"effect": effect, "params": params}


def grid_cells(effects: tuple[str, ...] | None = None) -> list[GridCell]:
    """The nominal cell, then every effect of the grid (or of ``effects``) at each size."""
    names = tuple(EFFECT_GRID) if effects is None else effects
    return [GridCell(NOMINAL)] + [GridCell(e, s) for e in names for s in GRID_SIZES]


def cell_effects(cell: GridCell, road: str | MagicFormula, v0: float,
                 p: qc.QuarterCarParams = qc.PAPER_PARAMS) -> list[dict[str, Any]]:
    """The ``effects`` list of a cell for a stop (``[]`` for the nominal plant)."""
    return [] if cell.effect == NOMINAL else [grid_effect(cell.effect, cell.size, road, v0, p)]


def grid_randomization(effects: tuple[str, ...] | None = None, p: qc.QuarterCarParams = qc.PAPER_PARAMS
                       ) -> dict[str, Mapping[str, tuple[float, float]]]:
    """``effects_randomization`` over the grid's ranges: per effect and parameter, (low, high) spanning the nominal
    value and both sizes. ``mu_change`` is left out: its parameters are relative to the road and the time of the
    stop, which a training curriculum draws itself (friction changes between roads).

    :param effects: the effects to randomise (default: every grid effect but ``mu_change``).
    :param p: nominal vehicle parameters (radius).
    """
    names = tuple(e for e in EFFECT_GRID if e != "mu_change") if effects is None else effects
    out: dict[str, dict[str, tuple[float, float]]] = {}
    for effect in names:
        if effect == "mu_change" or effect not in EFFECT_GRID:
            raise ValueError(f"grid_randomization takes {', '.join(e for e in EFFECT_GRID if e != 'mu_change')}; "
                             f"got {effect!r}")
        low, high = EFFECT_GRID[effect]
        ranges = {}
        for name in low:
            values = (low[name], high[name], NOMINAL_VALUES[effect][name])
            factor = p.r if RELATIVE_PARAMS.get((effect, name)) == "r" else 1.0
            ranges[name] = (min(values) * factor, max(values) * factor)
        out[effect] = ranges
    return out
