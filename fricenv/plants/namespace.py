"""One formula, several number systems: a plain-math function of fricenv with its ``np`` rebound.

The library's formulas (the Magic Formula, the slip, the ROS2 substep, the slip ODE, drag) are written once as
plain arithmetic over a module-level ``np`` (numpy's ``arctan``, ``sin``, ``cos``, ``maximum``, ``where``, ...).
:func:`with_namespace` returns a copy of such a function, and of every fricenv function it calls, that sees another
namespace under that name: numba's float kernels (:func:`fricenv.plants.compiled.compile_formula`) and the
estimators' CasADi models (``estimators.quarter_car_model``) are built this way from the same source.
"""

from __future__ import annotations

import types
from collections.abc import Callable
from typing import Any

__all__ = ["with_namespace"]


def with_namespace(func: Callable, np_like: Any, wrap: Callable | None = None, seen: dict | None = None) -> Callable:
    """``func`` with ``np`` bound to ``np_like`` in it and in every plain Python function of fricenv it calls.

    :param func: a fricenv function written over ``np``.
    :param np_like: the namespace that stands for numpy (it needs the attributes the formulas use).
    :param wrap: applied to each rebound copy (e.g. ``numba.njit``); None keeps the plain function.
    :param seen: cache of finished copies (function -> copy), shared across calls with the same ``np_like``.
    :return: the rebound (and wrapped) copy of ``func``.
    """
    seen = {} if seen is None else seen
    if func in seen:
        return seen[func]
    deps = {"np": np_like} if "np" in func.__code__.co_names else {}
    for name in func.__code__.co_names:
        g = func.__globals__.get(name)
        if isinstance(g, types.FunctionType) and g.__module__.startswith("fricenv"):
            deps[name] = with_namespace(g, np_like, wrap, seen)
    rebound = types.FunctionType(func.__code__, {**func.__globals__, **deps}, func.__name__, func.__defaults__)
    seen[func] = out = rebound if wrap is None else wrap(rebound)
    return out
