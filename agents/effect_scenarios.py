"""Evaluation scenarios on a plant with effects: one fixed effect list, or every cell of the effect grid.

``fricenv evaluate --effects SPEC`` runs every scenario on the plant ``SPEC`` names (:func:`parse_effects_arg`: JSON
text when it starts with ``[``, else a path to a JSON list or to a ``gap diagnose`` ``report.json``; the entries
are those of ``gymnasium.make("fricenv/Braking-v0", effects=...)``). ``--effect-grid`` runs :data:`GRID_SCENARIOS`
on every cell of :mod:`fricenv.effects.grid` (the nominal plant, then each effect at its low and high size).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from agents.evaluation import Scenario
from fricenv.effects.grid import GridCell, cell_effects, grid_cells
from fricenv.envs.effect_spec import EffectSpecError, describe_effects, resolve_effects

__all__ = ["CUSTOM_CELL", "GRID_SCENARIOS", "fixed_effect_scenarios", "grid_scenarios", "parse_effects_arg"]

GRID_SCENARIOS: tuple[Scenario, ...] = (Scenario("dry", 20.0), Scenario("wet", 20.0))
CUSTOM_CELL = "custom"


def parse_effects_arg(text: str) -> list[dict[str, Any]]:
    """The ``{"effect", "params"}`` entries of an ``--effects`` value, validated.

    :param text: JSON text of a list (starts with ``[``), or a path to a JSON list or a ``report.json``.
    :raises EffectSpecError: unreadable or invalid, in one line naming the argument.
    """
    text = str(text).strip()
    if text.startswith("["):
        try:
            spec: Any = json.loads(text)
        except json.JSONDecodeError as exc:
            raise EffectSpecError(f"--effects: not valid JSON ({exc})") from None
    else:
        path = Path(text)
        if not path.is_file():
            raise EffectSpecError(f"--effects: {text!r} is neither a JSON list (starting with '[') nor a file")
        try:
            spec = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise EffectSpecError(f"--effects: cannot read {text!r} as JSON ({exc})") from None
        if isinstance(spec, dict):
            spec = text  # a report.json: resolve_effects reads its verdict or effects
    try:
        return describe_effects(resolve_effects(spec))
    except EffectSpecError as exc:
        raise EffectSpecError(f"--effects: {exc}") from None


def fixed_effect_scenarios(scenarios: Sequence[Scenario], effects: list[dict[str, Any]]) -> list[Scenario]:
    """Every scenario on the plant with ``effects`` (the nominal plant when empty)."""
    cell = CUSTOM_CELL if effects else "nominal"
    return [dataclasses.replace(sc, effects=tuple(effects), cell=cell) for sc in scenarios]


def grid_scenarios(scenarios: Sequence[Scenario] = GRID_SCENARIOS,
                   cells: Sequence[GridCell] | None = None) -> list[Scenario]:
    """Every scenario on every grid cell (cells outer): each cell's effects scaled to the scenario's road and
    speed (:func:`fricenv.effects.grid.cell_effects`)."""
    return [dataclasses.replace(sc, effects=tuple(cell_effects(c, sc.road, sc.v0)), cell=c.label)
            for c in (grid_cells() if cells is None else cells) for sc in scenarios]
