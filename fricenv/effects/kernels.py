"""Compiled (numba) window simulator: :class:`fricenv.effects.quarter_car.EffectSimulator` for a whole batch of
prediction windows in one call, element by element in machine code instead of numpy calls on small arrays.

One formula: the physics is not written again here. The ROS2 substep is
:func:`fricenv.plants.compiled.substep_refined` (:func:`fricenv.plants.rosenbrock.ros2_substep` with the reference's
refinement of unphysical substeps, as bounded recursion), the relaxation plant is
:func:`fricenv.effects.relaxation.relaxation_step_elementwise`, the Magic Formula, the slip and the drag force are
:mod:`fricenv.plants.tire`'s and :func:`fricenv.effects.library.drag_force`: numba compiles those same Python
functions (:func:`fricenv.plants.compiled.compile_formula`, which rebinds their callees to compiled ones). What is written here is the loop of
:meth:`EffectSimulator.step` over substeps (actuator chain delay -> lag -> gain -> fade, road change, load transfer,
sliding-speed friction, drag halves, pitch mode), elementwise. It is tested against ``EffectSimulator`` to 1e-12
(``tests/effects/test_kernels.py``).

Plug-in effects with Python hooks (registry entries that are not built in) are not compiled: :func:`supported`
says so and the caller keeps the numpy simulator. numba is imported by this module only, which nothing imports at
``import fricenv``; compiled code is cached on disk (``cache=True``).
"""

from __future__ import annotations

import numba
import numpy as np

from fricenv.effects import quarter_car as sim
from fricenv.effects import registry
from fricenv.effects.batch import ModelBatch
from fricenv.effects.library import drag_force
from fricenv.effects.relaxation import RELAX_GAMMA, relaxation_step_elementwise
from fricenv.plants import compiled
from fricenv.plants import quarter_car as qc
from fricenv.plants.compiled import compile_formula, jit, substep_refined
from fricenv.plants.tire import longitudinal_slip

__all__ = ["PARAM_COLUMNS", "actuator_run", "simulate_windows", "supported"]

# Columns of the per-element parameter matrix the kernel reads.
PARAM_COLUMNS = ("B", "C", "E", "theta", "tau", "delay", "gain", "sigma", "r_eff", "t_change", "theta_after", "c0",
                 "c2", "fade", "load", "slide")
_INDEX_EPS = sim._INDEX_EPS  # EffectSimulator's delay index guard
_PITCH_OMEGA, _PITCH_ZETA = sim._PITCH_OMEGA, sim._PITCH_ZETA  # EffectSimulator's pitch mode
_jit = jit
_compile = compile_formula
_mf = compiled.magic_formula_f
_slip = compiled.slip_f
_drag = compile_formula(drag_force)
_relax = compile_formula(relaxation_step_elementwise)


@_jit
def _theta(par, t_end, h, v, w, pitch, flags):
    """Peak factor over the substep ending at ``t_end`` (EffectSimulator._road_at, one element)."""
    th = par[3]
    if flags[5] and np.isfinite(par[9]):
        frac = min(max((t_end - par[9]) / h, 0.0), 1.0)
        th = th + frac * (par[10] - th)
    if flags[3]:
        th = th * max(1.0 + par[14] * pitch, 0.0)
    if flags[4]:
        th = th * np.exp(-par[15] * max(v - w * par[8], 0.0))
    return th


@_jit
def _tire_force(par, t, h, v, w, lt, pitch, flags, Fz):
    """EffectSimulator.tire_force of one element at time ``t``."""
    th = _theta(par, t, h, v, w, pitch, flags)
    if par[7] > 0.0:
        return Fz * _mf(lt, par[0], par[1], par[2], th) if v > 0.0 else 0.0
    return Fz * _mf(_slip(v, w, par[8]), par[0], par[1], par[2], th)


@_jit
def _command(cmd, idx):
    return cmd[min(max(idx, 0), cmd.shape[0] - 1)]


@_jit
def _applied(cmd, k, j, par, Ta, energy, keep, spread, dt, substeps, flags):
    """Mean applied torque over substep ``j`` and the new lag state (EffectSimulator._actuator_substep)."""
    if flags[0]:
        width = 1.0 / substeps
        s_a = j * width - par[5] / dt
        i0 = int(np.floor(s_a + _INDEX_EPS))
        f = min(max((i0 + 1 - s_a) / width, 0.0), 1.0)
        u = f * _command(cmd, k + i0) + (1.0 - f) * _command(cmd, k + i0 + 1)
    else:
        u = _command(cmd, k)
    if flags[1]:
        offset = Ta - u
        mean = u + offset * spread
        Ta = u + offset * keep
    else:
        mean = u
        Ta = u
    torque = par[6] * mean
    if flags[2]:
        torque = torque / (1.0 + par[13] * energy)
    return torque, Ta


