"""Uniform time grids for real logs: jittered stamps, dropped rows and held samples (docs/contracts.md, section 1).

Pure numerics on arrays; :mod:`fricenv.logs` calls them and turns a :class:`StepError` into a message naming the
file, line and column.

Resampling rule. Let ``h0`` be the median step of the stamps. Every step must be a whole number ``n`` of ``h0``
(``1 <= n <= 1 + MAX_FILL``) to within ``MAX_JITTER`` of ``h0``; otherwise the log is rejected at that row. If every
step is already within ``UNIFORM_TOL`` of ``h0`` the log is kept as it is. Else the grid is ``t0 + k h``,
``k = 0 .. N`` with ``N`` the sum of the ``n`` and ``h = (t_last - t0) / N`` (the mean step, so the grid ends on the
last stamp); continuous channels are linearly interpolated at the grid times from the finite samples, and the
commanded torque is held (zero-order hold: a grid point takes the value of the row mapped to it, a filled gap the
value before it). A grid point whose row is missing (NaN) in a channel stays missing there; a filled gap point is
missing where either of its neighbouring rows is.

Held-sample rule. In a channel that changes at least ``MIN_CHANGES`` times, a row whose value equals exactly the
previous row's is a held sample (a slower sensor repeating its last value), unless the value is exactly 0 (a wheel
or a car at rest, a sensor's floor) or the run it belongs to lasts longer than ``MAX_HOLD_S`` (a genuinely constant
reading). Held samples become NaN: missing, not measured. When the log is resampled, a channel with held samples
keeps each fresh sample's value at its row's grid point (no interpolation: the neighbouring fresh samples are other
frames, rows away) and its other grid points are missing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fricenv.errors import InvalidInputError

__all__ = [
    "MAX_FILL",
    "MAX_HOLD_S",
    "MAX_JITTER",
    "MIN_CHANGES",
    "UNIFORM_TOL",
    "Grid",
    "StepError",
    "fill_short_gaps",
    "held_mask",
    "plan_grid",
    "resample",
]

UNIFORM_TOL = 1e-3  # every step within this share of the median step: already uniform, kept as it is [-]
MAX_JITTER = 0.25  # largest distance of a step from a whole number of median steps, in median steps [-]
MAX_FILL = 3  # most consecutive missing rows filled (a gap of up to 4 steps) [-]
MIN_CHANGES = 3  # a channel with fewer value changes is constant by nature: nothing in it is "held" [-]
MAX_HOLD_S = 1.0  # a run of equal values longer than this is a genuine reading, not a held sample [s]


class StepError(InvalidInputError):
    """A time step the grid cannot take; ``row`` is the index of the row that ends it."""

    def __init__(self, row: int, message: str):
        super().__init__(message)
        self.row = row


@dataclass(frozen=True)
class Grid:
    """The uniform grid a log is resampled onto (:func:`plan_grid`)."""

    index: np.ndarray  # grid index of each row (increasing; gaps where rows were dropped)
    step: float  # grid step h [s]
    median_step: float  # median step of the stamps h0 [s]
    max_jitter: float  # largest |step - n h0| / h0 over the rows [-]

    @property
    def size(self) -> int:
        """Number of grid points."""
        return int(self.index[-1]) + 1

    @property
    def filled(self) -> int:
        """Grid points without a row of their own (dropped rows filled in)."""
        return self.size - len(self.index)

    def times(self, t0: float) -> np.ndarray:
        """The grid times [s] from ``t0``."""
        return t0 + np.arange(self.size) * self.step

    def summary(self) -> dict:
        """What was done, for the log object and the report."""
        return {"method": "linear interpolation; zero-order hold for T_b", "step": self.step,
                "median_step": self.median_step, "max_jitter": self.max_jitter, "filled": self.filled,
                "rows": len(self.index), "samples": self.size}


def plan_grid(t: np.ndarray) -> Grid | None:
    """The grid for increasing stamps ``t``, or None if they are already uniform (:data:`UNIFORM_TOL`).

    :raises StepError: a step off a whole number of median steps by more than :data:`MAX_JITTER`, shorter than half
        a step, or longer than ``1 + MAX_FILL`` steps.
    """
    dt = np.diff(t)
    h0 = float(np.median(dt))
    if np.all(np.abs(dt - h0) <= UNIFORM_TOL * h0):
        return None
    ratio = dt / h0
    n = np.rint(ratio)
    off = np.abs(ratio - n)
    for i in range(len(dt)):  # the first offending row, with the reason
        if n[i] < 1 or off[i] > MAX_JITTER or n[i] > 1 + MAX_FILL:
            raise StepError(i + 1, _step_problem(float(dt[i]), h0, float(ratio[i])))
    index = np.concatenate([[0], np.cumsum(n.astype(int))])
    return Grid(index=index, step=float((t[-1] - t[0]) / index[-1]), median_step=h0, max_jitter=float(off.max()))


def _step_problem(dt: float, h0: float, ratio: float) -> str:
    if ratio > 1 + MAX_FILL + MAX_JITTER:
        return (f"gap of {dt:.6g} s ({ratio:.3g} steps of {h0:.6g} s): more than {MAX_FILL} missing samples in a "
                f"row; split the log at the gap")
    return (f"step {dt:.6g} s is {ratio:.3g} median steps ({h0:.6g} s): time-stamp jitter above "
            f"{MAX_JITTER:.0%} of the step; resample the log to a uniform step")


def resample(t: np.ndarray, cols: dict[str, np.ndarray], grid: Grid, hold: tuple[str, ...] = ("T_b",),
             keep: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """Every channel of ``cols`` (rows at stamps ``t``) on ``grid`` (see the module docstring); ``t`` included.

    :param hold: channels resampled by zero-order hold (commanded values); the others are interpolated linearly.
    :param keep: channels whose present samples keep their own value at their row's grid point (a slower sensor
        with held samples: its fresh sample is a frame taken some time before the row's stamp anyway, and
        interpolating towards the next frame, rows away, would mix two frames); the other points are missing.
    """
    times = grid.times(float(t[0]))
    out: dict[str, np.ndarray] = {"t": times}
    for name, x in cols.items():
        if name in keep:
            out[name] = np.full(grid.size, np.nan)
            out[name][grid.index] = x
        elif name != "t":
            out[name] = _held_on_grid(x, grid) if name in hold else _interp_on_grid(t, x, times, grid)
    return out


def _held_on_grid(x: np.ndarray, grid: Grid) -> np.ndarray:
    src = np.full(grid.size, -1)
    src[grid.index] = np.arange(len(grid.index))
    return x[np.maximum.accumulate(src)]  # a filled point holds the row before it


def _interp_on_grid(t: np.ndarray, x: np.ndarray, times: np.ndarray, grid: Grid) -> np.ndarray:
    ok = np.isfinite(x)
    if np.count_nonzero(ok) < 2:
        return np.full(grid.size, np.nan)
    y = np.interp(times, t[ok], x[ok])
    # the row at or before each grid point, and the row after it: a point is missing where its own row is, and a
    # filled point where either neighbour is
    before = np.searchsorted(grid.index, np.arange(grid.size), side="right") - 1
    after = np.minimum(before + 1, len(grid.index) - 1)
    own = grid.index[before] == np.arange(grid.size)
    missing = np.where(own, ~ok[before], ~ok[before] | ~ok[after])
    y[missing] = np.nan
    return y


def held_mask(x: np.ndarray, step: float) -> np.ndarray:
    """The held samples of a channel (see the module docstring): True where a row repeats the previous value.

    :param x: the channel's rows (NaN allowed: never held).
    :param step: the median time step [s], for :data:`MAX_HOLD_S`.
    """
    mask = np.zeros(len(x), dtype=bool)
    same = x[1:] == x[:-1]
    if np.count_nonzero(~same & np.isfinite(x[1:]) & np.isfinite(x[:-1])) < MIN_CHANGES:
        return mask
    run = np.cumsum(np.concatenate([[True], ~same])) - 1  # run id of each row
    held_in_run = np.bincount(run) - 1  # rows after the first of each run
    max_held = max(round(MAX_HOLD_S / step), 1)
    mask[1:] = same & (x[1:] != 0.0) & (held_in_run[run[1:]] <= max_held)
    return mask


def fill_short_gaps(x: np.ndarray, max_run: int = MAX_FILL) -> tuple[np.ndarray, int | None]:
    """Interior runs of up to ``max_run`` NaN rows filled by linear interpolation (in row index).

    :return: the filled copy, and the first row of a NaN run that could not be filled (at an end, or too long),
        or None.
    """
    bad = ~np.isfinite(x)
    if not bad.any():
        return x, None
    start = np.flatnonzero(bad & ~np.concatenate([[False], bad[:-1]]))
    stop = np.flatnonzero(bad & ~np.concatenate([bad[1:], [False]])) + 1
    for a, b in zip(start, stop):
        if a == 0 or b == len(x) or b - a > max_run:
            return x, int(a)
    rows = np.arange(len(x))
    y = x.copy()
    y[bad] = np.interp(rows[bad], rows[~bad], x[~bad])
    return y, None
