"""N regularized MHEs (:class:`estimators.mhe.RegularizedMHE`) side by side, one per sub-env of a vector env.

:class:`BatchedMHE` runs the single MHE's update for every sub-env in one set of numpy calls and one CasADi call per
Levenberg-Marquardt trial point: the alongside EKF (outlier gate, Joseph update, prediction), the window buffers,
the SVD weighting of eqs. (14)-(16) in the arrival covariance's units, the projected Levenberg-Marquardt solve of
eq. (12), the fallback to the a priori trajectory and the EKF-consistency gate, all over a leading batch axis.

Where the single MHE's time goes (cProfile of 1,000 updates in the braking env, theta alone): about 40 % in
CasADi's virtual machine (the window function, about 24,000 SX instructions, 3 calls per update, and the EKF's
model step, 1 call), the rest in Python and numpy bookkeeping of small arrays, of which about 0.2 ms per update
in converting CasADi's ``DM`` results to numpy. The batched form removes both: the numpy work is shared by the N
sub-envs, and the window function and the EKF's model step are compiled to C (:mod:`estimators.casadi_compiled`,
about 10x faster than the virtual machine, same results) and evaluated for all N sub-envs by one
``Function.map(N)`` call (``parallel="thread"``: CasADi's thread map, at most 2 threads).

Lockstep solve. The single solver's iterations branch per instance (a trial point accepted or not, damping raised,
early stop); the batched solver takes one trial point per live instance per pass and applies each instance's own
decision, so every instance follows the single solver's sequence of trial points exactly; an instance that has
stopped rides along unchanged. Every operation is the single MHE's on the same operands (numpy's stacked
``matmul`` and ``linalg`` calls run the same BLAS/LAPACK routines per matrix; ``einsum`` is avoided, it sums in
another order; the SVD weights and the step's linear system are computed per group of windows with the same
pattern of kept samples, thresholded directions and free variables), so the results equal N single MHEs to the
last bit on the tested machine (``tests/estimators/test_mhe_batched.py`` asserts 1e-9 across resets, outliers,
NaN samples and forced solver failures). Bit equality matters: a window without information (a stopped car,
every singular value near 0) has an arbitrary SVD basis, and a last-bit difference upstream changes its weights
and the estimate by 1e-5 (measured before the grouping). A linear-algebra error (a covariance that is not positive definite, an SVD that does not
converge) fails only the instance it belongs to (``Health.SOLVER_FAILED``, the single MHE's fallback).

Scope: the MHE of the observation entries ``mhe`` and ``mhe-full`` (EKF arrival cost, the scaled weighting, with
or without process noise and the gate); the paper's prior terms and the literal weighting are refused
(:class:`~estimators.base.EstimatorConfigError`): run single MHEs for those.

:data:`BATCHED_MHE` maps registry names to builders with the signature of :data:`estimators.batched.BATCHED`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from estimators.base import EstimatorConfigError, Health
from estimators.casadi_compiled import BatchCall, compiled, densified
from estimators.ekf import torque_jump_std, torque_step_noise
from estimators.mhe import PD_JITTER, RegularizedMHE
from estimators.mhe_solver import BatchedWindowSolver, sym
from estimators.mismatch import WheelSpeedGuard
from estimators.outliers import Verdict
from estimators.tuning import SLIP_PRIOR, V_PRIOR, brake_settle_samples
from fricenv.plants.tire import magic_formula

__all__ = ["BATCHED_MHE", "PARALLEL", "BatchedMHE", "mhe_builder"]

PARALLEL = ("serial", "thread")  # Function.map modes offered
MAX_THREADS = 2  # CasADi threads of the thread map (the machine budget: 2 cores)


class BatchedMHE:
    """N :class:`~estimators.mhe.RegularizedMHE` in one: ``update(omega, a_x, T_b)`` with arrays of shape (N,).

    The constants (model, tuning, bounds, compiled window function) come from one single MHE, ``template``, so the
    two cannot be configured differently. ``a_x`` is accepted for the batched interface and not used (the MHE
    measures the wheel speed only).

    :param template: a single MHE built as the sub-envs' would be (e.g. ``get_estimator("mhe").make(p, dt)``).
    :param n: number of sub-envs.
    :param parallel: ``"serial"`` (one C loop over the N windows) or ``"thread"`` (CasADi's thread map).
    :param threads: threads of the thread map (1 or 2).
    :param compile_c: compile the CasADi functions to C (:mod:`estimators.casadi_compiled`); without a compiler
        the virtual machine is used (same results, slower).
    """

    names = RegularizedMHE.names

    def __init__(self, template: RegularizedMHE, n: int, parallel: str = "serial", threads: int = MAX_THREADS,
                 compile_c: bool = True):
        if not isinstance(template, RegularizedMHE):
            raise TypeError(f"template must be a RegularizedMHE, got {type(template).__name__}")
        if template.arrival != "ekf" or template.weighting != "scaled":
            raise EstimatorConfigError(f"the batched MHE runs the EKF arrival cost with the scaled weighting, got "
                                       f"arrival={template.arrival!r}, weighting={template.weighting!r}; run "
                                       f"single MHEs (SyncVectorEnv) for the paper's variants")
        if int(n) != n or n < 1:
            raise EstimatorConfigError(f"n must be an integer >= 1, got {n!r}")
        if parallel not in PARALLEL:
            raise EstimatorConfigError(f"parallel must be one of {PARALLEL}, got {parallel!r}")
        if threads not in range(1, MAX_THREADS + 1):
            raise EstimatorConfigError(f"threads must be 1..{MAX_THREADS}, got {threads!r}")
        self.t = t = template
        self.n, self.nx, self.N1 = int(n), t.model.nx, t.N + 1
        dense = [densified(f) for f in (t._fun, t.model._functions()["fF"])]
        fast = [compiled(f) if compile_c else None for f in dense]
        self.compiled = all(f is not None for f in fast)  # else the virtual machine (same results)
        window, predict = (c or d for c, d in zip(fast, dense))
        self.solver = BatchedWindowSolver(t, lambda k: BatchCall(window, k, parallel, threads))
        self._predict = BatchCall(predict, self.n, parallel, threads)
        n, nx, N1 = self.n, self.nx, self.N1
        self.ekf_x, self.ekf_P = np.zeros((n, nx)), np.zeros((n, nx, nx))
        self.post_x, self.post_P = np.zeros((n, nx)), np.zeros((n, nx, nx))
        guard = self.t.arrival_filter.guard
        self.guards = [WheelSpeedGuard(guard.model, guard.params, guard.noise_std) for _ in range(n)]
        self.torque_prev = np.zeros(n)  # brake torque held since the last sample, per sub-env [N m]
        # the torques commanded over the brake's settling span, newest last, per sub-env (NaN: none yet) [N m]
        self.commands = np.full((n, brake_settle_samples(t.model.dt)), np.nan)
        # per window sample, the variance of (v, slip) the torque error's jump adds over the EKF's time update [-]
        self.torque_variance = np.zeros((n, N1, 2))
        self.y, self.u, self.used = np.zeros((n, N1)), np.zeros((n, N1)), np.ones((n, N1), dtype=bool)
        self.hist_x, self.hist_P = np.zeros((n, N1, nx)), np.zeros((n, N1, nx, nx))
        self.count = np.zeros(n, dtype=int)  # samples in the window buffer
        self.has_prev = np.zeros(n, dtype=bool)  # the last solve's model errors warm-start the next
        self.w_prev = np.zeros((n, self.solver.nz - nx))
        self.last = np.zeros((n, nx))
        self.reset()

    # ------------------------------------------------------------------ interface
    def values(self) -> dict[str, np.ndarray]:
        """Every sub-env's current values (the single MHE's names), each (N,)."""
        x = self.last
        B, C, E, theta = self.t.model.road(x.T)
        bc = lambda a: np.broadcast_to(np.asarray(a, dtype=float), (self.n,)).copy()
        return {"v": x[:, 0].copy(), "slip": x[:, 1].copy(), "theta": bc(theta), "B": bc(B), "C": bc(C),
                "E": bc(E), "mu": bc(magic_formula(x[:, 1], B, C, E, theta))}

    def reset(self, mask: np.ndarray | None = None, v0: np.ndarray | None = None) -> tuple[dict, np.ndarray]:
        """Reset the sub-envs in ``mask`` (all by default) from speeds ``v0`` (N,) [m/s] (default the prior, 19 m/s)
        and slip 0, as ``RegularizedMHE.reset(v=v0)``; returns every sub-env's values and the reset's health (OK)."""
        m = np.ones(self.n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        x0 = np.tile(self.t.model.nominal_state(V_PRIOR, SLIP_PRIOR), (self.n, 1))
        if v0 is not None:
            x0[:, 0] = np.asarray(v0, dtype=float)
        self.ekf_x[m], self.ekf_P[m], self.last[m] = x0[m], self.t._P0, x0[m]
        self.count[m], self.has_prev[m], self.torque_prev[m], self.commands[m] = 0, False, 0.0, np.nan
        for i in np.flatnonzero(m):
            self.guards[i].reset()
        return self.values(), np.full(self.n, int(Health.OK))

    def update(self, omega, a_x, T_b) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """One sample for every sub-env: wheel speed [rad/s] and the brake torque held [N m], each (N,).

        :param omega: measured wheel speeds.
        :param a_x: measured accelerations (not used by the MHE).
        :param T_b: brake torques held from this sample to the next.
        :return: values (name -> (N,) array) and health (N,) ints.
        """
        del a_x
        y, u = (np.asarray(a, dtype=float).reshape(self.n) for a in (omega, T_b))
        active = np.isfinite(y) & np.isfinite(u)  # a NaN sample is skipped: nothing changes (INVALID_INPUT)
        y, u = np.where(active, y, 0.0), np.where(active, u, 0.0)
        verdict = self._take(active, y, u)
        health = self._window_estimate(active)
        self._ekf_predict(active, u)
        self.torque_prev[active] = u[active]
        health = np.select([~active, verdict == Verdict.REJECT, verdict == Verdict.REINIT],
                           [int(Health.INVALID_INPUT), int(Health.OUTLIER), int(Health.REINITIALISED)], health)
        return self.values(), health

    # ------------------------------------------------------------------ the alongside EKF and the buffers
    def _h_and_jacobian(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eq. (7) and its Jacobian, (N,) and (N, 1, nx)."""
        r = self.t.model.p.r
        H = np.zeros((self.n, 1, self.nx))
        H[:, 0, 0], H[:, 0, 1] = (1.0 - x[:, 1]) / r, -x[:, 0] / r
        return x[:, 0] * (1.0 - x[:, 1]) / r, H

    def _gate(self, active: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The wheel-speed gate of the single MHE's arrival filter (:class:`estimators.mismatch.WheelSpeedGuard`,
        one per sub-env, the same code) on the EKF's prior; re-initialises or raises (x, P) in place; verdicts (N,)."""
        verdicts = np.full(self.n, int(Verdict.ACCEPT))
        if self.t.outlier_gate is None:
            return verdicts
        P0, R, Q = self.t._P0, self.t._R, self.t._Q
        for i in np.flatnonzero(active):
            verdict, x, P, _ = self.guards[i].check(self.ekf_x[i], self.ekf_P[i], P0, R, Q, y[i:i + 1],
                                                    float(self.torque_prev[i]))
            self.ekf_x[i], self.ekf_P[i], verdicts[i] = x, P, int(verdict)
        return verdicts

    def _take(self, active: np.ndarray, y: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Gate, restart the windows of re-initialised sub-envs, append the sample, the EKF's update."""
        verdict = self._gate(active, y)
        reinit = (verdict == Verdict.REINIT) | (verdict == Verdict.START)  # the window restarts
        self.count[reinit], self.has_prev[reinit] = 0, False
        full = active & (self.count == self.N1)  # the window slides: drop the oldest sample
        for buf in (self.y, self.u, self.used, self.hist_x, self.hist_P, self.torque_variance):
            buf[full] = np.roll(buf[full], -1, axis=1)
        rows = np.flatnonzero(active)
        pos = np.minimum(self.count[rows], self.N1 - 1)
        self.y[rows, pos], self.u[rows, pos] = y[rows], u[rows]
        self.used[rows, pos] = verdict[rows] != Verdict.REJECT  # a rejected sample stays with no weight
        self.hist_x[rows, pos], self.hist_P[rows, pos] = self.ekf_x[rows], self.ekf_P[rows]
        self.count[rows] = pos + 1
        # the EKF's measurement update (estimators.ekf.ekf_update, Joseph form), skipped for a rejected sample
        x, P, R = self.ekf_x, self.ekf_P, self.t._R
        hx, H = self._h_and_jacobian(x)
        PHt = P @ np.swapaxes(H, 1, 2)
        S = sym(H @ PHt + R)
        K = PHt / S
        IKH = np.eye(self.nx) - K @ H
        P_post = sym(IKH @ P @ np.swapaxes(IKH, 1, 2) + K @ R @ np.swapaxes(K, 1, 2))
        x_post = x + (K @ (y - hx)[:, None, None])[:, :, 0]
        for i in np.flatnonzero(active & (verdict != Verdict.REJECT)):  # (M2), (M5)
            x_post[i] = self.guards[i].bound_posterior(x_post[i], float(x[i, 0]), float(y[i]))
        upd = active & (verdict != Verdict.REJECT)
        self.post_x = np.where(upd[:, None], x_post, np.where(active[:, None], x, self.post_x))
        self.post_P = np.where(upd[:, None, None], P_post, np.where(active[:, None, None], P, self.post_P))
        return verdict

    def _ekf_predict(self, active: np.ndarray, u: np.ndarray) -> None:
        """The EKF's time update from x(t|t) to the prior of x(t+1); P0 again where the model gives non-finite."""
        lo, hi = self.t.lower, self.t.upper
        x_post = np.clip(self.post_x, lo, hi)
        xn, F = self._predict(x_post, u)
        xn = xn[:, :, 0]
        self.commands[active] = np.concatenate([self.commands[active, 1:], u[active, None]], axis=1)
        Q = self.t._Q
        e = self.t.arrival_filter.torque_error
        if e is not None:  # as the single EKF's time update
            given = np.where(np.isnan(self.commands), u[:, None], self.commands)  # none yet: the one held
            noise = torque_step_noise(F[:, :, e], torque_jump_std(given, self.torque_prev, self.t.model.torque_fade))
            Q = Q + noise
            rows = np.flatnonzero(active)  # the window's model errors of this sample take it too
            self.torque_variance[rows, self.count[rows] - 1] = np.diagonal(noise, axis1=1, axis2=2)[rows, :2]
        dv = self.t.arrival_filter.dv_max  # the single EKF's bound on a predicted speed change
        xn[:, 0] = np.clip(xn[:, 0], x_post[:, 0] - dv, x_post[:, 0] + dv)
        good = np.all(np.isfinite(xn), axis=1) & np.all(np.isfinite(F), axis=(1, 2))
        P_next = sym(F @ self.post_P @ np.swapaxes(F, 1, 2) + Q)
        self.ekf_x = np.where((active & good)[:, None], np.clip(xn, lo, hi), self.ekf_x)
        self.ekf_P = np.where(active[:, None, None], np.where(good[:, None, None], P_next, self.t._P0), self.ekf_P)

    # ------------------------------------------------------------------ the window
    def _window_estimate(self, active: np.ndarray) -> np.ndarray:
        """Warm-up, window solve (eq. (12)), fallback and the EKF-consistency gate; the health (N,)."""
        t, nx = self.t, self.nx
        health = np.full(self.n, int(Health.NOT_EXCITED))
        warm = active & (self.count < self.N1)
        self.last[warm] = np.clip(self.post_x[warm], t.lower, t.upper)  # warming up: the alongside EKF's
        live = active & ~warm
        if not live.any():
            return health
        rows = np.flatnonzero(live)
        warm = np.where(self.has_prev[rows, None], self.w_prev[rows], np.nan)
        w_scale = None
        if t.arrival_filter.torque_error is not None and self.solver.nz > nx:  # as the single MHE's window
            w_scale = np.sqrt(t._w_scale_free**2 + self.torque_variance[rows, :t.N].reshape(len(rows), -1))
        sol = self.solver.solve(self.hist_x[rows, 0], self.hist_P[rows, 0], self.y[rows], self.u[rows, :t.N],
                                self.used[rows], warm, w_scale)
        good = ~sol.failed
        ok = np.zeros(self.n, dtype=bool)
        ok[rows[good]] = True
        self.has_prev[ok] = True
        self.w_prev[ok] = sol.z[good, nx:]
        self.last[ok] = sol.X[good, -1]
        health[ok] = np.where(sol.rank[good] >= t.excited_rank, int(Health.OK), int(Health.NOT_EXCITED))
        if t.gate and ok.any():  # the EKF-consistency gate, on the solved windows only (as the single MHE)
            k = np.flatnonzero(ok)
            d = self.last[k] - self.post_x[k]
            Pj = self.post_P[k] + PD_JITTER * np.eye(nx)
            d2 = (d[:, None, :] @ np.linalg.solve(Pj, d[:, :, None]))[:, 0, 0]
            gated = k[d2 > t.gate]
            self.last[gated] = np.clip(self.post_x[gated], t.lower, t.upper)
            self.has_prev[gated] = False
        for i in rows[sol.failed]:
            self._fallback(i)
            health[i] = int(Health.SOLVER_FAILED)
        return health

    def _fallback(self, i: int) -> None:
        """A failed solve of sub-env i: the a priori trajectory of eq. (11) if usable, else hold the last value."""
        try:
            Xb = np.asarray(self.t._fun_prior(self.hist_x[i, 0], self.u[i, :self.t.N]))
            usable = bool(np.all(np.isfinite(Xb)))
        except Exception:  # noqa: BLE001 - as the single MHE: the fallback never raises
            usable = False
        if usable:
            self.has_prev[i] = False
            self.last[i] = Xb[:, -1]


def mhe_builder(name: str) -> Callable[[int, float, Any, dict], BatchedMHE]:
    """A :data:`estimators.batched.BATCHED` builder ``(n, dt, p, options) -> BatchedMHE`` for the registry entry
    ``name``: the template is ``get_estimator(name).make(p, dt, **options)``, as a single env builds its MHE.
    ``options["shape"]`` (the friction-map shape :func:`estimators.batched.make_batched` adds from the entry's
    ``assumed_shape`` for the EKF/RLS) is dropped: the registry builds the MHE's model from that same shape."""

    def build(n: int, dt: float, p: Any, options: dict) -> BatchedMHE:
        from estimators.registry import get_estimator

        own = {k: v for k, v in options.items() if k != "shape"}
        return BatchedMHE(get_estimator(name).make(p, dt, **own), n)

    return build


BATCHED_MHE: Mapping[str, Callable[[int, float, Any, dict], BatchedMHE]] = MappingProxyType({
    "mhe": mhe_builder("mhe"),
    "mhe-full": mhe_builder("mhe-full"),
})
