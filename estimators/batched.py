"""Batched estimators: N independent quarter-car estimators updated in one compiled call.

:class:`BatchedEkfRls` is N :class:`estimators.ekf_rls.QuarterCarEkfRls` side by side (one per sub-env of a vector
env): the same four steps (velocity filter eqs. (4)-(6), slip eq. (3), force EKF eqs. (7)-(8) in Joseph form, RLS
eqs. (10)-(14), the friction map) and the same wheel-speed outlier gate (:class:`estimators.speed_reference.WheelSpeedGate`:
NIS test of :func:`estimators.outliers.gate`, the prediction in place of a rejected speed, the covariance held,
the ``max_rejections + 1``-th rejection in a row restarting the gate), written as one loop over the sub-envs
(:func:`_core_rows`, compiled with numba on first use and cached on disk: numpy calls on arrays of 32 cost more in
call overhead than the arithmetic; the update is about 3x cheaper than the numpy form). Its
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
from estimators.jump import jump_test
from estimators.mhe_batched import BATCHED_MHE
from estimators.speed_reference import (
    FREE_ROLLING_RATE,
    a_x_loop_step,
    brake_lag_shift,
    release_shift,
    speed_step,
)
from fricenv.plants.quarter_car import QuarterCarParams
from fricenv.plants.tire import SLIP_SPEED_FLOOR

__all__ = ["BATCHED", "BatchedEkfRls", "BatchedEstimator", "BatchedGate", "make_batched"]


_INVALID, _OUTLIER, _REINIT = int(Health.INVALID_INPUT), int(Health.OUTLIER), int(Health.REINITIALISED)
_OK, _NOT_EXCITED = int(Health.OK), int(Health.NOT_EXCITED)


def _gate_row(i, omega, torque_prev, ceiling, gc, x, P, started, rejected, jump, commands) -> tuple[float, int]:
    """:class:`~estimators.speed_reference.WheelSpeedGate` for sub-env ``i``: the wheel speed to use and the health it
    implies (``_OK`` when accepted). ``gc`` from :meth:`BatchedGate.constants`; ``jump[i]``: (armed, reference
    speed, sign) of the friction-jump rule (:mod:`estimators.jump`); ``ceiling``: rule (B3)'s bound on a braked
    wheel's prediction (inf: none); ``commands[i]``: rule (B4)'s span of torques, newest last (NaN: none yet).
    Plain Python compiled by :func:`_core_kernel`."""
    dt, I_w, R, b_var0, q_b, bound, max_rej = gc[0], gc[1], gc[2], gc[3], gc[4], gc[5], gc[6]
    if not started[i]:
        started[i], x[i, 0], x[i, 1] = True, omega, 0.0
        P[i, 0, 0], P[i, 0, 1], P[i, 1, 0], P[i, 1, 1] = R, 0.0, 0.0, b_var0
        return omega, _OK
    x0, x1 = x[i, 0] - dt * x[i, 1] + dt * torque_prev / I_w, x[i, 1]  # F x + (dt T / I_w, 0)
    if torque_prev < 0.0 and x0 > ceiling:  # (B3)
        x0 = ceiling
    p00 = P[i, 0, 0] - dt * P[i, 1, 0] - dt * (P[i, 0, 1] - dt * P[i, 1, 1])  # F P F^T + Q
    p01, p10, p11 = P[i, 0, 1] - dt * P[i, 1, 1], P[i, 1, 0] - dt * P[i, 1, 1], P[i, 1, 1] + q_b
    e, S = omega - x0, p00 + R
    nis = e * e / S if S > 0 else np.inf
    t_min, t_max = torque_prev, torque_prev  # (B4): the span's commands, this one last
    for j in range(commands.shape[1] - 1):
        commands[i, j] = commands[i, j + 1]
        if not np.isnan(commands[i, j]):
            t_min, t_max = min(t_min, commands[i, j]), max(t_max, commands[i, j])
    commands[i, commands.shape[1] - 1] = torque_prev
    if nis > bound and rejected[i] == 0:  # (B4): the first failing sample, the brake's lag?
        shift = brake_lag_shift(e, torque_prev, t_min, t_max, ceiling - x0 if torque_prev < 0.0 else np.inf, dt,
                                I_w)
        if (e - shift) * (e - shift) / S <= bound:
            x0, e = x0 + shift, e - shift
            nis = e * e / S
        else:  # (B6): a released wheel spinning up through the tire's peak?
            shift = release_shift(e, x1, torque_prev, t_min, dt, gc[7])
            if (e - shift) * (e - shift) / S <= bound:
                x0, x1, e = x0 + shift, x1 - shift / dt, e - shift
                nis = e * e / S
    if nis <= bound:  # accepted: the Kalman update
        rejected[i] = 0
        k0, k1 = p00 / S, p10 / S
        x[i, 0], x[i, 1] = x0 + k0 * e, x1 + k1 * e
        P[i, 0, 0], P[i, 0, 1], P[i, 1, 0], P[i, 1, 1] = p00 - k0 * p00, p01 - k0 * p01, p10 - k1 * p00, p11 - k1 * p01
        return omega, _OK
    ref = x[i, 0] if rejected[i] == 0 else jump[i, 1]
    is_jump, chain, b = jump_test(rejected[i], jump[i, 0] > 0, jump[i, 2], ref, omega, torque_prev, e, dt, I_w,
                                     gc[7], gc[8])
    jump[i, 0], jump[i, 1], jump[i, 2] = 1.0 if chain else 0.0, omega, np.sign(e)
    if is_jump or rejected[i] >= max_rej:  # a friction jump, or the (max_rejections + 1)-th in a row: restart
        rejected[i], x[i, 0], x[i, 1], jump[i, 0] = 0, omega, b if is_jump else 0.0, 0.0
        P[i, 0, 0], P[i, 0, 1], P[i, 1, 0], P[i, 1, 1] = R, 0.0, 0.0, b_var0
        return omega, _REINIT
    rejected[i] += 1  # rejected: the prediction replaces the speed, the covariance is held
    x[i, 0], x[i, 1] = x0, x1
    return x0, _OUTLIER


def _ekf_row(i, a_x, torque, S, k, x, P, H, A, Q, T, U) -> float:
    """Step 3, eqs. (7)-(8), for sub-env ``i``: a_x update (Joseph form), then the prediction; the updated force.
    ``T``, ``U``: (3, 3) scratch. Plain Python compiled by :func:`_core_kernel` (scalar loops: no allocation)."""
    R, m, R_w, I_w, C_s = k[12], k[4], k[1], k[5], k[6]
    PH0 = P[i, 0, 0] * H[0] + P[i, 0, 1] * H[1] + P[i, 0, 2] * H[2]
    PH1 = P[i, 1, 0] * H[0] + P[i, 1, 1] * H[1] + P[i, 1, 2] * H[2]
    PH2 = P[i, 2, 0] * H[0] + P[i, 2, 1] * H[1] + P[i, 2, 2] * H[2]
    s = PH0 * H[0] + PH1 * H[1] + PH2 * H[2] + R
    K = (PH0 / s, PH1 / s, PH2 / s)
    innov = a_x - (x[i, 0] * H[0] + x[i, 1] * H[1] + x[i, 2] * H[2])
    F = x[i, 2] + K[2] * innov
    for r in range(3):  # T = (I - K H) P
        for c in range(3):
            T[r, c] = P[i, r, c] - K[r] * (H[0] * P[i, 0, c] + H[1] * P[i, 1, c] + H[2] * P[i, 2, c])
    for r in range(3):  # U = T (I - K H)^T + R K K^T, the Joseph form
        for c in range(3):
            U[r, c] = T[r, c] - (T[r, 0] * H[0] + T[r, 1] * H[1] + T[r, 2] * H[2]) * K[c] + R * K[r] * K[c]
    for r in range(3):  # symmetric part, then T = A U
        for c in range(r + 1):
            U[r, c] = U[c, r] = 0.5 * (U[r, c] + U[c, r])
    for r in range(3):
        for c in range(3):
            T[r, c] = A[r, 0] * U[0, c] + A[r, 1] * U[1, c] + A[r, 2] * U[2, c]
    for r in range(3):  # P = A U A^T + Q, symmetric part
        for c in range(3):
            U[r, c] = T[r, 0] * A[c, 0] + T[r, 1] * A[c, 1] + T[r, 2] * A[c, 2] + Q[r, c]
    for r in range(3):
        for c in range(3):
            P[i, r, c] = 0.5 * (U[r, c] + U[c, r])
    x[i, 0], x[i, 1], x[i, 2] = F / m, (-F * R_w + torque) / I_w, C_s * S
    return F


def _core_rows(omega, a_x, T_b, k, gated, gc, gx, gP, started, rejected, gj, gh, y, c, R_g, x, P, k_s, P_rls, s_num,
               s_den, mu_peak, torque_prev, H, A, Q, out) -> None:
    """Steps 1-4 of :class:`~estimators.ekf_rls.EkfRlsCore` for every sub-env, in place; ``out`` gets (S, F,
    health) per sub-env. ``k``: (dt, R_w, d, m_eff, m, I_w, C_s, a_x loop factor, dead zone, lam, F_z, phi_min
    slip, a_x noise variance, rules (B1)-(B3) on (1) or off (0), their margin). Plain Python compiled by
    :func:`_core_kernel`."""
    dt, R_w, d, m_eff, corr, db, lam, Fz = k[0], k[1], k[2], k[3], k[7], k[8], k[9], k[10]
    T, U = np.empty((3, 3)), np.empty((3, 3))
    for i in range(omega.shape[0]):
        if not (np.isfinite(omega[i]) and np.isfinite(a_x[i]) and np.isfinite(T_b[i])):
            out[i, 0], out[i, 1], out[i, 2] = 0.0, 0.0, _INVALID  # skipped: values held
            continue
        torque, w, health = -T_b[i], omega[i], _OK
        if gated:
            ceiling = (y[i] + k[14]) / R_w if k[13] > 0.0 and not np.isnan(y[i]) else np.inf  # (B3)
            w, health = _gate_row(i, omega[i], torque_prev[i], ceiling, gc, gx, gP, started, rejected, gj, gh)
            if health == _REINIT:  # the gate restarted: the RLS forgets the old road (as EkfRlsCore.step)
                P_rls[i] = RLS_P0
        torque_prev[i] = torque
        wr = w * R_w
        if np.isnan(y[i]):  # 1. velocity filter, eqs. (4)-(6) with the a_x loop
            y[i] = wr
        else:
            c_new = a_x_loop_step(c[i], a_x[i], R_g[i], corr, k[13] > 0.0 and torque <= 0.0)
            dead = np.sign(c[i]) * max(abs(c[i]) - db, 0.0) + np.sign(c_new) * max(abs(c_new) - db, 0.0)
            rate = max(R_g[i] + 0.5 * dead, 0.0)
            y[i] = speed_step(y[i], wr, rate, dt, d, k[13] > 0.0 and torque < 0.0, k[14],
                              k[13] > 0.0 and R_g[i] <= FREE_ROLLING_RATE)
            c[i] = c_new
        R_g[i] = abs(torque) / (m_eff * R_w)  # eq. (5)
        S = (wr - y[i]) / max(max(y[i], wr), SLIP_SPEED_FLOOR)  # 2. slip, eq. (3)
        F = _ekf_row(i, a_x[i], torque, S, k, x, P, H, A, Q, T, U)  # 3. force EKF
        phi = Fz * S  # 4. RLS, eqs. (10)-(14)
        if abs(phi) > k[11] * Fz:
            gain = P_rls[i] * phi / (lam + phi * P_rls[i] * phi)  # (12)
            k_s[i] += gain * (F - phi * k_s[i])  # (11), (14)
            P_rls[i] = (P_rls[i] - gain * phi * P_rls[i]) / lam  # (13)
            s_num[i] = lam * s_num[i] + phi * phi * abs(phi) / Fz
            s_den[i] = lam * s_den[i] + phi * phi
        elif health == _OK:
            health = _NOT_EXCITED
        mu_peak[i] = max(mu_peak[i], abs(F) / Fz)
        out[i, 0], out[i, 1], out[i, 2] = S, F, health


_COMPILED_CORE: list = []  # the compiled steps, built on first use (numba is not imported with the module)


def _core_kernel():
    """:func:`_core_rows` compiled with numba (once per process, cached on disk), with :func:`_gate_row` and
    :func:`_ekf_row` compiled into it."""
    if not _COMPILED_CORE:
        import types

        import numba

        jit = numba.njit(cache=True, error_model="numpy")
        gate_row = types.FunctionType(_gate_row.__code__, {**globals(), "jump_test": jit(jump_test),
                                                            "brake_lag_shift": jit(brake_lag_shift),
                                                            "release_shift": jit(release_shift)}, "_gate_row")
        deps = {"_gate_row": jit(gate_row), "_ekf_row": jit(_ekf_row), "speed_step": jit(speed_step),
                "a_x_loop_step": jit(a_x_loop_step)}
        _COMPILED_CORE.append(jit(types.FunctionType(_core_rows.__code__, {**globals(), **deps}, "_core_rows")))
    return _COMPILED_CORE[0]


class _NoGate:
    """Placeholder gate state for an estimator without the wheel-speed gate (the compiled step skips it)."""

    def __init__(self, n: int):
        self.x, self.P = np.zeros((n, 2)), np.zeros((n, 2, 2))
        self.started, self.rejected = np.zeros(n, dtype=bool), np.zeros(n, dtype=np.int64)
        self.jump = np.zeros((n, 3))
        self.commands = np.zeros((n, 1))

    def constants(self) -> np.ndarray:
        return np.zeros(9)


class BatchedGate:
    """The state of N one-wheel :class:`~estimators.speed_reference.WheelSpeedGate` filters, (omega, b) per sub-env; the
    gate's step is part of the compiled update (:func:`_gate_row`).

    :param template: a single wheel-speed gate whose constants (F, Q, R, b's initial spread, gate) are used.
    :param n: number of sub-envs.
    """

    def __init__(self, template, n: int):
        self.t = template
        self.n = n
        self.x = np.zeros((n, 2))
        self.P = np.zeros((n, 2, 2))
        self.started = np.zeros(n, dtype=bool)
        self.rejected = np.zeros(n, dtype=np.int64)
        self.jump = np.zeros((n, 3))  # (armed, reference speed, sign) of the friction-jump rule (estimators.jump)
        self.commands = np.full((n, template.settle), np.nan)  # rule (B4)'s span of torques, newest last

    def reset(self, mask: np.ndarray) -> None:
        self.started[mask] = False
        self.rejected[mask] = 0
        self.jump[mask] = 0.0
        self.commands[mask] = np.nan

    def constants(self) -> np.ndarray:
        """(dt, I_w, R, b's initial variance, q_b, NIS bound, max rejections, jump bound, rest band) for the
        compiled step."""
        t = self.t
        return np.array([t.dt, t.I_w, t.R, t.b_std0[0] ** 2, t.Q[1, 1], t.params.bound, t.params.max_rejections,
                         t.b_bound[0], t.rest_band])


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
        self._no_gate = _NoGate(self.n)
        cfg = self.cfg
        self.consts = np.array([self.dt, cfg.R_w, cfg.d, cfg.m_eff, cfg.m, cfg.I_w, cfg.C_s, c.corr_factor,
                                cfg.deadband, cfg.forgetting, c.Fz_total, PHI_MIN_SLIP, c.R[0, 0],
                                float(cfg.braking_reference), cfg.overshoot_margin])
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
        nan = np.full(self.n, np.nan)  # an invalid sample changes no state: it loads the compiled steps now
        self.update(nan, nan, nan)

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

    def _shape(self, active: np.ndarray, S: np.ndarray, mu_util: np.ndarray, mu_map: np.ndarray,
               restarted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Step 6, the curve-shape fit: (peak friction, peak slip), the map's friction until the fit has data."""
        if self.shape_fit is None:
            return mu_map, np.full(self.n, self.prior_peak_slip)
        if restarted.any():  # the gate restarted (a friction jump): the fit withholds the old road's, as the single one
            self.shape_fit.restart(restarted)
        Fz = self.core.Fz_total
        self.shape_fit.update(np.abs(Fz * S) / Fz, mu_util, self.y, active)  # |phi| / F_z, as the single one
        peak_slip, mu_fit = self.shape_fit.outputs()
        return np.where(np.isfinite(mu_fit), mu_fit, mu_map), peak_slip

    def update(self, omega, a_x, T_b) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """One sample for every sub-env: wheel speed [rad/s], a_x [m/s^2], brake torque held [N m], each (N,).

        :return: values (name -> (N,) array, the single estimator's names) and health (N,) ints.
        """
        omega, a_x, T_b = (np.asarray(a, dtype=float).reshape(self.n) for a in (omega, a_x, T_b))
        out = np.zeros((self.n, 3))  # S, F, health
        g = self.gate or self._no_gate
        _core_kernel()(omega, a_x, T_b, self.consts, self.gate is not None, g.constants(), g.x, g.P, g.started,
                       g.rejected, g.jump, g.commands, self.y, self.c, self.R_g, self.x, self.P, self.k_s, self.P_rls,
                       self.s_num, self.s_den, self.mu_peak, self.torque_prev, self.core.H[0], self.core.A, self.core.Q,
                       out)
        S, F, health = out[:, 0], out[:, 1], out[:, 2].astype(int)
        active = health != int(Health.INVALID_INPUT)
        with np.errstate(divide="ignore", invalid="ignore"):
            s_bar = np.where(self.s_den > 0, self.s_num / self.s_den, 0.0)
        mu_util = np.abs(F) / self.core.Fz_total
        mu, peak_slip = self._shape(active, S, mu_util, self.core.mu_map.batch(self.k_s, s_bar),
                                    health == int(Health.REINITIALISED))
        new = {"v": self.y, "slip": -S, "F_x": -F, "k_s": self.k_s, "mu": mu, "mu_peak": self.mu_peak,
               "mu_utilized": mu_util, "peak_slip": peak_slip}
        every = active.all()
        for k, value in new.items():
            self.last[k] = value.copy() if every else np.where(active, value, self.last[k])
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
