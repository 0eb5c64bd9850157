"""The ``effects=`` and ``effects_randomization=`` arguments of the braking envs: parsing and validation.

``effects`` (docs/contracts.md):

* a sequence of ``{"effect": NAME, "params": {PARAM: value}}`` dicts (or effect specs of
  :func:`fricenv.effects.quarter_car.make_effect`); ``[]`` or None: the plain env;
* a path to a ``gap diagnose`` ``report.json``: its ``effects`` list if present, else its ``verdict`` with its
  ``params`` (``none`` and ``unexplained`` give no effects).

``effects_randomization``: ``{NAME: {PARAM: (low, high) or value}}``, parameter ranges drawn uniformly per episode
from the env's ``np_random``. A parameter without a range keeps its value from ``effects``; an effect named in both
is replaced by its drawn version. Draws are made in the mapping's order, parameters in their registry order, and a
degenerate range (``low == high``) draws nothing. ``{"one_of": {NAME: {PARAM: (low, high)}, ...}}`` draws, per
episode, one of the named effects or none, each with probability ``1 / (k + 1)`` for ``k`` effects (the effect
grid's distribution: one effect at a time, the nominal plant included), then that effect's parameters.

Unknown effect or parameter names, missing parameters and malformed entries raise :class:`EffectSpecError` (a
``ValueError``) naming them and the valid ones.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fricenv.effects.quarter_car import EFFECT_PARAMS, EFFECTS, effect_params, make_effect
from fricenv.errors import InvalidInputError

__all__ = [
    "NO_EFFECT_VERDICTS",
    "ONE_OF",
    "EffectRandomization",
    "EffectSpecError",
    "describe_effects",
    "effects_from_report",
    "parse_effect_args",
    "parse_randomization",
    "resolve_effects",
]

NO_EFFECT_VERDICTS = ("none", "unexplained")
ONE_OF = "one_of"  # the key of an effects_randomization that draws one effect per episode


class EffectSpecError(InvalidInputError):
    """An unknown effect or parameter name, or a malformed ``effects``/``effects_randomization`` argument."""


def _valid_effects() -> str:
    return ", ".join(EFFECT_PARAMS)


def _check_names(name: Any, params: Mapping[str, Any], where: str) -> None:
    """Raise :class:`EffectSpecError` for an unknown effect or unknown parameter names of a known one."""
    if name not in EFFECT_PARAMS:
        raise EffectSpecError(f"{where}: unknown effect {name!r}; valid effects: {_valid_effects()}")
    unknown = sorted(set(params) - set(EFFECT_PARAMS[name]))
    if unknown:
        raise EffectSpecError(f"{where}: effect {name!r} has no parameter(s) {', '.join(map(str, unknown))}; its "
                              f"parameters are: {', '.join(EFFECT_PARAMS[name])}")


def _make(name: str, params: Mapping[str, Any], where: str):
    """An effect spec, every failure as :class:`EffectSpecError` prefixed with ``where``."""
    _check_names(name, params, where)
    try:
        return make_effect(name, **{k: float(v) for k, v in params.items()})
    except (TypeError, ValueError) as exc:
        raise EffectSpecError(f"{where}: {exc}") from None


def _effect_from_entry(entry: Any, where: str):
    """One effect from a ``{"effect", "params"}`` mapping or an effect spec object."""
    if isinstance(entry, tuple(EFFECTS.values())):
        return entry
    if not isinstance(entry, Mapping) or "effect" not in entry:
        raise EffectSpecError(f"{where}: expected {{'effect': NAME, 'params': {{...}}}} or an effect spec, got "
                              f"{entry!r}")
    extra = sorted(set(entry) - {"effect", "params"})
    if extra:
        raise EffectSpecError(f"{where}: unknown key(s) {extra}; an effect entry has 'effect' and 'params'")
    params = entry.get("params") or {}
    if not isinstance(params, Mapping):
        raise EffectSpecError(f"{where}: 'params' must be a mapping of parameter names to numbers, got {params!r}")
    return _make(entry["effect"], params, where)


def effects_from_report(report: Mapping[str, Any]) -> tuple[str, list]:
    """(verdict, effect specs) of a ``report.json`` object: its ``effects`` list if present, else the verdict's
    effect with its fitted ``params``; no effects for the verdicts ``none`` and ``unexplained``."""
    if "verdict" not in report:
        raise EffectSpecError("report has no 'verdict': not a gap diagnose report.json")
    verdict = report["verdict"]
    if "effects" in report:
        entries = report["effects"]
        if not isinstance(entries, Sequence) or isinstance(entries, str):
            raise EffectSpecError(f"report 'effects' must be a list of effect entries, got {entries!r}")
        return verdict, [_effect_from_entry(e, f"report effects[{k}]") for k, e in enumerate(entries)]
    if verdict in NO_EFFECT_VERDICTS:
        return verdict, []
    if "params" not in report:
        raise EffectSpecError("report has no 'params': not a gap diagnose report.json")
    if verdict not in EFFECT_PARAMS:
        raise EffectSpecError(f"report verdict {verdict!r} is not a library effect; valid: "
                              f"{', '.join(NO_EFFECT_VERDICTS)}, {_valid_effects()}")
    return verdict, [_make(verdict, report["params"], "report")]


def _read_report(path: str | os.PathLike) -> Mapping[str, Any]:
    try:
        report = json.loads(Path(path).read_text())
    except OSError as exc:
        raise EffectSpecError(f"cannot read effects report {str(path)!r}: {exc.strerror or exc}") from None
    except json.JSONDecodeError as exc:
        raise EffectSpecError(f"effects report {str(path)!r} is not JSON: {exc}") from None
    if not isinstance(report, Mapping):
        raise EffectSpecError(f"effects report {str(path)!r} must hold a JSON object")
    return report


def resolve_effects(effects: Any) -> tuple:
    """The effect specs of an ``effects`` argument (see the module docstring); each effect name at most once."""
    if effects is None:
        return ()
    if isinstance(effects, (str, os.PathLike)):
        out = effects_from_report(_read_report(effects))[1]
    elif isinstance(effects, Mapping) or not isinstance(effects, Sequence):
        raise EffectSpecError(f"effects must be a list of {{'effect': NAME, 'params': {{...}}}} entries or a path "
                              f"to a report.json, got {type(effects).__name__}")
    else:
        out = [_effect_from_entry(e, f"effects[{k}]") for k, e in enumerate(effects)]
    names = [e.name for e in out]
    if len(set(names)) != len(names):
        raise EffectSpecError(f"each effect may appear once, got {names}")
    return tuple(out)


def describe_effects(effects: Sequence) -> list[dict[str, Any]]:
    """Effect specs as ``[{"effect": NAME, "params": {...}}]`` (the report's form)."""
    return [{"effect": e.name, "params": effect_params(e)} for e in effects]


def _parse_range(value: Any, where: str) -> tuple[float, float]:
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool):
        lo = hi = float(value)
    elif isinstance(value, Sequence) and not isinstance(value, str) and len(value) == 2:
        lo, hi = float(value[0]), float(value[1])
    else:
        raise EffectSpecError(f"{where}: expected a (low, high) range or a number, got {value!r}")
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
        raise EffectSpecError(f"{where}: range must be finite with low <= high, got {value!r}")
    return lo, hi


