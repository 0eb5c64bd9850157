"""One registry of the paper estimators: name -> :class:`EstimatorEntry` (factory, outputs, assumed shape, variant).

Every place that builds an estimator by name reads :data:`ESTIMATORS` (the braking env's estimator observation,
``estimators/bench.py``, ``fricenv paper mhe`` and ``paper ekf-rls``, the estimator + slip-controller pipeline):

==================  ========  ========  ==================================================================
name                family    variant   estimator
==================  ========  ========  ==================================================================
``ekf``             ekf       default   :class:`~estimators.ekf.QuarterCarEKF`, theta and the mismatch states
                                        ``k_T``, ``a_b`` augmented (``ekf-full``, ``mhe``, ``mhe-full`` too)
``ekf-full``        ekf       full      the same with (theta, B, C, E) augmented (Sui & Johansen, cases 3-4)
``ekf-ax``          ekf       ax        the EKF with the car's speed from the measured a_x (``v' = a_x``, input
                                        ``(T_b, a_x)``), theta and the brake gain augmented
``mhe-ax``          mhe       ax        the MHE on that model, its arrival filter ``ekf-ax``
``mhe``             mhe       default   :class:`~estimators.mhe.RegularizedMHE`, default (EKF arrival cost,
                                        process noise, gate), theta augmented
``mhe-full``        mhe       full      the same with (theta, B, C, E) augmented
``mhe-paper``       mhe       paper     the paper's MHE: prior terms beta_i, hard dynamics (12b)
``mhe-ekf``         mhe       ekf       hard dynamics with the EKF arrival cost only (no process noise, gate)
``mhe-literal``     mhe       literal   the literal SI reading of eq. (16) with the paper's prior terms
``ekf-rls``         ekf-rls   default   :class:`~estimators.ekf_rls.QuarterCarEkfRls` (quarter car) or
                                        :class:`~estimators.ekf_rls.TwoAxleEkfRls` (two-axle params), a_x loop
                                        K = ``ENV_CORRECTION_GAIN``
``ekf-rls-paper-    ekf-rls   paper-    the same with the paper-literal a_x loop of Fig. 2 (K = 100 1/s)
loop``                        loop
``ekf-rls-paper-    ekf-rls   paper-    the same with the paper's friction map eq. (15)
map``                         map
==================  ========  ========  ==================================================================

Each entry's factory takes the plant parameters the estimator assumes (``QuarterCarParams``, or
``TwoAxleParams`` for the EKF/RLS) and the sample time: the estimator's model uses that plant's m, J, r and F_z.
``assumed_shape`` is the Magic Formula shape an estimator holds for what it does not estimate (Sui & Johansen
eq. (18) for the EKF and MHE, the dry family of the EKF/RLS map); the factory builds the estimator with that very
shape, so the two cannot disagree. ``values`` says which :class:`~estimators.base.Estimate` value carries each
standard quantity (``v``, ``slip``, ``mu`` in use, ``theta`` the road's peak factor): the EKF/RLS reports the
friction in use as ``mu_utilized`` and the road's peak friction as ``mu`` (on the Magic Formula family with the
shape's peak at 1, the peak friction is theta).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from estimators.base import Estimator, EstimatorConfigError
from estimators.ekf import QuarterCarEKF
from estimators.ekf_rls import ENV_CORRECTION_GAIN, PAPER_CORRECTION_GAIN, QuarterCarEkfRls, TwoAxleEkfRls
from estimators.mhe import RegularizedMHE
from estimators.quarter_car_model import PARAM_NAMES, AugmentedModel
from estimators.slope_maps import PAPER_MAP
from estimators.tuning import (
    A_X_SLIP_BRAKING_Q_STD,
    A_X_SPEED_Q_STD,
    KT_TIMING_Q_STD,
    MISMATCH_STATES,
    TIMING_STATES,
)
from fricenv.errors import InvalidInputError
from fricenv.plants import sui_johansen as sj
from fricenv.plants.quarter_car import PAPER_PARAMS, QuarterCarParams
from fricenv.plants.tire import DRY, MagicFormula
from fricenv.plants.two_axle import TwoAxleParams

__all__ = [
    "ESTIMATORS",
    "ESTIMATOR_IDS",
    "FULL_SHAPE",
    "OBSERVATION_ESTIMATORS",
    "EstimatorEntry",
    "UnknownEstimatorError",
    "check_name",
    "get_estimator",
    "make_estimator",
]

FULL_SHAPE = PARAM_NAMES  # (theta, B, C, E): what the "-full" variants augment (Sui & Johansen, cases 3-4)
THETA_ONLY = ("theta",)
QUARTER_CAR_VALUES = MappingProxyType({"v": "v", "slip": "slip", "mu": "mu", "theta": "theta"})
EKF_RLS_VALUES = MappingProxyType({"v": "v", "slip": "slip", "mu": "mu_utilized", "theta": "mu"})


class UnknownEstimatorError(InvalidInputError):
    """An estimator name that is not in the registry."""


def _shape_dict(road: MagicFormula) -> Mapping[str, float]:
    return MappingProxyType({"theta": road.theta, "B": road.B, "C": road.C, "E": road.E})


def _augmented_model(params: Any, dt: float, estimated: tuple[str, ...], shape: Mapping[str, float],
                     extras: tuple[str, ...] = (), speed_from_a_x: bool = False):
    if not isinstance(params, QuarterCarParams):
        raise EstimatorConfigError(f"the EKF and MHE take QuarterCarParams, got {type(params).__name__}")
    try:
        return AugmentedModel(estimated=tuple(estimated), dt=dt, p=params, fixed=dict(shape), extras=tuple(extras),
                              speed_from_a_x=bool(speed_from_a_x))
    except ValueError as exc:
        raise EstimatorConfigError(str(exc)) from None


def _build_ekf(entry: EstimatorEntry, params: Any, dt: float, estimated: tuple[str, ...],
               options: dict[str, Any]) -> Estimator:
    options = dict(options)
    model = _augmented_model(params, dt, estimated, entry.assumed_shape, options.pop("mismatch_states", ()),
                             options.pop("speed_from_a_x", False))
    return QuarterCarEKF(estimated=model.estimated, dt=dt, model=model, **options)


def _build_mhe(entry: EstimatorEntry, params: Any, dt: float, estimated: tuple[str, ...],
               options: dict[str, Any]) -> Estimator:
    options = dict(options)
    model = _augmented_model(params, dt, estimated, entry.assumed_shape, options.pop("mismatch_states", ()),
                             options.pop("speed_from_a_x", False))
    return RegularizedMHE(estimated=model.estimated, dt=dt, model=model, **options)


def _build_ekf_rls(entry: EstimatorEntry, params: Any, dt: float, estimated: tuple[str, ...],
                   options: dict[str, Any]) -> Estimator:
    if estimated:
        raise EstimatorConfigError(f"{entry.name} augments no Magic Formula parameters, got estimated={estimated}")
    if isinstance(params, TwoAxleParams):  # the paper's own set-up: its map eq. (15) by default
        return TwoAxleEkfRls(dt=dt, params=params, **options)
    if not isinstance(params, QuarterCarParams):
        raise EstimatorConfigError(f"{entry.name} takes QuarterCarParams or TwoAxleParams, "
                                   f"got {type(params).__name__}")
    shape = entry.assumed_shape or _shape_dict(DRY)
    return QuarterCarEkfRls(dt=dt, p=params, shape=MagicFormula(shape["B"], shape["C"], shape["E"], shape["theta"]),
                            **options)


Builder = Callable[["EstimatorEntry", Any, float, tuple[str, ...], dict[str, Any]], Estimator]


@dataclass(frozen=True, eq=False)  # eq=False: hashed by identity (its mappings are unhashable)
class EstimatorEntry:
    """One registered estimator.

    :param family: ``ekf``, ``mhe`` or ``ekf-rls`` (the class it builds).
    :param variant: variant id within the family (``default``, ``full``, ``paper``, ...).
    :param summary: one line for tables and help.
    :param build: the family's builder ``(entry, params, dt, estimated, options) -> Estimator``.
    :param options: constructor arguments fixing this variant.
    :param estimated: Magic Formula parameters augmented by default (empty for the EKF/RLS).
    :param cls: the quarter-car estimator class it builds (its ``names`` are the entry's :attr:`outputs`).
    :param values: standard quantity (v, slip, mu, theta) -> the Estimate value that carries it.
    :param assumed_shape: the shape (theta, B, C, E) held for what it does not estimate; None: no Magic Formula
        shape (a linear friction map).
    :param observation: offered as an observation estimator of the braking env.
    """

    family: str
    variant: str
    summary: str
    build: Builder = field(repr=False)
    options: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    estimated: tuple[str, ...] = THETA_ONLY
    cls: type[Estimator] = QuarterCarEKF
    values: Mapping[str, str] = field(default_factory=lambda: QUARTER_CAR_VALUES)
    assumed_shape: Mapping[str, float] | None = field(default_factory=lambda: sj.NOMINAL_SHAPE)
    observation: bool = False

    @property
    def outputs(self) -> tuple[str, ...]:
        """The names of its :class:`~estimators.base.Estimate` values (quarter car)."""
        return tuple(self.cls.names)

    @property
    def name(self) -> str:
        """``family`` for the default variant, else ``family-variant``."""
        return self.family if self.variant == "default" else f"{self.family}-{self.variant}"

    def make(self, params: Any = PAPER_PARAMS, dt: float = sj.SAMPLE_TIME, estimated: tuple[str, ...] | None = None,
             **options: Any) -> Estimator:
        """A fresh estimator.

        :param params: plant parameters the estimator assumes (its model's m, J, r, F_z).
        :param dt: sample time [s].
        :param estimated: augmented parameters (default :attr:`estimated`).
        :param options: constructor arguments added to (or overriding) the variant's.
        """
        chosen = self.estimated if estimated is None else tuple(estimated)
        return self.build(self, params, float(dt), chosen, {**self.options, **options})


def _entries() -> tuple[EstimatorEntry, ...]:
    mhe_paper = {"arrival": "paper", "model_error": None}
    # the env entries' brake gain and drag states, and a brake's torque error (estimators.tuning)
    absorb = MappingProxyType({"mismatch_states": TIMING_STATES})
    # the full forms carry no torque error: they take the brake's timing in their brake gain
    full = {"mismatch_states": MISMATCH_STATES}
    timing_in_gain = {"Q_std": {"k_T": KT_TIMING_Q_STD}}
    # the speed from a_x: its model, and its filter's noise (the MHE's arrival filter is that EKF)
    a_x_filter = {"Q_std": {"v": A_X_SPEED_Q_STD, "k_T": KT_TIMING_Q_STD},
                  "Q_braking_std": {"slip": A_X_SLIP_BRAKING_Q_STD}}
    a_x_model = {"mismatch_states": ("k_T",), "speed_from_a_x": True}
    return (
        EstimatorEntry("ekf", "default", "augmented EKF, theta, brake gain, deceleration bias, brake torque error",
                       _build_ekf, absorb, observation=True),
        EstimatorEntry("mhe", "default", "regularized MHE (EKF arrival, process noise, gate), theta, brake gain, "
                       "deceleration bias, brake torque error", _build_mhe, absorb, cls=RegularizedMHE, observation=True),
        EstimatorEntry("ekf-rls", "default", "EKF/RLS, torque feedforward with an a_x loop, Magic Formula family map",
                       _build_ekf_rls, MappingProxyType({"correction_gain": ENV_CORRECTION_GAIN,
                                                         "braking_reference": True}), estimated=(),
                       cls=QuarterCarEkfRls, values=EKF_RLS_VALUES,
                       assumed_shape=_shape_dict(DRY), observation=True),
        EstimatorEntry("ekf", "full", "augmented EKF, theta, B, C, E, brake gain, deceleration bias", _build_ekf,
                       MappingProxyType({**full, **timing_in_gain}), estimated=FULL_SHAPE, observation=True),
        EstimatorEntry("mhe", "full", "regularized MHE, theta, B, C, E, brake gain, deceleration bias", _build_mhe,
                       MappingProxyType({**full, "filter_options": timing_in_gain}), estimated=FULL_SHAPE,
                       cls=RegularizedMHE, observation=True),
        EstimatorEntry("ekf", "ax", "augmented EKF, the speed from a_x, theta, brake gain", _build_ekf,
                       MappingProxyType({**a_x_model, **a_x_filter}), observation=True),
        EstimatorEntry("mhe", "ax", "regularized MHE, the speed from a_x, theta, brake gain", _build_mhe,
                       MappingProxyType({**a_x_model, "filter_options": a_x_filter}), cls=RegularizedMHE,
                       observation=True),
        EstimatorEntry("mhe", "paper", "the paper's MHE: prior terms beta_i, hard dynamics", _build_mhe,
                       MappingProxyType(mhe_paper), cls=RegularizedMHE),
        EstimatorEntry("mhe", "ekf", "hard dynamics, EKF arrival cost only", _build_mhe,
                       MappingProxyType({"arrival": "ekf", "model_error": None, "gate": None}), cls=RegularizedMHE),
        EstimatorEntry("mhe", "literal", "literal SI reading of eq. (16), the paper's prior terms", _build_mhe,
                       MappingProxyType({"weighting": "literal", **mhe_paper}), cls=RegularizedMHE),
        EstimatorEntry("ekf-rls", "paper-loop", "EKF/RLS with the paper-literal a_x loop (K = 100 1/s)",
                       _build_ekf_rls, MappingProxyType({"correction_gain": PAPER_CORRECTION_GAIN}), estimated=(),
                       cls=QuarterCarEkfRls, values=EKF_RLS_VALUES, assumed_shape=_shape_dict(DRY)),
        EstimatorEntry("ekf-rls", "paper-map", "EKF/RLS with the paper's friction map eq. (15)", _build_ekf_rls,
                       MappingProxyType({"mu_map": PAPER_MAP}), estimated=(), cls=QuarterCarEkfRls,
                       values=EKF_RLS_VALUES, assumed_shape=None),
    )


ESTIMATORS: Mapping[str, EstimatorEntry] = MappingProxyType({e.name: e for e in _entries()})
ESTIMATOR_IDS: tuple[str, ...] = tuple(ESTIMATORS)
# The estimators the braking env can run inside its observation (EstimatorObservation).
OBSERVATION_ESTIMATORS: tuple[str, ...] = tuple(n for n, e in ESTIMATORS.items() if e.observation)


def check_name(name: str, valid: tuple[str, ...] = ESTIMATOR_IDS) -> str:
    """Return ``name`` if it is in ``valid``, else raise :class:`UnknownEstimatorError` listing ``valid``."""
    if not isinstance(name, str) or name not in valid:
        raise UnknownEstimatorError(f"unknown estimator {name!r}; valid: {', '.join(valid)}")
    return name


def get_estimator(name: str, valid: tuple[str, ...] = ESTIMATOR_IDS) -> EstimatorEntry:
    """The registry entry called ``name``; :class:`UnknownEstimatorError` listing the valid names otherwise.

    :param name: estimator name.
    :param valid: the names accepted here (default: all).
    """
    return ESTIMATORS[check_name(name, valid)]


def make_estimator(name: str, params: Any = PAPER_PARAMS, dt: float = sj.SAMPLE_TIME,
                   estimated: tuple[str, ...] | None = None, **options: Any) -> Estimator:
    """A fresh estimator by registry name (see :meth:`EstimatorEntry.make`)."""
    return get_estimator(name).make(params, dt, estimated, **options)
