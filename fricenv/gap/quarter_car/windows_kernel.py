"""The per-window nuisance fit of :func:`fricenv.gap.quarter_car.windows.window_residuals` compiled with numba: for every
parameter set and window, the Gauss-Newton iterations on the window's start states (finite-difference replicas,
normalised residuals, the small normal equations, the clipped move) and the final simulation run in one call,
element by element, instead of one numpy round trip per iteration.

The same arithmetic as the numpy loop in :mod:`fricenv.gap.quarter_car.windows` (the same replicas, steps, clips and bounds,
the normal equations summed in numpy's einsum order, the same LAPACK solve), so equal to it bit for bit on this
platform's numpy build (``tests/gap/test_gap_window_fit_kernel.py``; elsewhere einsum's SIMD width may differ, and with
it the last bit of a one-state sum). A fit's path through a least-squares run can amplify a last-bit difference
into a visibly different optimum, so the diagnosis' results depend on this equality. The windows are simulated by
:func:`fricenv.effects.kernels._trajectory`, the compiled ``EffectSimulator``. Imported only when a compiled
diagnosis runs, so ``import fricenv`` does not load numba.

:func:`sensitivities` runs the same fit for one parameter set and then the least-squares fits' Jacobian
with respect to the parameters by variable projection: one simulation per parameter from the fitted start states,
what those states absorb projected out (``tests/gap/test_gap_jacobian.py``).
"""

from __future__ import annotations

import numba
import numpy as np

from fricenv.effects import kernels
from fricenv.effects.batch import ModelBatch
from fricenv.plants import quarter_car as qc

__all__ = ["STATES", "fit_windows", "sensitivities"]

STATES = ("v", "omega", "lam_t")  # the window start states, in the order of the kernel's state vector
_STATE_ROW = {"v": 1, "omega": 0, "a_x": 2}  # channel -> row of the simulator's output
_trajectory = kernels._trajectory
_slip = kernels._slip
_REG = 1e-9  # Tikhonov term of the normal equations (as the numpy loop's ``1e-9 * eye``)
_BIG = np.finfo(float).max  # np.nan_to_num's replacement of an infinite move


@numba.njit(cache=True, error_model="numpy")
def _solve(A, g):
    """``A x = g`` by LAPACK's gesv (numba's ``np.linalg.solve``: bit for bit numpy's); a singular matrix gives
    ``x = 0``, the numpy loop's answer to a ``LinAlgError`` (there for the whole batch, here for this window)."""
    try:
        return np.linalg.solve(A, g)
    except Exception:  # noqa: BLE001 (numba catches only Exception; solve raises LinAlgError when singular)
        return np.zeros_like(g)


@numba.njit(cache=True, error_model="numpy")
def _dot_simd(a, b):
    """``sum(a * b)`` in the order of numpy's einsum on contiguous operands (two SIMD lanes, unrolled four times,
    the lanes added at the end), so that the one-state normal equations equal the numpy loop's bit for bit."""
    n = a.shape[0]
    acc0, acc1 = 0.0, 0.0
    i = 0
    while n - i >= 8:
        acc0 = a[i] * b[i] + (a[i + 2] * b[i + 2] + (a[i + 4] * b[i + 4] + (a[i + 6] * b[i + 6] + acc0)))
        acc1 = a[i + 1] * b[i + 1] + (a[i + 3] * b[i + 3] + (a[i + 5] * b[i + 5] + (a[i + 7] * b[i + 7] + acc1)))
        i += 8
    while i < n:
        acc0 = a[i] * b[i] + acc0
        if i + 1 < n:
            acc1 = a[i + 1] * b[i + 1] + acc1
        i += 2
    return acc0 + acc1


@numba.njit(cache=True, error_model="numpy")
def _replicas(cmd, k, p, s, Ta, free, steps, has_lt, flags, dt, t0, substeps, consts, want_ax, buf):
    """Simulate the base state ``s`` (v, omega, lam_t) into ``buf[:, 0]`` and one replica per free state, that
    state moved by its step, into ``buf[:, 1 + i]``."""
    for j in range(1 + free.shape[0]):
        v, w, lt = s[0], s[1], s[2]
        if j > 0:
            f = free[j - 1]
            v = v + steps[f] if f == 0 else v
            w = w + steps[f] if f == 1 else w
            lt = lt + steps[f] if f == 2 else lt
        if not has_lt:
            lt = _slip(v, w, p[8])
        _trajectory(cmd, k, p, v, w, Ta, lt, flags, dt, t0, substeps, consts, want_ax, buf, j)


