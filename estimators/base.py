"""The one small interface every estimator follows (docs/contracts.md).

An estimator is fed one sample at a time with ``update(measurement, u)`` and answers an :class:`Estimate`: named
values plus a health flag. It never raises inside a loop for a bad sample or a failed solve; it falls back (keeps
its prior, holds the last value) and says so in the flag. Every estimator gates its measurements
(:mod:`estimators.outliers`): a sample that fails the innovation test is skipped (``OUTLIER``), and after too many
in a row the estimator restarts from the measurement (``REINITIALISED``). Configuration errors (bad ``dt``, wrong shapes at
construction, unknown options) do raise, at construction, with a clear message.

:func:`run` drives any estimator over a whole log, given as arrays or as a log file / :class:`QuarterCarLog`.
"""

from __future__ import annotations

import enum
import inspect
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from fricenv.errors import InvalidInputError

__all__ = ["Estimate", "Estimator", "EstimatorConfigError", "Health", "check_dt", "reset_from_wheel", "run"]


class EstimatorConfigError(InvalidInputError):
    """An estimator was configured with invalid options (raised at construction, never inside ``update``)."""


class Health(enum.IntEnum):
    """Health flag of an :class:`Estimate`; the integer value is what an observation carries."""

    OK = 0  # converged / nominal
    NOT_EXCITED = 1  # data not informative: parameters held near their prior
    SOLVER_FAILED = 2  # the numerical solve failed; the estimate is the fallback (prior / last value)
    INVALID_INPUT = 3  # NaN, wrong shape or otherwise unusable sample: the sample was skipped
    OUTLIER = 4  # the sample failed the innovation gate (estimators.outliers): the update skipped it
    REINITIALISED = 5  # too many outliers in a row: the measured states restarted from this sample


@dataclass(frozen=True)
class Estimate:
    """Named estimator outputs and a health flag.

    ``values`` maps names such as ``v``, ``slip``, ``mu``, ``theta``, ``B``, ``C``, ``E``, ``S`` to floats or
    arrays. ``info`` carries diagnostics (solver iterations, singular values, ...), never needed by a consumer.
    """

    values: Mapping[str, float | np.ndarray]
    health: Health = Health.OK
    info: Mapping[str, object] = field(default_factory=dict)

    def __getitem__(self, name: str):
        return self.values[name]

    def __contains__(self, name: str) -> bool:
        return name in self.values

    @property
    def ok(self) -> bool:
        return self.health == Health.OK


def check_dt(dt: float) -> float:
    """Validate a sample time [s]."""
    if not np.isfinite(dt) or dt <= 0:
        raise EstimatorConfigError(f"dt must be a finite positive sample time in seconds, got {dt!r}")
    return float(dt)


class Estimator(ABC):
    """Base class: ``reset`` then ``update`` once per sample.

    Subclasses declare which log columns feed them, so :func:`run` can drive them over a log:

    - ``measurement_columns``: e.g. ``("omega",)`` or ``("omega", "a_x")``;
    - ``input_columns``: e.g. ``("T_b",)``;
    - ``names``: the value names every :class:`Estimate` carries.
    """

    measurement_columns: tuple[str, ...] = ()
    input_columns: tuple[str, ...] = ()
    names: tuple[str, ...] = ()

    @abstractmethod
    def reset(self, **kwargs) -> Estimate:
        """Start over (optionally from given initial values); returns the initial estimate."""

    @abstractmethod
    def update(self, measurement, u) -> Estimate:
        """Take one sample: ``measurement`` in ``measurement_columns`` order, ``u`` in ``input_columns`` order."""

    def _validated_sample(self, measurement, u) -> tuple[np.ndarray, np.ndarray] | None:
        """Measurement and input as 1-D float arrays, or None if the sample is unusable (shape or NaN)."""
        y = np.atleast_1d(np.asarray(measurement, dtype=float))
        uu = np.atleast_1d(np.asarray(u, dtype=float))
        if y.shape != (len(self.measurement_columns),) or uu.shape != (len(self.input_columns),):
            return None
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(uu))):
            return None
        return y, uu


def reset_from_wheel(estimator: Estimator, v0: float, v_std: float) -> Estimate:
    """Reset ``estimator`` from a free-rolling wheel sample: speed ``v0`` [m/s] and slip 0, as far as its ``reset``
    takes them. An estimator whose speed integrates the measured ``a_x`` (``a_x`` among its inputs) keeps the error
    it starts with, so it is also told the sample's spread ``v_std`` [m/s] when its ``reset`` takes one; the others
    keep their prior's spread.

    :param estimator: any :class:`Estimator`.
    :param v0: the wheel's speed [m/s] (omega r); :param v_std: its spread [m/s] (the wheel-speed noise times r).
    """
    accepted = inspect.signature(estimator.reset).parameters
    given = {"v": v0, "v0": v0, "slip": 0.0}
    if "a_x" in estimator.input_columns:
        given["v_std"] = v_std
    return estimator.reset(**{k: val for k, val in given.items() if k in accepted})


def _columns(log, names: Sequence[str]) -> np.ndarray:
    cols = []
    for name in names:
        col = getattr(log, name, None) if not isinstance(log, Mapping) else log.get(name)
        if col is None:
            raise ValueError(f"this estimator needs the log column {name!r}, which the log does not have")
        cols.append(np.asarray(col, dtype=float))
    return np.column_stack(cols) if cols else np.zeros((0, 0))


def run(estimator: Estimator, log, reset_kwargs: Mapping | None = None) -> dict[str, np.ndarray]:
    """Run ``estimator`` over a whole log and stack its outputs.

    :param estimator: any :class:`Estimator`.
    :param log: a path to a quarter-car log file, a :class:`fricenv.logs.QuarterCarLog`, or a mapping of column
        name to array (``t`` plus the estimator's measurement and input columns).
    :param reset_kwargs: passed to ``estimator.reset``.
    :return: one array per value name (time first), plus ``health`` (int array) and ``t``.
    """
    if isinstance(log, (str, bytes)) or hasattr(log, "__fspath__"):
        from fricenv.logs import read_log

        log = read_log(log, plant="quarter-car")
    y = _columns(log, estimator.measurement_columns)
    u = _columns(log, estimator.input_columns)
    t = np.asarray(log["t"] if isinstance(log, Mapping) else log.t, dtype=float)
    estimator.reset(**(reset_kwargs or {}))
    out: dict[str, list] = {name: [] for name in estimator.names}
    health = []
    for k in range(len(t)):
        est = estimator.update(y[k], u[k] if u.size else ())
        for name in estimator.names:
            out[name].append(est.values[name])
        health.append(int(est.health))
    result = {name: np.asarray(vals) for name, vals in out.items()}
    result["health"] = np.asarray(health, dtype=int)
    result["t"] = t
    return result
