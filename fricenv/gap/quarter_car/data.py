"""The quarter-car log prepared for the fits (:class:`Data`): samples, noise levels, windows and folds."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fricenv.plants import quarter_car as qc

__all__ = ["Data"]


@dataclass
class Data:
    """The log prepared for fitting (picklable for the worker processes)."""

    t0: float
    dt: float
    Tb: np.ndarray
    omega: np.ndarray
    v: np.ndarray | None
    a_x: np.ndarray | None
    sigma: dict  # noise std per logged channel
    v_smooth: np.ndarray | None
    starts: np.ndarray  # window start indices
    fold: np.ndarray  # cross-fitting fold of each window
    test: np.ndarray  # bool per window: held out in the fit at hand (the others are its training windows)
    horizon: int
    free_end: int  # first sample after the free-rolling stretch
    p: qc.QuarterCarParams
    substeps: int
    meas: dict | None = None  # channel -> measured samples, NaN where missing, held or an outlier
    counts: np.ndarray | None = None  # (windows,) residual samples with a fresh measurement per window
    sensors: dict | None = None  # channel -> ChannelCondition.summary() (missing, outliers, filtered, quantised)
    compiled: bool = True  # windows simulated by the compiled kernel (DiagnoseConfig.compiled)
    # kernel threads, in the main process and in each of the diagnosis' ``jobs`` worker processes: the phases with
    # fewer fits than workers (the last fits of a phase, the main process's own fits) then use every core
    threads: int = 1

    @property
    def n(self) -> int:
        return len(self.Tb)

    @property
    def channels(self) -> list[str]:
        return ["omega"] + (["v"] if self.v is not None else []) + (["a_x"] if self.a_x is not None else [])
