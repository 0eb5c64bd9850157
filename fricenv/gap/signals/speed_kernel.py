"""The speed recursion of :mod:`fricenv.gap.signals.speed` compiled with numba: :func:`_SpeedModel.step` one sample at a time
for every element, from the library's own slip and Magic Formula functions (compiled by
:func:`fricenv.effects.kernels._compile`, so the formulas are not written twice).

Compiled, the plain sequential recursion costs a few tens of nanoseconds per sample and element, far less than the
numpy Newton solve of the whole trajectory (:func:`fricenv.gap.signals.speed.reconstruct_speed`, kept as the numpy path).
Imported only when a compiled diagnosis runs, so ``import fricenv`` does not load numba.
"""

from __future__ import annotations

import numba
import numpy as np

from fricenv.effects.kernels import _compile, _guard_cache
from fricenv.gap.signals import speed_step
from fricenv.plants.tire import SLIP_SPEED_FLOOR, magic_formula_and_dslip, slip_and_partials

__all__ = ["sequential_speed"]

_slip_partials = _compile(slip_and_partials)
_mu_dslip = _compile(magic_formula_and_dslip)
_lag_decay = _compile(speed_step.slip_lag_decay)
_speed_update = _compile(speed_step.speed_update)


@numba.njit(cache=True, error_model="numpy")
def _recursion(omega, r, c0, c2, B, C, E, theta, relax, dt_over_sigma, Fz, m, dt, implicit, out):
    """``out[:, k + 1] = Phi_k(out[:, k])`` (:meth:`fricenv.gap.signals.speed._SpeedModel.step`) from ``out[:, 0]``, the
    transient slip starting from rest; per-element arrays (K,), ``theta`` (K, n)."""
    K, n = out.shape
    for i in range(K):
        v = out[i, 0]
        lt = 0.0
        for k in range(n - 1):
            lam, dlam_dv, _ = _slip_partials(v, omega[k], r[i], SLIP_SPEED_FLOOR)
            if relax[i]:
                lt = lam + (lt - lam) * _lag_decay(v, dt_over_sigma[i])
                mu, dmu = _mu_dslip(lt, B[i], C[i], E[i], theta[i, k])
                dmu_dv = 0.0  # the filtered slip lags: no implicit feedback
            else:
                lt = lam
                mu, dmu = _mu_dslip(lam, B[i], C[i], E[i], theta[i, k])
                dmu_dv = dmu * dlam_dv
            v = _speed_update(v, mu, dmu_dv, c0[i], c2[i], Fz, m, dt, implicit)
            out[i, k + 1] = v
    return out


def sequential_speed(model, v0: np.ndarray) -> np.ndarray:
    """Speed (K, n) of the recursion of ``model`` (a :class:`fricenv.gap.signals.speed._SpeedModel`) from ``v0`` (K,).

    :param model: the per-element constants of the recursion.
    :param v0: initial speeds [m/s].
    """
    K, n = len(v0), len(model.omega)
    out = np.empty((K, n))
    out[:, 0] = v0
    col = lambda a: np.ascontiguousarray(np.broadcast_to(a, (K, 1))[:, 0], dtype=float)
    B, C, E = (col(s) for s in model.shape)
    theta = np.ascontiguousarray(np.broadcast_to(model.theta, (K, n)), dtype=float)
    return _recursion(np.ascontiguousarray(model.omega, dtype=float), col(model.r), col(model.c0), col(model.c2),
                      B, C, E, theta, np.ascontiguousarray(np.broadcast_to(model.relax, (K, 1))[:, 0]),
                      col(model.dt_over_sigma), float(model.p.Fz), float(model.p.m), float(model.dt),
                      speed_step.IMPLICIT, out)


_guard_cache(globals(), ("fricenv.gap.signals.speed_step",))  # the cache compiled in the slip, Magic Formula and lag formulas
