"""The batched MHE's window solve: N projected Levenberg-Marquardt solves of eq. (12) in lockstep.

:class:`BatchedWindowSolver` is :meth:`estimators.mhe.RegularizedMHE._solve` (EKF arrival cost, scaled weighting)
over a leading batch axis: the window weights of eqs. (14)-(16) in the arrival covariance's units, the arrival
cost ``||L^-1 (x(t-N) - xbar)||^2`` (P = L L^T), the process-noise terms and the projected Levenberg-Marquardt
iterations with the bounds (12c), one trial point per live instance per pass, one mapped CasADi call per pass
(see :mod:`estimators.mhe_batched`). The constants (tolerances, damping, bounds) are the single MHE's.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estimators.mhe import (
    BOUND_TOL,
    LM_DAMPING0,
    LM_DAMPING_MAX,
    MAX_EVALS,
    PD_JITTER,
    TOL_STEP,
    RegularizedMHE,
)

__all__ = ["BatchedWindowSolver", "WindowSolution", "rowwise", "sym"]


@dataclass
class WindowSolution:
    """The solves of one batched update (rows that were not live carry placeholders).

    :param z: decision vectors (x(t-N), model errors), (N, nz).
    :param X: window trajectories, row i = x(t-N+i), (N, N+1, nx).
    :param rank: singular values kept by the SVD thresholding, (N,).
    :param failed: the solve failed (single MHE: an exception or a non-finite cost or solution), (N,).
    """

    z: np.ndarray
    X: np.ndarray
    rank: np.ndarray
    failed: np.ndarray


def rowwise(fn: Callable[..., np.ndarray], failed: np.ndarray, *arrays: np.ndarray) -> np.ndarray:
    """``fn`` over a batch; if it raises a LinAlgError, row by row, marking the rows that raise in ``failed``
    (their results NaN), so that one bad instance fails alone as a single MHE would."""
    try:
        return fn(*arrays)
    except np.linalg.LinAlgError:
        pass
    out = None
    for i in range(len(arrays[0])):
        try:
            value = fn(*(a[i:i + 1] for a in arrays))[0]
        except np.linalg.LinAlgError:
            failed[i] = True
            continue
        if out is None:
            out = np.full((len(arrays[0]),) + value.shape, np.nan)
        out[i] = value
    if out is None:
        raise np.linalg.LinAlgError("every instance failed")
    return out


class BatchedWindowSolver:
    """Lockstep solves of eq. (12) for up to N windows; only the windows being solved are evaluated.

    :param template: the single MHE whose constants are used (EKF arrival cost, scaled weighting).
    :param window: ``k -> evaluator`` of its window function (dense outputs) over k instances
        (:class:`~estimators.casadi_compiled.BatchCall`): (z, U) -> (outputs, Jacobian, f(x0)); built per k on
        first use and kept.
    """

    def __init__(self, template: RegularizedMHE, window: Callable[[int], Callable[..., list[np.ndarray]]]):
        self.t, self._make_window, self._windows = template, window, {}
        self.nx, self.N1, self.nz = template.model.nx, template.N + 1, template._nz
        self.zlo, self.zhi = template._zlo, template._zhi
        self.span = np.minimum(self.zhi - self.zlo, 1.0)
        self.w_scale = template._w_scale_free  # the model errors' scales, (nz - nx,); solve() may give them per window
        self._eye_w = np.eye(self.nz - self.nx)

    # ------------------------------------------------------------------ pieces
    def evaluate(self, z: np.ndarray, U: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Window outputs H (k, N+1), Jacobian dH/dz (k, N+1, nz), trajectory X (k, N+1, nx): one mapped call."""
        k = len(z)
        if k not in self._windows:
            self._windows[k] = self._make_window(k)
        out, J, _ = self._windows[k](z, U)
        out = out[:, :, 0]
        return out[:, :self.N1], J, out[:, self.N1:].reshape(k, self.N1, self.nx)

    def weights(self, Phi: np.ndarray, used: np.ndarray, L: np.ndarray, failed: np.ndarray):
        """W_t of the scaled reading (estimators.mhe: ``_weights``, ``_masked_weights``) with zero weight on the
        samples the gate rejected; returns (W (k, N+1, N+1), rank kept (k,)).

        The windows are grouped by their pattern of kept samples and of thresholded singular values, so that each
        group runs the single MHE's own operations (the same LAPACK/BLAS calls on the same operands): a window
        that carries no information (a stopped car: every singular value near 0) has an arbitrary SVD basis, and
        any other rounding would change its weights."""
        t, N1 = self.t, self.N1
        W = np.zeros((len(Phi), N1, N1))
        rank = np.zeros(len(Phi), dtype=int)
        for pattern, rows in groups(used):
            Phi_s = Phi[rows][:, pattern] @ L[rows] / t.noise_std
            bad = np.zeros(len(rows), dtype=bool)
            # one SVD per window, eq. (14): U and the singular values packed in one array for rowwise
            Us = rowwise(_svd_packed, bad, Phi_s)
            failed[rows[bad]] = True
            Uu, sv = Us[:, :-1], Us[:, -1]
            keep = sv >= t.delta
            rank[rows] = keep.sum(axis=1)
            k = int(pattern.sum())
            for kept, sub in groups(keep):
                Ud = Uu[sub][:, :, ~kept]
                Wg = (np.eye(k) - Ud @ np.swapaxes(Ud, 1, 2)) / t.noise_std
                W[np.ix_(rows[sub], pattern, pattern)] = Wg
        return W, rank

    def residual(self, z, e, PhiZ, W, Wa, xb0, w_scale) -> tuple[np.ndarray, np.ndarray]:
        """Weighted residual (k, nr) and Jacobian (k, nr, nz) of (12a) with the arrival and process-noise terms
        (``w_scale`` (k, nz - nx): the model errors' scales)."""
        nx, k = self.nx, len(z)
        r = [(W @ e[:, :, None])[:, :, 0], (Wa @ (z[:, :nx] - xb0)[:, :, None])[:, :, 0], z[:, nx:] / w_scale]
        Ja = np.zeros((k, nx, self.nz))
        Ja[:, :, :nx] = Wa
        Jw = np.zeros((k, self.nz - nx, self.nz))  # of the process-noise terms z[nx:] / w_scale
        Jw[:, :, nx:] = (1.0 / w_scale)[:, :, None] * self._eye_w
        J = [-W @ PhiZ, Ja, Jw]
        return np.concatenate(r, axis=1), np.concatenate(J, axis=1)

    # ------------------------------------------------------------------ solve
    def solve(self, xb0: np.ndarray, P: np.ndarray, Y: np.ndarray, U: np.ndarray, used: np.ndarray,
              w_warm: np.ndarray, w_scale: np.ndarray | None = None) -> WindowSolution:
        """Solve k windows from their a priori starts.

        :param xb0: a priori x(t-N) (the EKF's prior), (k, nx).
        :param P: its covariance, (k, nx, nx).
        :param Y: window wheel speeds, (k, N+1).
        :param U: window torques, (k, N).
        :param used: samples the outlier gate kept, (k, N+1).
        :param w_warm: the previous solve's model errors (NaN rows: none), (k, nz - nx).
        :param w_scale: the model errors' scales, (k, nz - nx); None: the template's.
        """
        nx, k = self.nx, len(xb0)
        w_scale = np.broadcast_to(self.w_scale, (k, self.nz - nx)) if w_scale is None else w_scale
        failed = np.zeros(k, dtype=bool)
        z = np.zeros((k, self.nz))
        z[:, :nx] = xb0
        if self.nz > nx:
            warm = np.concatenate([w_warm[:, 2:], np.zeros((k, 2))], axis=1)
            z[:, nx:] = np.where(np.isfinite(w_warm[:, :1]), warm, 0.0)
        H, PhiZ, X = self.evaluate(z, U)
        eye = np.eye(nx)
        L = rowwise(np.linalg.cholesky, failed, sym(P) + PD_JITTER * eye)
        L = np.where(failed[:, None, None], eye, L)
        W, rank = self.weights(PhiZ[:, :, :nx], used, L, failed)
        Wa = rowwise(lambda A: np.linalg.solve(A, np.broadcast_to(eye, A.shape)), failed, L)
        W, Wa = np.where(failed[:, None, None], 0.0, W), np.where(failed[:, None, None], 0.0, Wa)
        r, J = self.residual(z, Y - H, PhiZ, W, Wa, xb0, w_scale)
        cost = _dot(r, r)
        failed |= ~np.isfinite(cost)
        z, X = self._iterate(failed, z, X, r, J, cost, (U, Y, W, Wa, xb0, w_scale))
        failed |= ~(np.all(np.isfinite(z), axis=1) & np.all(np.isfinite(X), axis=(1, 2)))
        return WindowSolution(z, X, rank, failed)

    def _steps(self, a, free, JtJ, diag, lam, g, failed) -> np.ndarray:
        """Levenberg-Marquardt steps of rows ``a`` on their free variables, grouped by free set so that each
        group solves the single MHE's own system; a singular system fails its row. Arguments are rows ``a``'s."""
        step = np.zeros((len(a), self.nz))
        for pattern, rows in groups(free):
            # a C-ordered copy (so that the reshape below is a view): its diagonal gets + lam diag(J^T J)
            A = np.ascontiguousarray(JtJ[rows][:, pattern][:, :, pattern])
            m = A.shape[-1]
            A.reshape(len(rows), m * m)[:, ::m + 1] += lam[rows, None] * diag[rows][:, pattern]
            bad = np.zeros(len(rows), dtype=bool)
            sol = rowwise(lambda M, b: np.linalg.solve(M, b[:, :, None])[:, :, 0], bad, A, -g[rows][:, pattern])
            failed[a[rows[bad]]] = True
            step[np.ix_(rows, pattern)] = np.where(bad[:, None], 0.0, sol)
        return step

    def _iterate(self, failed, z, X, r, J, cost, data):
        """Projected Levenberg-Marquardt in lockstep (estimators.mhe: ``_solve``) on the rows still iterating;
        the solutions (z, X)."""
        U, Y, W, Wa, xb0, w_scale = data
        k = len(z)
        lam = np.full(k, LM_DAMPING0)
        n_eval = np.ones(k, dtype=int)
        iters = np.zeros(k, dtype=int)
        alive = ~failed & (lam <= LM_DAMPING_MAX) & (n_eval < MAX_EVALS)
        while alive.any():
            a = np.flatnonzero(alive)
            Ja = J[a]
            Jt = np.swapaxes(Ja, 1, 2)
            g = (Jt @ r[a][:, :, None])[:, :, 0]
            JtJ = Jt @ Ja  # one buffer transposed: numpy's matmul takes the symmetric (syrk) path, as J.T @ J
            diag = np.diagonal(JtJ, axis1=1, axis2=2) + 1e-12
            # active bounds (12c): variables at a bound whose descent direction points out are held there
            za = z[a]
            free = ~(((za <= self.zlo + BOUND_TOL * self.span) & (g > 0))
                     | ((za >= self.zhi - BOUND_TOL * self.span) & (g < 0)))
            step = self._steps(a, free, JtJ, diag, lam[a], g, failed)
            keep = ~failed[a]
            a, za, step = a[keep], za[keep], step[keep]
            alive[failed] = False
            if not len(a):
                break
            z_new = np.clip(za + step, self.zlo, self.zhi)  # bounds (12c) by projection
            H_new, PhiZ_new, X_new = self.evaluate(z_new, U[a])
            n_eval[a] += 1
            r_new, J_new = self.residual(z_new, Y[a] - H_new, PhiZ_new, W[a], Wa[a], xb0[a], w_scale[a])
            cost_new = _dot(r_new, r_new)
            with np.errstate(invalid="ignore"):
                ok = np.isfinite(cost_new) & (cost_new <= cost[a])
            lam[a] = np.where(ok, np.maximum(lam[a] / 10.0, LM_DAMPING0), lam[a] * 10.0)
            rel = (cost[a] - cost_new) / np.maximum(cost[a], 1e-300)
            acc = a[ok]
            z[acc], X[acc], r[acc], J[acc], cost[acc] = z_new[ok], X_new[ok], r_new[ok], J_new[ok], cost_new[ok]
            iters[acc] += 1
            alive[acc[(rel[ok] < TOL_STEP) | (iters[acc] >= self.t.max_iter)]] = False
            alive &= (lam <= LM_DAMPING_MAX) & (n_eval < MAX_EVALS)
        return z, X


