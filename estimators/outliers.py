"""Measurement gating shared by every estimator: a chi-square innovation test and a consecutive-rejection counter.

Rule (one place, used by the EKF, the MHE, the EKF/RLS, the FMS observer and the FMS RLS calibrator). For each
sample the estimator forms its innovation ``e`` (measurement minus its prediction) and the innovation covariance
``S`` (the prediction's covariance plus the measurement noise), and the normalised innovation squared

    NIS = e^T S^-1 e,

which, for a filter consistent with its noise model, is chi-square distributed with ``dof`` = dim(e) degrees of
freedom. :func:`gate` compares it with the bound ``chi2.isf(p_false, dof)`` of :class:`GateParams` (default
``p_false`` = 1e-5: 19.5 for one degree of freedom, 25.9 for three): a sample above the bound cannot be true
(under the model) and is rejected -- the update skips it and the estimate says ``Health.OUTLIER``.

Several rejections in a row must not lock the filter out (a real jump of the signal, a filter that lost track): the
counter of consecutive rejections is carried from sample to sample, and the ``max_rejections + 1``-th sample in a
row that fails the test is not rejected but taken as the new truth: the estimator re-initialises its measured
states from that measurement (widening their covariance back to the initial one) and says
``Health.REINITIALISED`` for that sample. So at most ``max_rejections`` (default 10, 100 ms at 10 ms) samples in a
row are ever discarded.

:func:`gate` is a pure function over the frozen :class:`GateParams`: the estimators keep the counter.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from estimators.base import EstimatorConfigError

__all__ = ["DEFAULT_GATE", "GateParams", "Verdict", "gate", "nis"]

P_FALSE = 1e-5  # default per-sample false-rejection probability of a consistent filter [-]
MAX_REJECTIONS = 10  # default number of samples in a row that may be rejected before a re-initialisation [-]


@dataclass(frozen=True)
class GateParams:
    """The innovation gate: chi-square bound and re-initialisation rule (module docstring).

    :param p_false: probability that a sample consistent with the model is rejected; sets the bound.
    :param dof: degrees of freedom, the innovation's dimension.
    :param max_rejections: samples in a row that may be rejected; the next failing one re-initialises.
    """

    p_false: float = P_FALSE
    dof: int = 1
    max_rejections: int = MAX_REJECTIONS
    bound: float = field(init=False)  # chi-square bound on the NIS [-]

    def __post_init__(self):
        if not (np.isfinite(self.p_false) and 0.0 < self.p_false < 1.0):
            raise EstimatorConfigError(f"gate p_false must be in (0, 1), got {self.p_false!r}")
        if int(self.dof) != self.dof or self.dof < 1:
            raise EstimatorConfigError(f"gate dof must be an integer >= 1, got {self.dof!r}")
        if int(self.max_rejections) != self.max_rejections or self.max_rejections < 0:
            raise EstimatorConfigError(f"gate max_rejections must be an integer >= 0, got {self.max_rejections!r}")
        object.__setattr__(self, "bound", float(chi2.isf(self.p_false, int(self.dof))))

    def with_dof(self, dof: int) -> "GateParams":
        """The same gate for an innovation of another dimension."""
        return GateParams(self.p_false, dof, self.max_rejections)


DEFAULT_GATE = GateParams()


class Verdict(enum.IntEnum):
    """What :func:`gate` decides for one sample."""

    ACCEPT = 0  # update with the sample
    REJECT = 1  # skip the update (Health.OUTLIER)
    REINIT = 2  # too many rejections in a row: re-initialise from the sample (Health.REINITIALISED)


def nis(innovation, S) -> float:
    """Normalised innovation squared ``e^T S^-1 e`` (inf when S is singular or the values are not finite).

    :param innovation: e, scalar or (m,).
    :param S: innovation covariance, scalar or (m, m).
    """
    e = np.atleast_1d(np.asarray(innovation, dtype=float))
    S = np.atleast_2d(np.asarray(S, dtype=float))
    if S.shape == (1, 1):
        value = float(e[0] * e[0] / S[0, 0]) if S[0, 0] > 0 else np.inf
    else:
        try:
            value = float(e @ np.linalg.solve(S, e))
        except np.linalg.LinAlgError:
            value = np.inf
    return value if np.isfinite(value) else np.inf


def gate(nis_value: float, rejected_in_row: int, params: GateParams = DEFAULT_GATE) -> tuple[Verdict, int]:
    """Decide on one sample from its NIS and the number of samples rejected just before it.

    :param nis_value: normalised innovation squared of the sample (:func:`nis`).
    :param rejected_in_row: consecutive rejections before this sample (the estimator's counter).
    :param params: bound and re-initialisation rule.
    :return: (verdict, the counter after this sample).
    """
    if nis_value <= params.bound:
        return Verdict.ACCEPT, 0
    if rejected_in_row >= params.max_rejections:
        return Verdict.REINIT, 0
    return Verdict.REJECT, rejected_in_row + 1
