"""The regularized MHE's options (:class:`MHEConfig`) and their checks, apart from the estimator that uses them.

:class:`MHEConfig` holds what a caller chooses; :meth:`MHEConfig.resolved` fills the per-group defaults (the
paper's alpha, beta, delta for theta alone or all four parameters; the arrival cost; the iterations; the process
noise) once the estimated parameters are known. Every check raises :class:`~estimators.base.EstimatorConfigError`
naming the option.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from estimators.base import EstimatorConfigError
from estimators.outliers import DEFAULT_GATE, GateParams, check_gate
from estimators.quarter_car_model import PARAM_NAMES
from estimators.tuning import DEFAULT_ARRIVAL, DEFAULT_EKF_TUNING, GATE_CHI2, HORIZON, PAPER_TUNING
from fricenv.plants.sui_johansen import OMEGA_NOISE_STD  # [rad/s], Section IV

__all__ = ["ARRIVALS", "MAX_ITER", "MAX_ITER_EKF_ARRIVAL", "WEIGHTINGS", "MHEConfig"]

WEIGHTINGS = ("literal", "scaled")
ARRIVALS = ("paper", "ekf")
MAX_ITER = 4  # Gauss-Newton iterations per update
MAX_ITER_EKF_ARRIVAL = 2  # the same with the EKF arrival cost (a nearly quadratic problem: 2 suffice, measured)


@dataclass(frozen=True)
class MHEConfig:
    """Options of :class:`estimators.mhe.RegularizedMHE` (its docstring says what each does).

    :param horizon: N.
    :param alpha: alpha of eqs. (15)-(16); None: the paper's for the group.
    :param beta: beta_i (one value for all i); None: the paper's.
    :param delta: SVD threshold; None: the paper's (0.1 for theta alone, 0.8 otherwise).
    :param weighting: ``"scaled"`` or ``"literal"``.
    :param arrival: ``"paper"`` or ``"ekf"``; None: ``"paper"`` for the literal weighting, else the group's default.
    :param state_scales: per-state scales of the scaled reading (overrides the group's).
    :param noise_std: wheel-speed noise standard deviation [rad/s].
    :param max_iter: Gauss-Newton iterations per update; None: 2 with the EKF arrival cost, else 4.
    :param model_error: ``"auto"``, (std_v [m/s], std_slip [-]) per sample, or None (hard dynamics).
    :param gate: EKF-consistency gate (squared Mahalanobis distance) or None.
    :param outlier_gate: the wheel-speed gate or None.
    """

    horizon: int = HORIZON
    alpha: float | None = None
    beta: float | None = None
    delta: float | None = None
    weighting: str = "scaled"
    arrival: str | None = None
    state_scales: Mapping[str, float] | None = None
    noise_std: float = OMEGA_NOISE_STD
    max_iter: int | None = None
    model_error: tuple[float, float] | str | None = "auto"
    gate: float | None = GATE_CHI2
    outlier_gate: GateParams | None = DEFAULT_GATE

    def __post_init__(self):
        if self.weighting not in WEIGHTINGS:
            raise EstimatorConfigError(f"weighting must be one of {WEIGHTINGS}, got {self.weighting!r}")
        if self.arrival is not None and self.arrival not in ARRIVALS:
            raise EstimatorConfigError(f"arrival must be one of {ARRIVALS} or None (per-group default), "
                                       f"got {self.arrival!r}")
        if int(self.horizon) != self.horizon or self.horizon < 1:
            raise EstimatorConfigError(f"horizon must be an integer >= 1, got {self.horizon!r}")
        bad = [k for k in (self.state_scales or {}) if k not in ("v", "slip") + PARAM_NAMES]
        if bad:
            raise EstimatorConfigError(f"state_scales keys {bad} unknown; valid: v, slip, {', '.join(PARAM_NAMES)}")
        if self.max_iter is not None and (int(self.max_iter) != self.max_iter or self.max_iter < 1):
            raise EstimatorConfigError(f"max_iter must be an integer >= 1, got {self.max_iter!r}")
        if isinstance(self.model_error, str) and self.model_error != "auto":
            raise EstimatorConfigError(
                f"model_error must be 'auto', None or (std_v, std_slip), got {self.model_error!r}")
        if self.model_error is not None and not isinstance(self.model_error, str):
            err = np.asarray(self.model_error, dtype=float)
            if err.shape != (2,) or not np.all(np.isfinite(err) & (err > 0)):
                raise EstimatorConfigError(f"model_error must be two positive std's (v, slip), got {err!r}")
        if self.gate is not None and not (np.isfinite(self.gate) and self.gate > 0):
            raise EstimatorConfigError(f"gate must be a positive squared distance or None, got {self.gate!r}")
        check_gate(self.outlier_gate)

    def resolved(self, group: str) -> MHEConfig:
        """Every None default filled for a parameter group (``"theta-only"`` or ``"all"``), and the checks that
        need them: alpha, beta, delta, noise_std ranges; process noise only with the EKF arrival cost."""
        tuning = PAPER_TUNING[group]
        alpha = float(tuning["alpha"] if self.alpha is None else self.alpha)
        beta = float(tuning["beta"] if self.beta is None else self.beta)
        delta = float(tuning["delta"] if self.delta is None else self.delta)
        for name, value, strict in (("alpha", alpha, True), ("beta", beta, False), ("delta", delta, False),
                                    ("noise_std", self.noise_std, True)):
            if not np.isfinite(value) or value < 0 or (strict and value == 0):
                raise EstimatorConfigError(f"{name} must be finite and {'> 0' if strict else '>= 0'}, got {value!r}")
        arrival = self.arrival
        if arrival is None:  # the literal reading is a paper comparison: with the paper's prior terms
            arrival = "paper" if self.weighting == "literal" else DEFAULT_ARRIVAL[group]
        max_iter = self.max_iter
        if max_iter is None:
            max_iter = MAX_ITER_EKF_ARRIVAL if arrival == "ekf" else MAX_ITER
        model_error = self.model_error
        if isinstance(model_error, str):
            ekf_q = DEFAULT_EKF_TUNING["Q_std"]
            model_error = (ekf_q["v"], ekf_q["slip"]) if arrival == "ekf" else None
        if model_error is not None and arrival != "ekf":
            raise EstimatorConfigError("model_error (process noise) needs arrival='ekf': the paper's prior terms "
                                       "beta_i pin every window state to the a priori trajectory of eq. (11) and "
                                       "fight the process noise (measured: the estimate diverges in case 1)")
        return replace(self, alpha=alpha, beta=beta, delta=delta, arrival=arrival, max_iter=int(max_iter),
                       model_error=None if model_error is None else tuple(float(m) for m in model_error),
                       horizon=int(self.horizon), noise_std=float(self.noise_std))
