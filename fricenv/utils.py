"""Small shared helpers: seeding, atomic file writes, JSON output, progress bars."""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["as_generator", "atomic_write", "progress", "read_json_object", "to_jsonable", "write_json"]


def as_generator(seed: int | np.random.Generator | None) -> np.random.Generator:
    """A ``numpy.random.Generator`` from a seed, a generator (returned as is) or ``None`` (fresh entropy)."""
    if isinstance(seed, np.random.Generator):
        return seed
    if seed is not None and not isinstance(seed, (int, np.integer)):
        raise TypeError(f"seed must be an int, a numpy Generator or None, got {type(seed).__name__}")
    return np.random.default_rng(seed)


@contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "w") -> Iterator[Any]:
    """Open a temporary file beside ``path``; rename it onto ``path`` only if the block succeeds.

    A reader never sees a half-written file, and a failure leaves any previous file untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, mode) as fh:
            yield fh
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def to_jsonable(obj: Any) -> Any:
    """Convert numpy scalars and arrays (recursively) to plain Python for ``json``."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        value = float(obj)
        return value if np.isfinite(value) else None
    return obj


def write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write ``obj`` as indented JSON, atomically; non-finite floats become ``null``."""
    with atomic_write(path) as fh:
        json.dump(to_jsonable(obj), fh, indent=2)
        fh.write("\n")


def read_json_object(path: str | os.PathLike, what: str) -> dict:
    """A JSON file that must hold one object (e.g. a ``--params`` file).

    :param path: the file.
    :param what: what the object holds, for the error message.
    :raises ValueError: the file is not valid JSON; :raises TypeError: it holds no JSON object.
    """
    with open(path) as fh:
        try:
            raw = json.load(fh)
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(raw, dict):
        raise TypeError(f"{path}: expected a JSON object of {what}")
    return raw


def progress(iterable=None, *, total: int | None = None, desc: str = "", disable: bool | None = None):
    """A tqdm progress bar on stderr; silent when stderr is not a terminal unless asked."""
    from tqdm.auto import tqdm

    if disable is None:
        disable = not os.isatty(2)
    return tqdm(iterable, total=total, desc=desc, disable=disable, leave=False)
