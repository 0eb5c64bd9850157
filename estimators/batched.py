"""Batched estimators: N independent quarter-car estimators updated in one set of numpy calls.

:class:`BatchedEkfRls` is N :class:`estimators.ekf_rls.QuarterCarEkfRls` side by side (one per sub-env of a vector
env): the same four steps (velocity filter eqs. (4)-(6), slip eq. (3), force EKF eqs. (7)-(8) in Joseph form, RLS
eqs. (10)-(14), the friction map) and the same wheel-speed outlier gate (:class:`estimators.ekf_rls.WheelSpeedGate`:
NIS test of :func:`estimators.outliers.gate`, the prediction in place of a rejected speed, the covariance held,
the ``max_rejections + 1``-th rejection in a row restarting the gate), written over a leading batch axis. Its
constants (noise covariances, Jacobians, gate, friction map) are taken from one single estimator built with the
same arguments, so the two cannot be configured differently; ``tests/test_batched_estimators.py`` checks the
outputs and health flags equal N single estimators to 1e-9 across per-env resets and injected outliers.

A sub-env is reset alone (``reset(mask, v0)``), as an autoreset of a vector env needs. A sample with a non-finite
entry is skipped for that sub-env (values held, ``Health.INVALID_INPUT``), as the single estimator does.

:data:`BATCHED` maps registry names (:data:`estimators.registry.ESTIMATORS`) to batched builders, the MHE's
(:mod:`estimators.mhe_batched`) included;
:func:`make_batched` returns None for an estimator without a batched form (the caller then runs single ones).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from estimators.base import Health
from estimators.curve_shape import ShapeFit
from estimators.ekf_rls import KS0, PHI_MIN_SLIP, RLS_P0, QuarterCarEkfRls
from estimators.mhe_batched import BATCHED_MHE
from estimators.outliers import Verdict
from fricenv.plants.quarter_car import QuarterCarParams

__all__ = ["BATCHED", "BatchedEkfRls", "BatchedEstimator", "BatchedGate", "make_batched"]


def _sym(P: np.ndarray) -> np.ndarray:
    """Symmetric part of a batch of square matrices (N, n, n)."""
    return 0.5 * (P + np.swapaxes(P, -1, -2))


class BatchedGate:
    """N one-wheel :class:`~estimators.ekf_rls.WheelSpeedGate` filters, state (omega, b) per sub-env.

    :param template: a single wheel-speed gate whose constants (F, Q, R, b's initial spread, gate) are used.
    :param n: number of sub-envs.
    """

    def __init__(self, template, n: int):
        self.t = template
        self.n = n
        self.x = np.zeros((n, 2))
        self.P = np.zeros((n, 2, 2))
        self.started = np.zeros(n, dtype=bool)
        self.rejected = np.zeros(n, dtype=int)

    def reset(self, mask: np.ndarray) -> None:
        self.started[mask] = False
        self.rejected[mask] = 0

    def _start(self, rows: np.ndarray, omega: np.ndarray) -> None:
        if not rows.any():
            return
        self.x[rows] = np.stack([omega[rows], np.zeros(rows.sum())], axis=1)
        self.P[rows] = np.diag([self.t.R, self.t.b_std0[0] ** 2])

    def __call__(self, omega: np.ndarray, torque_prev: np.ndarray, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gate the wheel speeds of the ``active`` sub-envs; the speeds to use and a :class:`Verdict` per sub-env."""
        t, F = self.t, self.t.F
        verdict = np.full(self.n, int(Verdict.ACCEPT))
        first = active & ~self.started
        self._start(first, omega)
        self.started |= first
        run = active & ~first
        x = self.x @ F.T
        x[:, 0] += t.dt * torque_prev / t.I_w
        P = F @ self.P @ F.T + t.Q
        e = omega - x[:, 0]
        S = P[:, 0, 0] + t.R
        with np.errstate(divide="ignore", invalid="ignore"):
            nis = np.where(S > 0, e * e / S, np.inf)
        nis = np.where(np.isfinite(nis), nis, np.inf)
        accept = run & (nis <= t.params.bound)
        reinit = run & ~accept & (self.rejected >= t.params.max_rejections)
        reject = run & ~accept & ~reinit
        self.rejected = np.where(reject, self.rejected + 1, np.where(run, 0, self.rejected))
        verdict[reject], verdict[reinit] = int(Verdict.REJECT), int(Verdict.REINIT)
        used = np.where(reject, x[:, 0], omega)
        K = P[:, :, 0] / S[:, None]
        x_acc = x + K * e[:, None]
        P_acc = P - K[:, :, None] * P[:, 0][:, None, :]
        self.x = np.where((accept | reject)[:, None], np.where(accept[:, None], x_acc, x), self.x)
        self.P = np.where(accept[:, None, None], P_acc, self.P)
        self._start(reinit, omega)
        return used, verdict


class BatchedEkfRls:
    """N quarter-car EKF/RLS estimators in one: ``update(omega, a_x, T_b)`` with arrays of shape (N,).

    :param n: number of sub-envs.
    :param dt: sample time [s].
    :param p: quarter-car parameters.
    :param options: keyword arguments of :class:`~estimators.ekf_rls.QuarterCarEkfRls` (``shape``, ``mu_map``,
        ``correction_gain``, ``outlier_gate``, ...); the map must offer ``batch(k_s, s_bar)``.
    """

    names = QuarterCarEkfRls.names

    def __init__(self, n: int, dt: float, p: QuarterCarParams, **options: Any):
        single = QuarterCarEkfRls(dt=dt, p=p, **options)
        self.core = c = single.core
        if not hasattr(c.mu_map, "batch"):
            raise TypeError(f"the friction map {type(c.mu_map).__name__} has no batch(k_s, s_bar) method")
        self.n, self.dt, self.cfg = int(n), c.dt, c.cfg
        self.P0 = c.P.copy()  # the force EKF's initial covariance (the single core has just been reset)
        self.gate = None if c.wheel_gate is None else BatchedGate(c.wheel_gate, self.n)
        self.y = np.full(self.n, np.nan)
        self.c, self.R_g = np.zeros(self.n), np.zeros(self.n)
        self.x, self.P = np.zeros((self.n, 3)), np.zeros((self.n, 3, 3))
        self.k_s, self.P_rls = np.full(self.n, KS0), np.full(self.n, RLS_P0)
        self.s_num, self.s_den, self.mu_peak = np.zeros(self.n), np.zeros(self.n), np.zeros(self.n)
        self.torque_prev = np.zeros(self.n)
        fit = c.shape_fit  # the curve-shape fit, step 6 (estimators.curve_shape), with the single one's bank
        self.shape_fit = None if fit is None else ShapeFit(self.n, fit.bank, fit.params, fit.coupling)
        self.prior_peak_slip = single.prior_peak_slip
        self.last = {k: np.zeros(self.n) for k in self.names}
        self.reset()

    def reset(self, mask: np.ndarray | None = None, v0: np.ndarray | None = None) -> tuple[dict, np.ndarray]:
        """Reset the sub-envs in ``mask`` (all by default), from speeds ``v0`` (N,) if given (else the first
        wheel speed); returns every sub-env's values and the reset's health (NOT_EXCITED)."""
        m = np.ones(self.n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        v = np.full(self.n, np.nan) if v0 is None else np.asarray(v0, dtype=float)
        self.y[m] = v[m]
        for arr, value in ((self.c, 0.0), (self.R_g, 0.0), (self.x, 0.0), (self.k_s, KS0), (self.P_rls, RLS_P0),
                           (self.s_num, 0.0), (self.s_den, 0.0), (self.mu_peak, 0.0), (self.torque_prev, 0.0)):
            arr[m] = value
        self.P[m] = self.P0
        if self.gate is not None:
            self.gate.reset(m)
        if self.shape_fit is not None:
            self.shape_fit.reset(m)
        start = {"v": v, "slip": 0.0, "F_x": 0.0, "k_s": KS0, "mu": self.core.mu_map.batch(KS0, 0.0),
                 "mu_peak": 0.0, "mu_utilized": 0.0, "peak_slip": self.prior_peak_slip}
        for k, value in start.items():
            self.last[k][m] = np.broadcast_to(value, (self.n,))[m]
        health = np.full(self.n, int(Health.NOT_EXCITED))
        return {k: a.copy() for k, a in self.last.items()}, health

    def _velocity(self, active: np.ndarray, x_ref: np.ndarray, a_x: np.ndarray, torque: np.ndarray) -> None:
        """Step 1, eqs. (4)-(6) with the a_x loop, for the active sub-envs (see QuarterCarEkfRls)."""
        cfg, db = self.cfg, self.cfg.deadband
        fresh = np.isnan(self.y)
        c_new = self.c + self.core.corr_factor * (np.abs(a_x) - self.R_g - self.c)
        dead = lambda c: np.sign(c) * np.maximum(np.abs(c) - db, 0.0)
        rate = np.maximum(self.R_g + 0.5 * (dead(self.c) + dead(c_new)), 0.0)
        sat = np.clip((self.y - x_ref) / cfg.d, -1.0, 1.0)  # eq. (6)
        y = np.maximum(self.y - self.dt * rate * sat, 0.0)
        self.y = np.where(active, np.where(fresh, x_ref, y), self.y)
        self.c = np.where(active & ~fresh, c_new, self.c)
        self.R_g = np.where(active, np.abs(torque) / (cfg.m_eff * cfg.R_w), self.R_g)  # eq. (5)

    def _force_ekf(self, active: np.ndarray, a_x: np.ndarray, torque: np.ndarray, S: np.ndarray) -> np.ndarray:
        """Step 3, eqs. (7)-(8): a_x update (Joseph form), then the prediction; the updated forces (N,)."""
        c, cfg = self.core, self.cfg
        H, R = c.H[0], c.R[0, 0]
        PHt = self.P @ H
        s = PHt @ H + R
        K = PHt / s[:, None]
        xk = self.x + K * (a_x - self.x @ H)[:, None]
        IKH = np.eye(3) - K[:, :, None] * H[None, None, :]
        Pk = _sym(IKH @ self.P @ np.swapaxes(IKH, 1, 2) + R * K[:, :, None] * K[:, None, :])
        F = xk[:, 2]
        x_next = np.stack([F / cfg.m, (-F * cfg.R_w + torque) / cfg.I_w, cfg.C_s * S], axis=1)
        P_next = _sym(c.A @ Pk @ c.A.T + c.Q)
        self.x = np.where(active[:, None], x_next, self.x)
        self.P = np.where(active[:, None, None], P_next, self.P)
        return F

    def _rls(self, active: np.ndarray, F: np.ndarray, S: np.ndarray) -> np.ndarray:
        """Step 4, eqs. (10)-(14), where excited; the excitation flags (N,)."""
        lam, Fz = self.cfg.forgetting, self.core.Fz_total
        phi = Fz * S
        excited = active & (np.abs(phi) > PHI_MIN_SLIP * Fz)
        e = F - phi * self.k_s  # (11)
        K = self.P_rls * phi / (lam + phi * self.P_rls * phi)  # (12)
        self.P_rls = np.where(excited, (self.P_rls - K * phi * self.P_rls) / lam, self.P_rls)  # (13)
        self.k_s = np.where(excited, self.k_s + K * e, self.k_s)  # (14)
        s_eff = np.abs(phi) / Fz
        self.s_num = np.where(excited, lam * self.s_num + phi * phi * s_eff, self.s_num)
        self.s_den = np.where(excited, lam * self.s_den + phi * phi, self.s_den)
        return excited

    def _shape(self, active: np.ndarray, S: np.ndarray, mu_util: np.ndarray, mu_map: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
        """Step 6, the curve-shape fit: (peak friction, peak slip), the map's friction until the fit has data."""
        if self.shape_fit is None:
            return mu_map, np.full(self.n, self.prior_peak_slip)
        Fz = self.core.Fz_total
        self.shape_fit.update(np.abs(Fz * S) / Fz, mu_util, self.y, active)  # |phi| / F_z, as the single one
        peak_slip, mu_fit = self.shape_fit.outputs()
        return np.where(np.isfinite(mu_fit), mu_fit, mu_map), peak_slip

    def update(self, omega, a_x, T_b) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """One sample for every sub-env: wheel speed [rad/s], a_x [m/s^2], brake torque held [N m], each (N,).

        :return: values (name -> (N,) array, the single estimator's names) and health (N,) ints.
        """
        omega, a_x, T_b = (np.asarray(a, dtype=float).reshape(self.n) for a in (omega, a_x, T_b))
        active = np.isfinite(omega) & np.isfinite(a_x) & np.isfinite(T_b)
        omega, a_x, torque = np.where(active, omega, 0.0), np.where(active, a_x, 0.0), np.where(active, -T_b, 0.0)
        verdict = np.zeros(self.n, dtype=int)
        if self.gate is not None:
            omega, verdict = self.gate(omega, self.torque_prev, active)
        self.torque_prev = np.where(active, torque, self.torque_prev)
        wr = omega * self.cfg.R_w
        self._velocity(active, wr, a_x, torque)
        S = (wr - self.y) / np.maximum(np.maximum(self.y, wr), 0.1)  # eq. (3)
        F = self._force_ekf(active, a_x, torque, S)
        excited = self._rls(active, F, S)
        with np.errstate(divide="ignore", invalid="ignore"):
            s_bar = np.where(self.s_den > 0, self.s_num / self.s_den, 0.0)
        mu_util = np.abs(F) / self.core.Fz_total
        self.mu_peak = np.where(active, np.maximum(self.mu_peak, mu_util), self.mu_peak)
        mu, peak_slip = self._shape(active, S, mu_util, self.core.mu_map.batch(self.k_s, s_bar))
        new = {"v": self.y, "slip": -S, "F_x": -F, "k_s": self.k_s, "mu": mu, "mu_peak": self.mu_peak,
               "mu_utilized": mu_util, "peak_slip": peak_slip}
        for k, value in new.items():
            self.last[k] = np.where(active, value, self.last[k])
        health = np.select([~active, verdict == Verdict.REJECT, verdict == Verdict.REINIT, excited],
                           [int(Health.INVALID_INPUT), int(Health.OUTLIER), int(Health.REINITIALISED),
                            int(Health.OK)], int(Health.NOT_EXCITED))
        return {k: a.copy() for k, a in self.last.items()}, health


BatchedEstimator = BatchedEkfRls  # the batched interface (reset(mask, v0), update(...)) every entry builds
BATCHED: Mapping[str, Callable[..., BatchedEstimator]] = MappingProxyType({
    "ekf-rls": lambda n, dt, p, options: BatchedEkfRls(n, dt, p, **options),
    "ekf-rls-paper-loop": lambda n, dt, p, options: BatchedEkfRls(n, dt, p, **options),
    "ekf-rls-paper-map": lambda n, dt, p, options: BatchedEkfRls(n, dt, p, **options),
    **BATCHED_MHE,
})


def make_batched(name: str, n: int, params: QuarterCarParams, dt: float, **options: Any) -> BatchedEstimator | None:
    """A batched estimator for the registry entry ``name`` (its variant options applied), or None if it has no
    batched form.

    :param name: registry name (:data:`estimators.registry.ESTIMATORS`).
    :param n: number of sub-envs.
    :param params: the plant parameters the estimator assumes.
    :param dt: sample time [s].
    :param options: constructor arguments added to the variant's.
    """
    from estimators.registry import ESTIMATORS, get_estimator

    if name not in BATCHED or name not in ESTIMATORS:
        return None
    entry = get_estimator(name)
    shape = entry.assumed_shape
    base: dict[str, Any] = dict(entry.options)
    if shape is not None and "mu_map" not in base:
        from fricenv.plants.tire import MagicFormula

        base["shape"] = MagicFormula(shape["B"], shape["C"], shape["E"], shape["theta"])
    return BATCHED[name](n, dt, params, {**base, **options})
