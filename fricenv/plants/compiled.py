"""The library's plain-math formulas compiled by numba: one source, a compiled copy for the hot loops.

:func:`compile_formula` numba-compiles a plain Python function of fricenv (and, first, every fricenv function it
calls), with ``np`` rebound to :data:`FLOAT_NP` (numpy's ufuncs plus a scalar ``where``), so that the formulas of
:mod:`fricenv.plants.tire` and :mod:`fricenv.plants.rosenbrock` run on floats in machine code without being written
again. Compiled here: the ROS2 substep with the reference's refinement of unphysical substeps
(:func:`substep_refined`, the scalar form of :func:`fricenv.plants.quarter_car.step` with ``substeps=1``) and its
loop over ``n`` cars (:func:`substep_cars`). :func:`compile_array_formula` compiles the same functions for arrays
(numpy itself for ``np``). numba is imported by this module, which nothing imports at
``import fricenv``; compiled code is cached on disk (``cache=True``, guarded by :func:`guard_cache`).
"""

from __future__ import annotations

import hashlib
import os
import pathlib
import sys
import types

import numba
import numpy as np

from fricenv.plants import rosenbrock
from fricenv.plants.namespace import with_namespace
from fricenv.plants.rosenbrock import REFINE_MIN_STEP, REFINE_PARTS
from fricenv.plants.tire import longitudinal_slip, magic_formula

__all__ = ["FLOAT_NP", "compile_array_formula", "compile_formula", "guard_cache", "magic_formula_f", "slip_f",
           "substep_cars", "substep_refined"]

# the numpy error model: a float division by zero gives inf or NaN as in numpy (no Python exception check per
# division, which also costs a branch in every division of the hot loop)
jit = numba.njit(cache=True, error_model="numpy")
# numba's own thread pool, which survives a fork: the gap tool forks its worker processes after the main process
# ran kernels in threads (GNU OpenMP, numba's first choice here, aborts a forked child that uses it)
if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER = "workqueue"


@numba.njit(cache=True, error_model="numpy", inline="always")
def _where(condition, x, y):
    """``np.where`` on floats (numba's makes a 0-d array, which costs an allocation per call)."""
    return x if condition else y


# the numpy namespace the compiled copies of the library's formulas see: numpy with a scalar ``where``
FLOAT_NP = types.ModuleType("numpy_for_kernels")
FLOAT_NP.__dict__.update({k: getattr(np, k) for k in ("arctan", "sin", "cos", "exp", "maximum", "minimum",
                                                      "isfinite")})
FLOAT_NP.where = _where

_COMPILED: dict = {}  # Python function -> its compiled copy on floats
_COMPILED_ARRAYS: dict = {}  # Python function -> its compiled copy on arrays


def compile_formula(func):
    """numba-compile ``func`` and, first, every plain Python function of fricenv it calls, with :data:`FLOAT_NP`
    for numpy (:func:`~fricenv.plants.namespace.with_namespace`), so that the library's own numpy formulas run
    compiled on floats."""
    return with_namespace(func, FLOAT_NP, numba.njit(error_model="numpy"), _COMPILED)


def compile_array_formula(func):
    """numba-compile ``func`` (and every plain Python function of fricenv it calls) for arrays, with numpy itself
    for ``np``: numba runs each statement of elementwise arithmetic as one loop over the elements, which keeps the
    arithmetic of :func:`compile_formula`'s copy per element (IEEE operations and the same libm calls) and lets the
    elements' independent evaluations overlap in the processor."""
    return with_namespace(func, np, numba.njit(error_model="numpy"), _COMPILED_ARRAYS)


_ros2 = compile_formula(rosenbrock.ros2_substep)
magic_formula_f = compile_formula(magic_formula)
slip_f = compile_formula(longitudinal_slip)


@jit
def substep_refined(v, w, Tb, B, C, E, theta, mu1, h, r, m, J, Fz):
    """One substep of :func:`fricenv.plants.quarter_car.step` for one car (``substeps=1``), the refinement of an
    unphysical substep included (:data:`REFINE_PARTS` parts, again while longer than :data:`REFINE_MIN_STEP`)."""
    v_new, w_new, broken = _ros2(v, w, Tb, B, C, E, theta, mu1, h, r, m, J, Fz)
    if not broken or h <= REFINE_MIN_STEP:
        return v_new, w_new
    hp = h / REFINE_PARTS
    for _ in range(REFINE_PARTS):
        v, w = substep_refined(v, w, Tb, B, C, E, theta, mu1, hp, r, m, J, Fz)
    return v, w


@jit
def substep_cars(v, w, Tb, road, h, r, m, J, Fz, v_out, w_out):
    """:func:`substep_refined` of every car: ``road`` rows (B, C, E, theta, mu(1)), results into the out arrays."""
    for i in range(v.shape[0]):
        B, C, E, theta, mu1 = road[i, 0], road[i, 1], road[i, 2], road[i, 3], road[i, 4]
        v_new, w_new, broken = _ros2(v[i], w[i], Tb[i], B, C, E, theta, mu1, h, r, m, J, Fz)  # inlined: the common case
        if broken and h > REFINE_MIN_STEP:  # rare: the refinement (recursive, not inlined)
            v_new, w_new = substep_refined(v[i], w[i], Tb[i], B, C, E, theta, mu1, h, r, m, J, Fz)
        v_out[i], w_out[i] = v_new, w_new


def guard_cache(namespace: dict, extra_modules: tuple[str, ...] = ()) -> None:
    """Drop the on-disk compiled code when a module whose functions or constants it compiled in has changed.

    numba checks a cached function against its own source file only: an edit of the Magic Formula or of the ROS2
    substep in another module would otherwise leave the old formula compiled in. The dependencies' sources are
    hashed next to the cache; a different hash flushes the module's cached functions once (they recompile).

    :param namespace: the globals of the module whose cached functions are guarded.
    :param extra_modules: further modules they compile in (imported names).
    """
    modules = [sys.modules[m] for m in ("fricenv.plants.tire", "fricenv.plants.rosenbrock",
                                        "fricenv.plants.compiled", *extra_modules)]
    digest = hashlib.sha256(b"".join(pathlib.Path(m.__file__).read_bytes() for m in modules)).hexdigest()
    cached = [f for f in namespace.values() if isinstance(f, numba.core.registry.CPUDispatcher)
              and f.py_func.__module__ == namespace["__name__"]  # its own functions, not imported ones
              and getattr(f, "_cache", None) is not None and f._cache.__class__.__name__ == "FunctionCache"]
    if not cached:
        return
    stamp = os.path.join(cached[0]._cache.cache_path, namespace["__name__"].rsplit(".", 1)[-1] + ".deps")
    try:
        with open(stamp) as fh:
            if fh.read() == digest:
                return
    except OSError:
        pass
    for f in cached:
        f._cache.flush()
    try:
        with open(stamp, "w") as fh:
            fh.write(digest)
    except OSError:  # a read-only install: numba then caches elsewhere or not at all
        pass


guard_cache(globals())