@numba.njit(cache=True, error_model="numpy")
def _normal_equations(buf, meas, sig, rows, free, steps, J, r0, A, g):
    """``A = J^T J + 1e-9 I`` and ``g = -J^T r`` of one window from its replicas ``buf`` (3, 1 + q, H): ``r`` the
    normalised residuals of the base simulation (0 where no measurement), ``J`` their forward differences, (M, q)
    with ``M`` = channels x H in the residuals' order. The sums in the numpy loop's order (einsum: sequential over
    ``M`` for several states, :func:`_dot_simd` for one)."""
    q = free.shape[0]
    H = meas.shape[1]
    for c in range(meas.shape[0]):
        for t in range(H):
            m = meas[c, t]
            row = c * H + t
            ok = np.isfinite(m)
            r0[row] = (buf[rows[c], 0, t] - m) / sig[c] if ok else 0.0
            for i in range(q):
                ri = (buf[rows[c], 1 + i, t] - m) / sig[c] if ok else 0.0
                J[row, i] = (ri - r0[row]) / steps[free[i]]
    if q == 1:
        A[0, 0] = _dot_simd(J[:, 0], J[:, 0])
        g[0] = -_dot_simd(J[:, 0], r0)
    else:
        A[:, :] = 0.0
        g[:] = 0.0
        for row in range(J.shape[0]):
            for i in range(q):
                g[i] += J[row, i] * r0[row]
                for j in range(q):
                    A[i, j] += J[row, i] * J[row, j]
        for i in range(q):
            g[i] = -g[i]
    for i in range(q):
        A[i, i] += _REG


@numba.njit(cache=True, error_model="numpy")
def _move(s, move, free, max_move, lower, upper):
    """The numpy loop's update: ``nan_to_num`` of the move, clipped to ``max_move``, the state to its bounds."""
    for i in range(free.shape[0]):
        f = free[i]
        x = move[i]
        x = 0.0 if np.isnan(x) else (_BIG if x == np.inf else (-_BIG if x == -np.inf else x))
        x = max(-max_move[f], min(x, max_move[f]))  # finite here
        y = s[f] + x
        # NaN stays NaN, as in np.clip (numba's min/max would not keep it)
        s[f] = lower[f] if y < lower[f] else (upper[f] if y > upper[f] else y)  # noqa: FURB136


@numba.njit(cache=True, error_model="numpy")
def _work(C, H, q):
    """Work arrays of one window's fit: replicas (3, 1 + q, H), J (C H, q), r0 (C H), A (q, q), g (q)."""
    return np.empty((3, 1 + q, H)), np.empty((C * H, q)), np.empty(C * H), np.empty((q, q)), np.empty(q)


@numba.njit(cache=True, error_model="numpy")
def _gauss_newton_move(cmd, k, p, s, Ta, meas_w, sig, rows, free, steps, max_move, lower, upper, has_lt, flags, dt,
                       t0, substeps, consts, want_ax, buf, J, r0, A, g):
    """One Gauss-Newton move of the free start states ``s`` of one window (in place): its replicas, the normal
    equations (``J``, ``r0``, ``A``, ``g`` at the states before the move) and the clipped move."""
    _replicas(cmd, k, p, s, Ta, free, steps, has_lt, flags, dt, t0, substeps, consts, want_ax, buf)
    _normal_equations(buf, meas_w, sig, rows, free, steps, J, r0, A, g)
    _move(s, _solve(A, g), free, max_move, lower, upper)


@numba.njit(cache=True, error_model="numpy", parallel=True)
def _fit_windows(cmd, k0, par, x0, meas, sig, rows, free, steps, max_move, lower, upper, iters, has_lt, flags, dt,
                 t0, substeps, consts, want_ax, out):
    """Every (parameter set, window) pair: ``iters`` Gauss-Newton moves of its free start states, then its
    simulation from the fitted states into ``out[:, k * W + w]``; the pairs shared among numba's threads."""
    K, W = par.shape[0], k0.shape[0]
    H = out.shape[2]
    q = free.shape[0]
    for e in numba.prange(K * W):
        k, w = e // W, e % W
        s = x0[k, w, :3].copy()
        Ta = x0[k, w, 3]
        buf, J, r0, A, g = _work(meas.shape[0], H, q)
        for _ in range(iters):
            _gauss_newton_move(cmd, k0[w], par[k], s, Ta, meas[:, w], sig, rows, free, steps, max_move, lower, upper,
                               has_lt, flags, dt, t0, substeps, consts, want_ax, buf, J, r0, A, g)
        lt = s[2] if has_lt else _slip(s[0], s[1], par[k, 8])
        _trajectory(cmd, k0[w], par[k], s[0], s[1], Ta, lt, flags, dt, t0, substeps, consts, want_ax, out, e)


