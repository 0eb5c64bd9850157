"""The one object every step of a quarter-car diagnosis works in (:class:`FitContext`)."""

from __future__ import annotations

from dataclasses import dataclass

from fricenv.gap.quarter_car.config import DiagnoseConfig
from fricenv.gap.quarter_car.data import Data
from fricenv.plants import quarter_car as qc

__all__ = ["FitContext"]


@dataclass(frozen=True)
class FitContext:
    """The prepared log, its cross-fitting folds, the settings and the worker processes of one diagnosis.

    :param d: the whole log prepared for fitting (every window held out by one fold).
    :param folds: the log once per fold, that fold's windows held out (:func:`fricenv.gap.quarter_car.stats.fold_data`).
    :param cfg: the settings (a step may run with a variant: ``dataclasses.replace(ctx, cfg=...)``).
    :param jobs: worker processes of the fits.
    """

    d: Data
    folds: tuple[Data, ...]
    cfg: DiagnoseConfig
    jobs: int

    @property
    def p(self) -> qc.QuarterCarParams:
        """The nominal vehicle parameters the log was prepared with."""
        return self.d.p
