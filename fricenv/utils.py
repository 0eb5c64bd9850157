"""Small shared helpers: seeding, atomic file writes with the user's umask, checks of input files and output paths
before long work, JSON input and output, progress of loops."""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from fricenv.errors import InputFileError, InvalidInputError, InvalidTypeError, OutputPathError

__all__ = [
    "as_generator",
    "atomic_write",
    "check_input_file",
    "check_output_dir",
    "check_output_file",
    "progress",
    "read_json_object",
    "save_figure",
    "to_jsonable",
    "write_json",
]


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

    A reader never sees a half-written file, and a failure leaves any previous file untouched. The file gets the
    mode a plain ``open`` would give it (0666 less the umask: 0644 by default), not mkstemp's 0600.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, 0o666 & ~_umask())
        with os.fdopen(fd, mode) as fh:
            yield fh
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _umask() -> int:
    """The process umask (read by setting it and restoring it at once)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def save_figure(fig, path: str | os.PathLike, **savefig_kwargs: Any) -> None:
    """Save a matplotlib figure as PNG atomically (never a half-written plot)."""
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", **savefig_kwargs)


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
    :raises InputFileError: the file is missing or unreadable; :raises InvalidInputError: it is not valid JSON;
        :raises InvalidTypeError: it holds no JSON object.
    """
    check_input_file(path, f"{what} file")
    try:
        with open(path, encoding="utf-8") as fh:
            raw = json.load(fh)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InvalidInputError(f"{path}: not valid JSON ({exc}); expected a JSON object of {what}") from None
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read {what} ({exc.strerror})") from None
    if not isinstance(raw, dict):
        raise InvalidTypeError(f"{path}: expected a JSON object of {what}, found a JSON {type(raw).__name__}")
    return raw


def check_input_file(path: str | os.PathLike, what: str) -> Path:
    """``path`` as a Path if it is a readable file.

    :param path: the input file.
    :param what: what it is, for the message (e.g. ``"--params"`` or ``"log"``).
    :raises InputFileError: naming the file and what is wrong with it.
    """
    p = Path(path)
    if not p.exists():
        raise InputFileError(f"{what} {path}: no such file")
    if p.is_dir():
        raise InputFileError(f"{what} {path}: is a directory, expected a file")
    if not os.access(p, os.R_OK):
        raise InputFileError(f"{what} {path}: not readable (permission denied)")
    return p


def _check_can_create_in(directory: Path, what: str, path: str | os.PathLike) -> None:
    """``directory`` exists as a writable directory, or can be created under its nearest existing ancestor."""
    ancestor = directory
    while not os.path.lexists(ancestor) and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise OutputPathError(f"{what} {path}: {ancestor} is a file, not a directory; choose another path")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise OutputPathError(f"{what} {path}: directory {ancestor} is not writable; choose another path")


def check_output_file(path: str | os.PathLike, what: str) -> Path:
    """``path`` as a Path if a file can be written there; nothing is created.

    :param path: the output file.
    :param what: the option that names it, for the message (e.g. ``"--json"``).
    :raises OutputPathError: it is a directory, or its directory cannot be created or written.
    """
    p = Path(path)
    if p.is_dir():
        raise OutputPathError(f"{what} {path}: is a directory, expected a file name")
    _check_can_create_in(p.parent, what, path)
    return p


def check_output_dir(path: str | os.PathLike, what: str) -> Path:
    """``path`` as a Path if it is, or can be created as, a writable directory; nothing is created.

    :param path: the output directory.
    :param what: the option that names it, for the message (e.g. ``"--out"``).
    :raises OutputPathError: it is a file, or it cannot be created or written.
    """
    p = Path(path)
    if os.path.lexists(p) and not p.is_dir():
        raise OutputPathError(f"{what} {path}: is a file, expected a directory")
    _check_can_create_in(p, what, path)
    return p


def progress(iterable: Iterable, *, total: int | None = None, desc: str = "", disable: bool | None = None):
    """Iterate over ``iterable``, reporting one step per item to the progress sink (:mod:`fricenv.progress`).

    Nothing is shown unless a front end installed a sink (the CLI does, unless ``--quiet`` or stdout is not a
    terminal).

    :param iterable: the items.
    :param total: number of items (default ``len(iterable)`` when it has one).
    :param desc: label of the task.
    :param disable: True: report nothing.
    """
    from fricenv import progress as progress_events

    if disable:
        yield from iterable
        return
    if total is None and hasattr(iterable, "__len__"):
        total = len(iterable)
    with progress_events.task(desc, total) as advance:
        for item in iterable:
            yield item
            advance()
