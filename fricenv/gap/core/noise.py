"""Noise levels and the gap in noise units, shared by every plant's diagnosis."""

from __future__ import annotations

from math import comb

import numpy as np

__all__ = ["estimate_noise", "gap_of"]


def estimate_noise(x: np.ndarray, order: int = 2) -> float:
    """Noise std of a sampled signal from the median absolute difference of the given order (robust to sparse
    kinks). White noise of std s gives k-th differences of std s sqrt(binomial(2k, k)); a higher order suppresses a
    smooth signal better at coarse sample times.

    :param x: the samples.
    :param order: difference order k >= 1 (default 2).
    """
    if int(order) != order or order < 1:
        raise ValueError(f"order must be a positive integer, got {order!r}")
    dk = np.diff(np.asarray(x, dtype=float), int(order))
    if dk.size < 3:
        return float("nan")
    mad = np.median(np.abs(dk - np.median(dk)))
    return float(1.4826 * mad / np.sqrt(comb(2 * int(order), int(order))))


def gap_of(mse: float) -> float:
    """Model part of a mean squared normalised residual, in noise units: sqrt(max(mse - 1, 0))."""
    return float(np.sqrt(max(mse - 1.0, 0.0)))