@numba.njit(cache=True, error_model="numpy")
def _start(s, x0i, fitted, has_lt, r_eff):
    """The start of a perturbed parameter set's window: the base set's fitted states where fitted, its own estimates
    (``x0i``: v, omega, lam_t, Ta) elsewhere."""
    v = s[0] if fitted[0] else x0i[0]
    w = s[1] if fitted[1] else x0i[1]
    lt = (s[2] if fitted[2] else x0i[2]) if has_lt else _slip(v, w, r_eff)
    return v, w, lt


@numba.njit(cache=True, error_model="numpy", parallel=True)
def _sensitivity_windows(cmd, k0, par, x0, meas, sig, rows, free, steps, max_move, lower, upper, iters, has_lt,
                         flags, dt, t0, substeps, consts, want_ax, hpar, r_out, J_out):
    """Per window: the base set's (row 0) Gauss-Newton fit of the start states, its normalised residuals ``r0`` and
    state Jacobian ``J_s`` at the fitted states ``s*``, and for each further row ``i`` the projected difference
    ``P (r_i(s*) - r0) / hpar[i - 1]``, ``P = I - J_s (J_s^T J_s)^-1 J_s^T`` (see :func:`sensitivities`)."""
    W, C = k0.shape[0], meas.shape[0]
    H = r_out.shape[1] // C
    q = free.shape[0]
    fitted = np.zeros(3, dtype=np.bool_)
    for f in free:
        fitted[f] = True
    for w in numba.prange(W):
        s = x0[0, w, :3].copy()
        Ta = x0[0, w, 3]
        buf, J, r0, A, g = _work(C, H, q)
        for _ in range(iters):
            _gauss_newton_move(cmd, k0[w], par[0], s, Ta, meas[:, w], sig, rows, free, steps, max_move, lower, upper,
                               has_lt, flags, dt, t0, substeps, consts, want_ax, buf, J, r0, A, g)
        # r0 and J_s at s*: the base replica is the window's prediction from its fitted states
        _replicas(cmd, k0[w], par[0], s, Ta, free, steps, has_lt, flags, dt, t0, substeps, consts, want_ax, buf)
        _normal_equations(buf, meas[:, w], sig, rows, free, steps, J, r0, A, g)
        r_out[w] = r0
        one = np.empty((3, 1, H))
        dr = np.empty(C * H)
        for i in range(1, par.shape[0]):
            v, om, lt = _start(s, x0[i, w], fitted, has_lt, par[i, 8])
            _trajectory(cmd, k0[w], par[i], v, om, x0[i, w, 3], lt, flags, dt, t0, substeps, consts, want_ax, one,
                        0)
            for c in range(C):
                for t in range(H):
                    m = meas[c, w, t]
                    row = c * H + t
                    x = ((one[rows[c], 0, t] - m) / sig[c] - r0[row]) / hpar[i - 1] if np.isfinite(m) else 0.0
                    dr[row] = x if np.isfinite(x) else 0.0
            coef = _solve(A, J.T @ dr)
            J_out[w, :, i - 1] = dr - J @ coef


def sensitivities(batch: ModelBatch, cmd: np.ndarray, starts: np.ndarray, x0: dict, meas: dict, sigma: dict,
                  free: list[str], steps: dict, max_move: dict, lower: dict, upper: dict, iters: int, dt: float,
                  t0: float, substeps: int, p: qc.QuarterCarParams, h: np.ndarray, threads: int = 1):
    """The windows' residuals at the base parameter set (row 0 of ``batch``) and their derivatives along the
    further rows, with the start states fitted per window (variable projection, Kaufman's Jacobian).

    A window's residuals depend on the parameters directly and through its fitted start states ``s*``. At a
    least-squares optimum over ``s`` the second path contributes the projection of the first onto the span of the
    state Jacobian ``J_s``, so ``dr/dx_i = (I - J_s J_s^+) dr/dx_i |_s*``: one simulation per parameter from the
    base set's fitted states, instead of a Gauss-Newton fit per perturbed set (a forward difference of
    :func:`fit_windows`). States that are not fitted (the reconstructed speed without ``v``, the lag filter) are the
    perturbed set's own, as in :func:`fit_windows`.

    :param batch: 1 + P parameter sets: the base, then the base moved by ``h[i]`` in one parameter each.
    :param h: (P,) the moves; the other arguments as :func:`fit_windows`.
    :return: (r0 (W, M) the base set's normalised residuals, equal to :func:`fit_windows`'s; J (W, M, P)), ``M`` =
        channels x H in the residuals' order, 0 where no measurement.
    """
    M = len(meas) * next(iter(meas.values())).shape[1]
    r0 = np.zeros((len(starts), M))
    J = np.zeros((len(starts), M, len(batch) - 1))
    _sensitivity_windows(*_kernel_args(batch, cmd, starts, x0, meas, sigma, free, steps, max_move, lower, upper, iters,
                                       dt, t0, substeps, p, threads), np.ascontiguousarray(h, dtype=float), r0, J)
    return r0, J