@dataclass(frozen=True)
class EffectRandomization:
    """Fixed effects plus per-episode draws of effect parameters (see the module docstring)."""

    fixed: tuple  # effects drawn nothing for
    ranges: tuple[tuple[str, tuple[tuple[str, float, float], ...]], ...]  # (effect, ((param, low, high), ...))
    one_of: bool = False  # per episode one of the ranged effects or none, instead of all of them

    def draw(self, rng: np.random.Generator) -> tuple:
        """One episode's effects: the fixed ones, then each randomised effect (``one_of``: one of them or none) with
        its parameters drawn."""
        out = list(self.fixed)
        ranges = self.ranges
        if self.one_of:
            k = int(rng.integers(len(ranges) + 1))
            ranges = ranges[k:k + 1]  # k == len(ranges): the nominal plant
        for name, params in ranges:
            values = {p: lo if lo == hi else float(rng.uniform(lo, hi)) for p, lo, hi in params}
            out.append(make_effect(name, **values))
        return tuple(out)


def parse_randomization(spec: Mapping[str, Any] | None, effects: Sequence = ()) -> EffectRandomization | None:
    """An :class:`EffectRandomization` from ``effects_randomization`` and the fixed ``effects`` (None if ``spec``
    is empty). Both ends of every range are checked against the effect's own bounds."""
    if not spec:
        return None
    if not isinstance(spec, Mapping):
        raise EffectSpecError(f"effects_randomization must be a mapping {{effect: {{param: (low, high)}}}}, got "
                              f"{type(spec).__name__}")
    one_of = ONE_OF in spec
    if one_of:
        if len(spec) != 1 or not isinstance(spec[ONE_OF], Mapping) or not spec[ONE_OF]:
            raise EffectSpecError(f"effects_randomization: {ONE_OF!r} takes a non-empty mapping "
                                  f"{{effect: {{param: (low, high)}}}} and stands alone, got {dict(spec)!r}")
        spec = spec[ONE_OF]
    base = {e.name: effect_params(e) for e in effects}
    ranges = []
    for name, params in spec.items():
        where = f"effects_randomization[{name!r}]"
        if not isinstance(params, Mapping) or not params:
            raise EffectSpecError(f"{where}: expected a non-empty mapping {{param: (low, high)}}, got {params!r}")
        _check_names(name, params, where)
        rows = []
        for p in EFFECT_PARAMS[name]:
            if p in params:
                lo, hi = _parse_range(params[p], f"{where}[{p!r}]")
            elif p in base.get(name, {}):
                lo = hi = base[name][p]
            else:
                raise EffectSpecError(f"{where}: parameter {p!r} needs a range here or a value in effects")
            rows.append((p, lo, hi))
        for end in (1, 2):  # both ends of every range must make a valid effect
            _make(name, {r[0]: r[end] for r in rows}, where)
        ranges.append((name, tuple(rows)))
    fixed = tuple(e for e in effects if e.name not in spec)
    return EffectRandomization(fixed=fixed, ranges=tuple(ranges), one_of=one_of)


