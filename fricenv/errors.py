"""The errors fricenv raises for a user's mistake, and how the command line tells them from bugs.

Every error caused by the user's input (an option value, an input file, an output path) is a :class:`FricenvError`
whose message is one line that says what to do; each also subclasses the builtin that fits (``ValueError``,
``TypeError`` or ``OSError``), so ``except ValueError`` in existing callers keeps working. ``fricenv.cli.main``
catches them once: one line on stderr, exit code 2. Anything else is a bug and keeps its traceback.

The domain errors of the library (``UnknownRoadError``, ``UnknownEffectError``, ``EstimatorConfigError``, ...) are
:class:`InvalidInputError` subclasses, so they belong to the family and stay ``ValueError`` for their callers.
"""

from __future__ import annotations

import errno
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = [
    "FricenvError",
    "InputFileError",
    "InvalidInputError",
    "InvalidTypeError",
    "OutputPathError",
    "is_user_error",
    "one_line",
    "user_input",
]


class FricenvError(Exception):
    """Base of the errors caused by the user's input; the message is one line that says what to do."""


class InvalidInputError(FricenvError, ValueError):
    """An option value or an input's content is invalid (unknown name, out of range, malformed file)."""


class InvalidTypeError(FricenvError, TypeError):
    """An input has the wrong type (e.g. a JSON file that holds a list where an object is expected)."""


class InputFileError(FricenvError, OSError):
    """An input file is missing or cannot be read."""


class OutputPathError(FricenvError, OSError):
    """An output path cannot be written (a file where a directory is needed, no permission, read-only)."""


# OSErrors about the user's files or machine, not about fricenv's code: reported in one line wherever they occur.
_USER_ERRNOS = frozenset({
    errno.ENOENT, errno.EACCES, errno.EPERM, errno.EISDIR, errno.ENOTDIR, errno.EEXIST, errno.EROFS,
    errno.ENOSPC, errno.EDQUOT, errno.ENAMETOOLONG, errno.ELOOP,
})


def is_user_error(exc: BaseException) -> bool:
    """True if ``exc`` is about the user's input or files (shown in one line), False if it is a bug.

    User errors: the :class:`FricenvError` family and OSErrors on a named file with an
    errno of the user's making (missing file, no permission, disk full, ...).
    """
    if isinstance(exc, FricenvError):
        return True
    return isinstance(exc, OSError) and exc.filename is not None and exc.errno in _USER_ERRNOS


def one_line(exc: BaseException) -> str:
    """The message of ``exc`` as one line (an OSError names its file and the system's reason)."""
    if isinstance(exc, OSError) and not isinstance(exc, FricenvError) and exc.strerror:
        text = f"{exc.filename}: {exc.strerror}" if exc.filename is not None else exc.strerror
    else:
        text = str(exc) or type(exc).__name__
    return " ".join(text.split())


@contextmanager
def user_input(what: str) -> Iterator[None]:
    """Mark the enclosed validation of user input: a ValueError or TypeError in it becomes a :class:`FricenvError`.

    Use it around a call that validates what the user gave (e.g. building an env from option values), never around
    long work, where a ValueError may be a bug.

    :param what: the input being checked, prefixed to the message (e.g. ``"--v0"``).
    """
    try:
        yield
    except FricenvError:
        raise
    except ValueError as exc:
        raise InvalidInputError(f"{what}: {one_line(exc)}") from exc
    except TypeError as exc:
        raise InvalidTypeError(f"{what}: {one_line(exc)}") from exc