def _start_states(x0: dict, cmd: np.ndarray, k0: np.ndarray, K: int, W: int) -> np.ndarray:
    """(K, W, 4) start states v, omega, lam_t (0 when the model has none) and Ta (None: the command at the start)."""
    Ta = x0.get("Ta")
    Ta = np.broadcast_to(cmd[np.clip(k0, 0, len(cmd) - 1)], (K, W)) if Ta is None else Ta
    lt = x0["lam_t"] if x0.get("lam_t") is not None else np.zeros((K, W))
    return np.ascontiguousarray(np.stack([np.broadcast_to(x0["v"], (K, W)), np.broadcast_to(x0["omega"], (K, W)),
                                          lt, Ta], axis=-1), dtype=float)


def _per_state(values: dict, default: float) -> np.ndarray:
    return np.array([float(values.get(name, default)) for name in STATES])


def fit_windows(batch: ModelBatch, cmd: np.ndarray, starts: np.ndarray, x0: dict, meas: dict, sigma: dict,
                free: list[str], steps: dict, max_move: dict, lower: dict, upper: dict, iters: int, dt: float,
                t0: float, substeps: int, p: qc.QuarterCarParams, threads: int = 1) -> dict:
    """The windows' predictions from their Gauss-Newton-fitted start states, as the numpy loop of
    :func:`fricenv.gap.quarter_car.windows.window_residuals` computes them (:func:`kernels.supported` must hold for ``batch``).

    :param batch: K parameter sets; :param cmd: the command log [N m]; :param starts: W window start samples.
    :param x0: start states (K, W) by name: ``v``, ``omega``, ``Ta`` (None: the command at the start) and ``lam_t``
        (None: the start slip; a model without tire relaxation does not use it).
    :param meas: channel -> (W, H) measurements (NaN: none), in the residuals' channel order.
    :param sigma: channel -> noise std; :param free: the fitted states (names of :data:`STATES`), in J's order.
    :param steps, max_move, lower, upper: per fitted state, its finite-difference step, largest move per
        iteration and bounds. :param iters: Gauss-Newton iterations.
    :param dt, t0, substeps, p: as :func:`kernels.simulate_windows`; :param threads: threads sharing the pairs.
    :return: channel -> (K, W, H) predictions.
    """
    K, W = len(batch), len(starts)
    channels = list(meas)
    H = next(iter(meas.values())).shape[1]
    out = np.zeros((3, K * W, H))
    _fit_windows(*_kernel_args(batch, cmd, starts, x0, meas, sigma, free, steps, max_move, lower, upper, iters, dt, t0,
                               substeps, p, threads), out)
    return {c: out[_STATE_ROW[c]].reshape(K, W, H) for c in channels}


def _kernel_args(batch: ModelBatch, cmd: np.ndarray, starts: np.ndarray, x0: dict, meas: dict, sigma: dict,
                 free: list[str], steps: dict, max_move: dict, lower: dict, upper: dict, iters: int, dt: float,
                 t0: float, substeps: int, p: qc.QuarterCarParams, threads: int) -> tuple:
    """The arguments :func:`_fit_windows` and :func:`_sensitivity_windows` share, as arrays in the kernels' layout
    (and numba's thread count set)."""
    cmd = np.ascontiguousarray(cmd, dtype=float)
    k0 = np.ascontiguousarray(starts, dtype=np.int64)
    channels = list(meas)
    numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    return (cmd, k0, kernels._params(batch), _start_states(x0, cmd, k0, len(batch), len(starts)),
            np.ascontiguousarray(np.stack([meas[c] for c in channels])),
            np.array([sigma[c] for c in channels], dtype=float),
            np.array([_STATE_ROW[c] for c in channels], dtype=np.int64),
            np.array([STATES.index(n) for n in free], dtype=np.int64), _per_state(steps, 0.0),
            _per_state(max_move, 0.0), _per_state(lower, -np.inf), _per_state(upper, np.inf), int(iters),
            x0.get("lam_t") is not None, kernels._flags(batch), float(dt), float(t0), int(substeps),
            (p.m, p.J, p.Fz, p.g), "a_x" in channels)


kernels._guard_cache(globals(), ("fricenv.effects.kernels",))  # the cache compiled in the window simulator