@_jit
def _sample(cmd, k, par, x, keep, spread, s1, dt, t0, substeps, flags, consts):
    """Advance one element by one sample (EffectSimulator.step); ``x`` = (v, w, Ta, lam_t, energy, pitch, rate)."""
    m, J, Fz, g = consts
    v, w, Ta, lt, energy, pitch, rate = x
    h = dt / substeps
    relax = par[7] > 0.0
    for j in range(substeps):
        torque, Ta = _applied(cmd, k, j, par, Ta, energy, keep, spread, dt, substeps, flags)
        t_end = t0 + (k + (j + 1) / substeps) * dt
        th = _theta(par, t_end, h, v, w, pitch, flags)
        decel = 0.0
        if flags[2] or flags[3]:
            decel = _tire_force(par, t0 + k * dt, h, v, w, lt, pitch, flags, Fz) / m
        if relax:
            v, w, lt = _relax(v, w, lt, torque, par[0], par[1], par[2], th, h, par[8], par[7], par[11], par[12],
                              m, J, Fz, RELAX_GAMMA)
        else:
            if flags[6]:
                v = max(v - 0.5 * h * _drag(v, par[11], par[12]) / m, 0.0)
            v, w = substep_refined(v, w, torque, par[0], par[1], par[2], th, th * s1, h, par[8], m, J, Fz)
            if flags[6]:
                v = max(v - 0.5 * h * _drag(v, par[11], par[12]) / m, 0.0)
        if flags[2]:
            energy = energy + torque * w * h
        if flags[3]:
            acc = _PITCH_OMEGA**2 * (decel / g - pitch) - 2 * _PITCH_ZETA * _PITCH_OMEGA * rate
            rate = rate + h * acc
            pitch = pitch + h * rate
    return v, w, Ta, lt, energy, pitch, rate


@_jit
def _trajectory(cmd, k, p, v, w, Ta, lt, flags, dt, t0, substeps, consts, want_ax, out, i):
    """Simulate one window of the element with parameter row ``p`` from sample ``k`` and state (v, w, Ta, lt):
    ``out[:, i]`` (3, H) receives omega, v and a_x at the sample times."""
    m, Fz = consts[0], consts[2]
    h = dt / substeps
    keep, spread = 0.0, 0.0
    if p[4] > 0.0:
        e = np.exp(-h / p[4])
        keep, spread = e, p[4] / h * (1.0 - e)
    s1 = _mf(1.0, p[0], p[1], p[2], 1.0)
    x = (v, w, Ta, lt, 0.0, 0.0, 0.0)
    H = out.shape[2]
    for jj in range(H):
        out[0, i, jj] = x[1]
        out[1, i, jj] = x[0]
        if want_ax:
            F = _tire_force(p, t0 + k * dt, h, x[0], x[1], x[3], x[5], flags, Fz)
            out[2, i, jj] = -(F + _drag(x[0], p[11], p[12])) / m
        if jj < H - 1:
            x = _sample(cmd, k, p, x, keep, spread, s1, dt, t0, substeps, flags, consts)
            k += 1


@_jit
def _window(i, cmd, k0, x0, par, flags, dt, t0, substeps, consts, want_ax, out):
    """Simulate element ``i``'s window (:func:`_trajectory` from row ``i`` of ``k0``, ``x0`` and ``par``)."""
    _trajectory(cmd, k0[i], par[i], x0[i, 0], x0[i, 1], x0[i, 2], x0[i, 3], flags, dt, t0, substeps, consts,
                want_ax, out, i)


@numba.njit(cache=True, error_model="numpy", parallel=True)
def _windows(cmd, k0, x0, par, flags, dt, t0, substeps, consts, want_ax, out):
    """Every element's window (:func:`_window`), the elements shared among numba's threads (each is independent,
    so the result does not depend on the thread count)."""
    for i in numba.prange(x0.shape[0]):
        _window(i, cmd, k0, x0, par, flags, dt, t0, substeps, consts, want_ax, out)


@_jit
def _actuator(cmd, k0, Ta0, par, flags, dt, substeps, out):
    """Lag state at the start of each sample, actuator chain only (EffectSimulator.actuator_run's loop)."""
    h = dt / substeps
    for i in range(Ta0.shape[0]):
        p = par[i]
        keep, spread = 0.0, 0.0
        if p[4] > 0.0:
            e = np.exp(-h / p[4])
            keep, spread = e, p[4] / h * (1.0 - e)
        Ta = Ta0[i]
        for k in range(out.shape[1]):
            out[i, k] = Ta
            for j in range(substeps):
                Ta = _applied(cmd, k0[i] + k, j, p, Ta, 0.0, keep, spread, dt, substeps, flags)[1]


def actuator_run(batch: ModelBatch, commands: np.ndarray, k0, Ta0, n_steps: int, dt: float,
                 substeps: int) -> np.ndarray:
    """:meth:`EffectSimulator.actuator_run` (preset shared command log, no plant) compiled: the lag-filter state at
    the start of each of ``n_steps`` samples, (n, n_steps), from ``reset(..., k0, Ta=Ta0)``.

    :param batch: per-element model; :param commands: the shared command log [N m], (n_samples,).
    :param k0: start sample index, int or (n,); :param Ta0: lag state at ``k0`` [N m], float or (n,).
    :param n_steps: samples to run; :param dt: sample time [s]; :param substeps: physics substeps per sample.
    """
    n = len(batch)
    k0 = np.ascontiguousarray(np.broadcast_to(k0, (n,)), dtype=np.int64)
    Ta0 = np.ascontiguousarray(np.broadcast_to(np.asarray(Ta0, dtype=float), (n,)))
    out = np.empty((n, int(n_steps)))
    _actuator(np.ascontiguousarray(commands, dtype=float), k0, Ta0, _params(batch), _flags(batch), float(dt),
              int(substeps), out)
    return out


