"""The one action check of the single envs: a numeric, finite array of the action space's shape, or a clear error.

Gymnasium users expect out-of-range values to be clipped (the env does that), but a NaN, an inf, a wrong shape, a
non-numeric or a ragged action is a bug in the caller: it is rejected with a one-line ``ValueError`` about the action.
"""

from __future__ import annotations

import numpy as np

__all__ = ["check_action"]


def check_action(action, shape: tuple[int, ...], hint: str = "", column: bool = False) -> np.ndarray:
    """``action`` as an array of ``shape``, checked.

    :param action: what the caller passed to ``step``.
    :param shape: the action space's shape.
    :param hint: what the entries mean, appended to the shape in the error message (e.g. ``"(M, f_x, f_y)"``).
    :param column: also accept a column ``shape + (1,)`` (one action entry per row), returned as ``shape``.
    :raises ValueError: a ragged or non-numeric action, a wrong shape, or a NaN/inf entry.
    """
    try:
        a = np.asarray(action)
    except (ValueError, TypeError):
        raise ValueError(f"action must be a numeric array of shape {shape}, got a ragged sequence {action!r}") from None
    if a.dtype.kind not in "fiu":
        raise ValueError(f"action must be numeric, got dtype {a.dtype}")
    if column and a.shape == (*shape, 1):
        a = a.reshape(shape)
    if a.shape != shape:
        raise ValueError(f"action must have shape {shape}{' ' + hint if hint else ''}, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"action must be finite, got {a.tolist()!r} (NaN or inf)")
    return a