def parse_effect_args(names: Sequence[str], params: Sequence[str]) -> list:
    """Effect specs from command-line ``--effect NAME`` and ``--param NAME=VALUE`` / ``EFFECT.NAME=VALUE`` strings
    (``none`` is ignored); a bare parameter name goes to the first given effect that has it."""
    names = [n for n in names if n != "none"]
    for n in names:
        _check_names(n, {}, "--effect")
    values: dict[str, dict[str, float]] = {n: {} for n in names}
    for item in params:
        key, sep, value = item.partition("=")
        if not sep:
            raise EffectSpecError(f"--param {item!r}: expected NAME=VALUE")
        try:
            val = float(value)
        except ValueError:
            raise EffectSpecError(f"--param {item!r}: {value!r} is not a number") from None
        eff, dot, pname = key.rpartition(".")
        if dot:
            if eff not in values:
                raise EffectSpecError(f"--param {item!r}: effect {eff!r} is not among --effect {', '.join(names)}")
        else:
            owners = [n for n in names if key in EFFECT_PARAMS[n]]
            if not owners:
                valid = ", ".join(f"{p} ({n})" for n in names for p in EFFECT_PARAMS[n]) or "none (no --effect given)"
                raise EffectSpecError(f"--param {item!r}: unknown parameter {key!r}; valid parameters: {valid}")
            eff, pname = owners[0], key
        values[eff][pname] = val
    return [_make(n, values[n], f"--effect {n}") for n in names]