def _params(b: ModelBatch) -> np.ndarray:
    """The (n, len(PARAM_COLUMNS)) parameter matrix of the kernels."""
    return np.ascontiguousarray(np.column_stack([b.road, b.tau, b.delay, b.gain, b.sigma, b.r_eff, b.t_change,
                                                 b.theta_after, b.c0, b.c2, b.fade, b.load, b.slide]), dtype=float)


def _flags(b: ModelBatch) -> np.ndarray:
    """Parts switched on: the numpy simulator switches each on for the whole batch when any element needs it."""
    return np.array([np.any(b.delay > 0.0), np.any(b.tau > 0.0), np.any(b.fade != 0.0), np.any(b.load != 0.0),
                     np.any(b.slide != 0.0), np.any(np.isfinite(b.t_change)),
                     np.any(b.c0 != 0.0) or np.any(b.c2 != 0.0)], dtype=np.bool_)


def _guard_cache(namespace: dict | None = None, extra_modules: tuple[str, ...] = ()) -> None:
    """:func:`fricenv.plants.compiled.guard_cache` of the cached functions of ``namespace`` (default: this
    module's), with the effects' formulas among the compiled-in modules.

    :param namespace: the globals of the module whose cached functions are guarded.
    :param extra_modules: further modules they compile in (imported names).
    """
    compiled.guard_cache(globals() if namespace is None else namespace,
                         ("fricenv.effects.relaxation", "fricenv.effects.library", *extra_modules))


def supported(batch: ModelBatch) -> bool:
    """Whether :func:`simulate_windows` can run ``batch``: no plug-in effect with Python hooks switched on."""
    return not any(not e.builtin and e.param_names[0] in batch.extra and (e.torque is not None or e.theta is not None)
                   for e in registry.REGISTRY.values())


def simulate_windows(batch: ModelBatch, commands: np.ndarray, k0: np.ndarray, v0: np.ndarray, w0: np.ndarray,
                     Ta0: np.ndarray | None, lt0: np.ndarray | None, horizon: int, dt: float, t0: float,
                     substeps: int, p: qc.QuarterCarParams, want_ax: bool = True, threads: int = 1,
                     repeat: int = 1) -> np.ndarray:
    """Every element of ``batch`` simulated ``horizon`` samples from its own start, as ``EffectSimulator`` (preset
    shared command log, ``reset(v0, w0, k0, Ta0, lt0)``, then ``step()`` between samples) does.

    :param batch: per-element model, n elements (:func:`supported` must hold).
    :param commands: the shared command log [N m], (n_samples,).
    :param k0: start sample index per element, (n,).
    :param v0: start speed [m/s], (n,); :param w0: start wheel speed [rad/s], (n,).
    :param Ta0: lag state [N m] (None: the command at ``k0``); :param lt0: transient slip (None: the start slip).
    :param horizon: samples per window (the start included).
    :param dt: sample time [s]; :param t0: log time of sample 0 [s]; :param substeps: physics substeps per sample.
    :param p: quarter-car parameters; :param want_ax: also compute the acceleration (else that row is left 0).
    :param threads: threads sharing the elements (at most numba's thread count).
    :param repeat: each element of ``batch`` stands for this many consecutive windows (``batch.repeat(repeat)``
        without building it); the other arguments have ``len(batch) * repeat`` entries.
    :return: (3, n, horizon): omega, v and a_x at the sample times.
    """
    cmd = np.ascontiguousarray(commands, dtype=float)
    n = len(batch) * int(repeat)
    k0 = np.ascontiguousarray(np.broadcast_to(k0, (n,)), dtype=np.int64)
    v0 = np.broadcast_to(np.asarray(v0, dtype=float), (n,))
    w0 = np.broadcast_to(np.asarray(w0, dtype=float), (n,))
    Ta0 = cmd[np.clip(k0, 0, len(cmd) - 1)] if Ta0 is None else np.broadcast_to(Ta0, (n,))
    lt0 = longitudinal_slip(v0, w0, np.repeat(batch.r_eff, repeat)) if lt0 is None else np.broadcast_to(lt0, (n,))
    x0 = np.ascontiguousarray(np.column_stack([v0, w0, Ta0, lt0]), dtype=float)
    out = np.zeros((3, n, int(horizon)))
    numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    _windows(cmd, k0, x0, np.repeat(_params(batch), repeat, axis=0), _flags(batch), float(dt), float(t0), int(substeps), (p.m, p.J, p.Fz, p.g),
             bool(want_ax), out)
    return out


_guard_cache()
