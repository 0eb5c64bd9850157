"""Vehicle speed reconstructed from the wheel speed, for logs without ``v``.

The speed follows the model's vehicle equation ``m v' = -F_z mu(lambda) - F_d(v)``, with the slip ``lambda`` taken
from ``v`` and the *measured* wheel speed (for a relaxation model, the transient slip filtered from it). Each sample
is one linearly implicit step, a map ``x_{k+1} = Phi_k(x_k)`` of the state ``x = (v, transient slip)``: the force at
the step's start, with the slip from the step's mean wheel speed (:func:`step_wheel_speed`), over
``1 - IMPLICIT dt df/dv`` (the linearly implicit trapezoidal rule for ``IMPLICIT = 1/2``, second order in the step).
A first-order step (the force at the step's first wheel-speed sample, ``IMPLICIT = 1``) lags the braking onset by
about a sample: from an independent simulator's noise-free wheel speed (``tests/independent_model.py``, 100 Hz) its
speed ran 28-43 mm/s (at most 66) above the truth on wet-road logs, which moved the windows' predicted wheel speed
by 0.2-0.8 noise std; this step stays within 17 mm/s (0.4-6.5 mm/s on average).

The diagnosis evaluates this recursion for every parameter set it tries, and one Python iteration per sample is the
most expensive part of a no-``v`` diagnosis. So the recursion is solved for all samples at once by Newton's method
on the whole trajectory: the residuals ``Phi_k(x_k) - x_{k+1}`` and the step Jacobians are evaluated for all ``k`` in
one vectorised call, and the Newton correction ``d_{k+1} = J_k d_k + r_k`` is an affine recursion, solved by a
parallel prefix scan in ``log2(n)`` vectorised rounds. The iteration stops when every residual is below a
round-off tolerance; whatever stretch has not converged by then (a kink of the slip at standstill) is finished by
the plain sequential recursion, which :func:`reconstruct_speed_sequential` also provides as the reference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fricenv.effects import registry
from fricenv.effects.quarter_car import ModelBatch
from fricenv.gap.signals.speed_step import IMPLICIT, slip_lag_decay, speed_update
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import magic_formula_and_dslip, slip_and_partials

__all__ = ["affine_scan", "filtered_transient_slip", "reconstruct_speed", "reconstruct_speed_sequential",
           "slip_lag_decay", "speed_update"]

NEWTON_ITERS = 20  # Newton iterations on the trajectory before the sequential finish
NEWTON_TOL = 1e-11  # largest accepted step residual [m/s] (transient slip: the same number, unitless)
FD_STEP = 1e-7  # finite-difference step of the step Jacobians [m/s], [-]


def step_wheel_speed(omega: np.ndarray) -> np.ndarray:
    """The wheel speed over each sample step, the mean of its two samples (the last step keeps its sample)."""
    w = np.asarray(omega, dtype=float)
    return np.r_[0.5 * (w[:-1] + w[1:]), w[-1:]] if w.size > 1 else w.copy()


@dataclass(frozen=True)
class _SpeedModel:
    """Per-element constants of the speed recursion, shaped to broadcast over (K, samples)."""

    r: np.ndarray  # rolling radius (K, 1) [m]
    c0: np.ndarray  # drag constant (K, 1) [N]
    c2: np.ndarray  # drag quadratic coefficient (K, 1) [N s^2/m^2]
    shape: tuple  # Magic Formula B, C, E, each (K, 1)
    theta: np.ndarray  # road condition coefficient per sample (K, n): a friction change switches it
    relax: np.ndarray  # element has tire relaxation (K, 1)
    dt_over_sigma: np.ndarray  # (K, 1) [s/m]
    omega: np.ndarray  # wheel speed over each step, the mean of its two measured samples (n,) [rad/s]
    dt: float  # sample period [s]
    p: qc.QuarterCarParams

    @classmethod
    def of(cls, batch: ModelBatch, omega: np.ndarray, t0: float, dt: float, p: qc.QuarterCarParams) -> _SpeedModel:
        col = lambda a: np.asarray(a, dtype=float)[:, None]
        t = t0 + dt * np.arange(len(omega))
        theta = np.where(t[None, :] >= col(batch.t_change), col(batch.theta_after), col(batch.road[:, 3]))
        for entry in registry.REGISTRY.values():  # plug-in effects on the road's peak factor
            if not entry.builtin and entry.theta is not None and entry.param_names[0] in batch.extra:
                theta = entry.theta({q: col(batch.extra[q]) for q in entry.param_names}, theta, t[None, :])
        relax = col(batch.sigma) > 0
        return cls(r=col(batch.r_eff), c0=col(batch.c0), c2=col(batch.c2),
                   shape=tuple(col(batch.road[:, i]) for i in range(3)), theta=theta, relax=relax,
                   dt_over_sigma=dt / np.where(relax, col(batch.sigma), 1.0), omega=step_wheel_speed(omega),
                   dt=dt, p=p)

    @property
    def has_relax(self) -> bool:
        return bool(self.relax.any())

    def step(self, v: np.ndarray, lt: np.ndarray, k) -> tuple[np.ndarray, np.ndarray]:
        """``Phi_k``: speed and transient slip ``(v_k, lt_{k-1})`` -> ``(v_{k+1}, lt_k)`` at samples ``k``.

        :param v: speed (K, m) [m/s].
        :param lt: transient slip of the previous sample (K, m) [-].
        :param k: sample indices (m,) or a slice.
        """
        p, dt = self.p, self.dt
        lam, dlam_dv, _ = slip_and_partials(v, self.omega[k], self.r)
        if self.has_relax:
            lt = np.where(self.relax, lam + (lt - lam) * slip_lag_decay(v, self.dt_over_sigma), lam)
            mu, dmu = magic_formula_and_dslip(lt, *self.shape, self.theta[:, k])
            dmu_dv = np.where(self.relax, 0.0, dmu * dlam_dv)  # the filtered slip lags: no implicit feedback
        else:
            lt = lam
            mu, dmu = magic_formula_and_dslip(lam, *self.shape, self.theta[:, k])
            dmu_dv = dmu * dlam_dv
        return speed_update(v, mu, dmu_dv, self.c0, self.c2, p.Fz, p.m, dt, IMPLICIT), lt


def _initial_speed(batch: ModelBatch, omega: np.ndarray, free_end: int) -> np.ndarray:
    """``v(0) = r_eff * mean(omega)`` over the free-rolling start (3 to 20 samples)."""
    m0 = max(min(free_end, 20), 3)
    return np.asarray(batch.r_eff, dtype=float) * float(np.mean(omega[:m0]))


def _sequential(model: _SpeedModel, out: np.ndarray, lt: np.ndarray, k_from: int) -> np.ndarray:
    """Finish ``out`` (K, n) from sample ``k_from`` on (its column ``k_from`` and ``lt`` of ``k_from - 1`` given)."""
    v = out[:, k_from:k_from + 1].copy()
    lt = lt[:, None].copy()
    for k in range(k_from, out.shape[1] - 1):
        v, lt = model.step(v, lt, slice(k, k + 1))
        out[:, k + 1] = v[:, 0]
    return out


def reconstruct_speed_sequential(batch: ModelBatch, omega: np.ndarray, t0: float, dt: float, free_end: int,
                                 p: qc.QuarterCarParams) -> np.ndarray:
    """Speed (K, n): the recursion one sample at a time (the reference of :func:`reconstruct_speed`)."""
    model = _SpeedModel.of(batch, omega, t0, dt, p)
    out = np.empty((len(batch), len(omega)))
    out[:, 0] = _initial_speed(batch, omega, free_end)
    return _sequential(model, out, np.zeros(len(batch)), 0)


def affine_scan(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """All prefixes of the affine recursion ``d_{k+1} = A_k d_k + b_k`` from ``d_0 = 0``, along axis 1.

    :param A: (K, N, q, q) step matrices.
    :param b: (K, N, q) step offsets.
    :return: (K, N, q) with row ``k`` holding ``d_{k+1}``.

    Hillis-Steele scan: after the round with shift ``s`` each element holds the composition of up to ``2 s``
    consecutive maps, so ``ceil(log2 N)`` vectorised rounds compose every prefix. The q x q products are written out
    element by element: for q <= 2 that is several times faster than a batched matmul.
    """
    q = b.shape[-1]
    a = [[A[..., i, j].copy() for j in range(q)] for i in range(q)]
    c = [b[..., i].copy() for i in range(q)]
    s = 1
    while s < b.shape[1]:
        c_new = [a[i][0][:, s:] * c[0][:, :-s] + c[i][:, s:] for i in range(q)]
        for i in range(q):
            for j in range(1, q):
                c_new[i] += a[i][j][:, s:] * c[j][:, :-s]
        a_new = [[sum(a[i][m][:, s:] * a[m][j][:, :-s] for m in range(q)) for j in range(q)] for i in range(q)]
        for i in range(q):
            c[i][:, s:] = c_new[i]
            for j in range(q):
                a[i][j][:, s:] = a_new[i][j]
        s *= 2
    return np.stack(c, axis=-1)


def filtered_transient_slip(lam: np.ndarray, v: np.ndarray, dt_over_sigma: np.ndarray) -> np.ndarray:
    """Transient slip (K, n) filtered from the slip ``lam`` (K, n) at the speeds ``v`` (K, n), starting at the first
    slip: ``lt_{k+1} = lam_k + (lt_k - lam_k) a_k`` with ``a_k`` = :func:`slip_lag_decay` (``dt_over_sigma``: (K, 1)).

    The recursion is affine in ``lt``, so it is composed for all samples at once by :func:`affine_scan`.
    """
    a = slip_lag_decay(v[:, :-1], dt_over_sigma)
    b = (1.0 - a) * lam[:, :-1]
    b[:, 0] += a[:, 0] * lam[:, 0]  # the start lt_0 = lam_0 enters through the first map (the scan starts at 0)
    rest = affine_scan(a[..., None, None], b[..., None])[..., 0]
    return np.concatenate([lam[:, :1], rest], axis=1)


def _envelope_guess(model: _SpeedModel) -> np.ndarray:
    """First guess (K, n) of the speed: the latest-to-earliest running maximum of ``r omega``.

    A braked wheel turns no faster than it rolls, and the vehicle only slows down, so ``v(t) >= max_{s >= t} r
    omega(s)``; the wheel spins back up near the vehicle speed between brake applications, so the bound is close.
    From this guess Newton converges in about five iterations; from a constant speed it needs about twenty.
    """
    return np.maximum.accumulate((model.r * model.omega[None, :])[:, ::-1], axis=1)[:, ::-1]


def _newton(model: _SpeedModel, X: np.ndarray) -> tuple[np.ndarray, int]:
    """Newton on the trajectory ``X`` (K, n, 2) of ``(v_k, lt_{k-1})``, its first row fixed.

    Returns the trajectory and the first sample whose step has not converged (``n - 1``: all converged).
    """
    K, n, _ = X.shape
    q = 2 if model.has_relax else 1  # without relaxation the transient slip is not a state
    ks = slice(0, n - 1)
    for _ in range(NEWTON_ITERS):
        Y = np.stack(model.step(X[:, :-1, 0], X[:, :-1, 1], ks), axis=-1)
        R = Y - X[:, 1:]
        R[..., q:] = 0.0
        if _first_unconverged(R[..., :q]) == n - 1:
            return X, n - 1
        J = np.empty((K, n - 1, q, q))
        for i in range(q):
            Xh = X[:, :-1].copy()
            Xh[..., i] += FD_STEP
            J[..., i] = (np.stack(model.step(Xh[..., 0], Xh[..., 1], ks), axis=-1)[..., :q] - Y[..., :q]) / FD_STEP
        X[:, 1:, :q] += affine_scan(J, R[..., :q])
        if not np.isfinite(X).all():  # a diverged stretch: leave it to the sequential finish
            break
    Y = np.stack(model.step(X[:, :-1, 0], X[:, :-1, 1], ks), axis=-1)
    return X, _first_unconverged((Y - X[:, 1:])[..., :q])


def _first_unconverged(R: np.ndarray) -> int:
    """First step whose residual (K, n - 1, q) is above the tolerance or not finite; ``n - 1`` if none is."""
    bad = ~(np.abs(R) <= NEWTON_TOL).all(axis=(0, 2))
    return int(np.argmax(bad)) if bad.any() else R.shape[1]


def reconstruct_speed(batch: ModelBatch, omega: np.ndarray, t0: float, dt: float, free_end: int,
                      p: qc.QuarterCarParams, compiled: bool = False) -> np.ndarray:
    """Speed (K, n) of every element of ``batch`` from the measured wheel speed ``omega`` (n,).

    :param batch: model parameters (road, rolling radius, drag, relaxation length, friction change).
    :param omega: measured wheel speed [rad/s].
    :param t0: time of the first sample [s].
    :param dt: sample period [s].
    :param free_end: first sample after the free-rolling start (the initial speed is taken before it).
    :param p: vehicle parameters.
    :param compiled: run the recursion sample by sample in compiled code (:mod:`fricenv.gap.signals.speed_kernel`) instead
        of the numpy Newton solve; the two agree to the Newton tolerance.
    """
    model = _SpeedModel.of(batch, omega, t0, dt, p)
    K, n = len(batch), len(omega)
    v0 = _initial_speed(batch, omega, free_end)
    if compiled:
        from fricenv.gap.signals.speed_kernel import sequential_speed  # numba only when asked for

        return sequential_speed(model, v0)
    X = np.empty((K, n, 2))
    X[:, :, 0] = _envelope_guess(model)
    X[:, 0, 0] = v0
    X[:, :, 1] = slip_and_partials(X[:, :, 0], model.omega, model.r)[0]
    X[:, 0, 1] = 0.0  # the transient slip starts from rest
    X, k_bad = _newton(model, X)
    out = np.ascontiguousarray(X[:, :, 0])
    if k_bad < n - 1:
        out = _sequential(model, out, X[:, k_bad, 1], k_bad)
    return out
