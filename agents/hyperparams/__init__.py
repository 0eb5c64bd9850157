"""Committed hyperparameter files that ``fricenv train`` reads: ``braking.json`` (PPO and SAC for the ABS task).

A file maps an algorithm (``ppo``, ``sac``) to the fields of its config dataclass
(:class:`agents.training.PPOConfig`, :class:`agents.training.SACConfig`); keys starting with ``_`` are comments.
An unknown algorithm or field, or a missing file, raises :class:`HyperparamsError` with what to fix.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

from fricenv.errors import InvalidInputError

__all__ = ["BRAKING_FILE", "HyperparamsError", "load_hyperparams"]

BRAKING_FILE = Path(__file__).with_name("braking.json")


class HyperparamsError(InvalidInputError):
    """A hyperparameter file that cannot be read into the config dataclasses."""


def load_hyperparams(path: str | Path, classes: dict[str, type]) -> dict[str, Any]:
    """The configs of a hyperparameter file, one per algorithm it lists.

    :param path: the JSON file.
    :param classes: algorithm -> config dataclass (its fields are the accepted keys).
    :return: algorithm -> config instance.
    """
    path = Path(path)
    try:
        raw = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise HyperparamsError(f"cannot read hyperparameters from {path}: {exc}; give a JSON file "
                               f"like {BRAKING_FILE}") from None
    out = {}
    for algo, values in raw.items():
        if algo.startswith("_"):
            continue
        if algo not in classes:
            raise HyperparamsError(f"{path}: unknown algorithm {algo!r}; valid: {', '.join(classes)}")
        cls = classes[algo]
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - names)
        if unknown:
            raise HyperparamsError(f"{path}: unknown {algo} hyperparameter(s) {unknown}; valid: {sorted(names)}")
        kwargs = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
        out[algo] = cls(**kwargs)
    return out
