"""The quarter-car effect registry: one entry per effect holds everything the library does with it.

An entry (:class:`QuarterCarEffect`) names the effect's spec class (a frozen dataclass whose fields are the
registry parameter names), its parameters (unit, fit range, the value that switches it off, fit scales), its fit
starts, what it needs from a log, how the gap tool fits it, its draw for the validation logs and, for an effect the
simulator does not build in, its physics hooks. :mod:`fricenv.effects.quarter_car` (``ModelBatch``,
``EffectSimulator``, ``make_effect``), the diagnosis, the validation and the speed reconstruction iterate over
:data:`REGISTRY`; adding an effect is one entry (built-in effects: :mod:`fricenv.effects.library`) and its test.

A plug-in effect (one registered at run time, ``builtin=False``) keeps its per-element parameters in
``ModelBatch.extra`` and acts through its hooks:

- ``torque(params, torque) -> torque``: the applied brake torque [N m] of each element after the built-in actuator
  chain (delay -> lag -> gain [-> fade]);
- ``theta(params, theta, t) -> theta``: the road's peak factor of each element at log time ``t`` [s].

``params`` maps each of the effect's parameter names to its (n,) array.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, fields

import numpy as np

from fricenv.errors import InvalidInputError

__all__ = [
    "REGISTRY",
    "Excitation",
    "FitContext",
    "Param",
    "QuarterCarEffect",
    "effects_in_library",
    "get",
    "register",
    "registered",
    "unregister",
]


class UnknownEffectError(InvalidInputError):
    """An effect name that is not registered."""


@dataclass(frozen=True)
class Param:
    """One effect parameter.

    :param name: registry parameter name (unique over all effects: the fits concatenate parameter vectors).
    :param unit: SI unit, for reports.
    :param bounds: the fit's range (``(-inf, inf)`` for a log time: then the training windows bound it).
    :param physical: the range a verdict may name, where narrower than ``bounds`` (default: ``bounds``): a fit may
        pass beyond it on its way, but a value beyond it stretches the effect to imitate something else.
    :param off: the value that switches the effect off; a callable ``(road (4,) or (n, 4), p) -> value`` when it
        depends on the road or the vehicle (the rolling radius, the theta after a change).
    :param fd_step: finite-difference step of the fit Jacobian (absolute).
    :param x_scale: the parameter's typical scale for the trust region.
    :param field: the ``ModelBatch`` field of a built-in effect (default: the name); None keeps the value in
        ``ModelBatch.extra`` (plug-in effects).
    :param log_time: the parameter is a time on the log's clock (bounded by the training windows in a fit).
    """

    name: str
    unit: str
    bounds: tuple[float, float]
    off: float | Callable = 0.0
    fd_step: float = 1e-3
    x_scale: float = 1.0
    field: str | None = ""
    log_time: bool = False
    physical: tuple[float, float] | None = None

    @property
    def physical_range(self) -> tuple[float, float]:
        return self.physical if self.physical is not None else self.bounds

    @property
    def batch_field(self) -> str | None:
        return self.name if self.field == "" else self.field

    def off_value(self, road: np.ndarray, p) -> np.ndarray | float:
        return self.off(road, p) if callable(self.off) else self.off


@dataclass(frozen=True)
class FitContext:
    """What a fit-start rule may use: the vehicle parameters and the log's free-rolling ratio ``v / omega``
    (median over the free-rolling start; None when ``v`` is not logged)."""

    p: object
    free_roll_ratio: float | None = None


@dataclass(frozen=True)
class Excitation:
    """What a log shows, for the effects' testability rules.

    :param has_v: the reference speed is logged.
    :param has_a_x: the longitudinal acceleration is logged.
    :param braking_windows: prediction windows with braking torque.
    :param torque_transients: brake apply/release events (torque changing fast while braking).
    :param slip_transient_windows: windows whose slip changes by more than a few percent.
    :param near_peak_early: windows near the friction peak in the first half of the braking.
    :param near_peak_late: the same in the second half.
    :param speed_range: braking speed range [m/s].
    :param training_windows: the fewest training windows of a cross-fitting fold.
    """

    has_v: bool
    has_a_x: bool
    braking_windows: int
    torque_transients: int
    slip_transient_windows: int
    near_peak_early: int
    near_peak_late: int
    speed_range: float
    training_windows: int


def always_testable(x: Excitation) -> str | None:
    """Testability rule of an effect any braking log shows."""
    return None if x.braking_windows >= 2 else "no braking in the log"


@dataclass(frozen=True)
class QuarterCarEffect:
    """A quarter-car effect: its spec, parameters, fit recipe, validation draw and (plug-ins) physics hooks.

    :param spec: frozen dataclass with a ``name`` ClassVar and one field per parameter, in ``params`` order.
    :param params: the parameters.
    :param needs: what a log must show for the effect to be identifiable (for reports).
    :param starts: ``FitContext -> [ {param: value}, ... ]`` fit starts (multiplied with the road starts).
    :param fit: the gap tool's fit strategy: ``"least_squares"`` or ``"change_point"`` (a switching time
        searched, its other parameters fitted).
    :param searched: parameters found by search and held during least squares (``"change_point"``).
    :param window_states: states fitted per prediction window on that window's own samples (a transient slip).
    :param draw: ``(road, rng, p) -> spec`` at a realistic size for the validation logs (None: not drawn).
    :param main_error: ``(truth, fitted, errors) -> figure`` of the 15 % parameter target; it may add entries to
        ``errors`` (default: the first parameter's relative error).
    :param in_library: the gap tool fits it (False: a validation-only effect outside the library).
    :param builtin: the simulator builds it in (False: a plug-in acting through ``torque``/``theta``).
    :param testable: ``Excitation -> None`` when the log can show the effect, else the reason it cannot (``needs``
        in the log's terms); a diagnosis lists the effects it could not test in ``where["not_testable"]``.
    :param caveat: ``Excitation -> None``, or what a test of the effect on this log rests on when it is testable
        only in part (``where["caveats"]``): a verdict of ``none`` says less about it.
    :param torque: plug-in hook on the applied torque (see the module docstring).
    :param theta: plug-in hook on the road's peak factor.
    """

    spec: type
    params: tuple[Param, ...]
    needs: str
    starts: Callable[[FitContext], list[dict]] = lambda ctx: []
    fit: str = "least_squares"
    searched: tuple[str, ...] = ()
    window_states: int = 0
    draw: Callable | None = None
    main_error: Callable | None = None
    in_library: bool = True
    builtin: bool = True
    torque: Callable | None = None
    theta: Callable | None = None
    testable: Callable[[Excitation], str | None] = always_testable
    caveat: Callable[[Excitation], str | None] | None = None

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(q.name for q in self.params)

    def make(self, **params: float):
        """The effect's spec from its parameters, by their registry names (ValueError listing the valid ones)."""
        valid = self.param_names
        unknown = sorted(set(params) - set(valid))
        missing = [v for v in valid if v not in params]
        if unknown or missing:
            what = f"unknown parameter(s) {', '.join(unknown)}" if unknown else \
                f"missing parameter(s) {', '.join(missing)}"
            raise ValueError(f"effect {self.name!r}: {what}; its parameters are: {', '.join(valid)}")
        return self.spec(**{k: float(v) for k, v in params.items()})


REGISTRY: dict[str, QuarterCarEffect] = {}


def register(entry: QuarterCarEffect) -> QuarterCarEffect:
    """Add an effect to the registry (its name and parameter names must be new, its parameters its spec's fields).

    :raises ValueError: a taken name or parameter name, parameters that are not the spec's fields, or a plug-in
        without a hook.
    """
    if entry.name in REGISTRY:
        raise ValueError(f"effect {entry.name!r} is already registered; unregister it first or pick another name")
    spec_fields = tuple(f.name for f in fields(entry.spec))
    if spec_fields != entry.param_names:
        raise ValueError(f"effect {entry.name!r}: params {entry.param_names} must be its spec's fields {spec_fields}")
    taken = {q.name for e in REGISTRY.values() if e.in_library for q in e.params}
    clash = sorted(taken & set(entry.param_names)) if entry.in_library else []
    if clash:
        raise ValueError(f"effect {entry.name!r}: parameter name(s) {', '.join(clash)} already used by another "
                         f"effect; the fits need unique names")
    if not entry.builtin and entry.torque is None and entry.theta is None:
        raise ValueError(f"plug-in effect {entry.name!r} needs a torque or theta hook")
    REGISTRY[entry.name] = entry
    return entry


def unregister(name: str) -> None:
    """Remove an effect from the registry."""
    REGISTRY.pop(name, None)


@contextmanager
def registered(entry: QuarterCarEffect) -> Iterator[QuarterCarEffect]:
    """The effect registered for the enclosed code only (tests, experiments)."""
    register(entry)
    try:
        yield entry
    finally:
        unregister(entry.name)


def get(name: str, allow_out_of_library: bool = True) -> QuarterCarEffect:
    """The registry entry of an effect name.

    :raises ValueError: unknown name (lists the valid ones).
    """
    entry = REGISTRY.get(name)
    if entry is None or not (entry.in_library or allow_out_of_library):
        valid = [n for n, e in REGISTRY.items() if e.in_library or allow_out_of_library]
        raise UnknownEffectError(f"unknown effect {name!r}; valid effects: {', '.join(valid)}")
    return entry


def effects_in_library() -> tuple[str, ...]:
    """Names of the library effects (the ones the gap tool fits), in registration order."""
    return tuple(n for n, e in REGISTRY.items() if e.in_library)