def sym(P: np.ndarray) -> np.ndarray:
    """Symmetric part of a batch of square matrices (N, n, n)."""
    return 0.5 * (P + np.swapaxes(P, -1, -2))


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot products of (N, m) arrays through matmul (rounds as the single ``a @ b``; einsum does not)."""
    return (a[:, None, :] @ b[:, :, None])[:, 0, 0]


def groups(patterns: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Rows of a boolean matrix (N, m) grouped by pattern: [(pattern (m,), row indices), ...]."""
    if len(patterns) == 0:
        return []
    if patterns.all():  # the usual case (every sample kept, every variable free): one group, no key arithmetic
        return [(patterns[0], np.arange(len(patterns)))]
    keys = patterns.astype(np.int64) @ (np.int64(1) << np.arange(patterns.shape[1], dtype=np.int64))
    if np.all(keys == keys[0]):  # the usual case: one group
        return [(patterns[0], np.arange(len(patterns)))]
    unique, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    return [(patterns[first[j]], np.flatnonzero(inverse == j)) for j in range(len(unique))]


def _svd_packed(A: np.ndarray) -> np.ndarray:
    """Thin SVD of a batch (N, m, k): U (N, m, k) with the singular values appended as row m, (N, m + 1, k)."""
    Uu, s, _ = np.linalg.svd(A, full_matrices=False)
    return np.concatenate([Uu, s[:, None, :]], axis=1)
