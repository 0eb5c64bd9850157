"""The classical pipeline: an estimator inside the env plus the gain-scheduled slip controller on its outputs.

:class:`EstimatorSlipPipeline` is what an RL policy must beat. It runs on an env wrapped by
:class:`~fricenv.envs.estimator_observation.EstimatorObservation` (``make_braking(estimator=...)``):

* speed: the estimator's ``v_hat`` (observation entry), so the slip is ``1 - omega_m r / v_hat``;
* slip reference: the peak of the *estimated* friction curve, ``MagicFormula(B_hat, C_hat, E_hat,
  theta_hat).peak_slip`` (:func:`agents.controllers.slip_reference`, capped at ``SLIP_REF_MAX`` like every slip
  controller here), from the estimator's last estimate. An estimator that only estimates ``theta`` keeps B, C, E
  at its fixed values (Sui & Johansen eq. (18): B = 12, C = 1.3, E = 0, peak at slip 0.22; the EKF/RLS: the dry
  family of its friction map, peak at 0.19) whatever theta is: theta scales the curve, it does not move its
  peak. That is the honest limit of a theta-only estimator as a slip-reference source (wet asphalt peaks at
  0.088, ice at 0.39), and why the ``*-full`` estimators (theta, B, C, E) exist;
* feedforward and PI: :class:`agents.controllers.SlipController` (Johansen et al. 2003), unchanged.

After a failed or skipped update (health ``SOLVER_FAILED`` / ``INVALID_INPUT``) the reference is held at its last
value (initially the peak of the nominal curve).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from agents.controllers import ControlSpec, SlipController, SlipControllerParams, slip_reference
from estimators.base import Health
from estimators.registry import ESTIMATORS
from fricenv.envs.estimator_observation import EstimatorObservation
from fricenv.plants.sui_johansen import NOMINAL_SHAPE
from fricenv.plants.tire import MagicFormula

__all__ = [
    "PIPELINE_NAME",
    "EstimatedPeakSource",
    "EstimatorSlipPipeline",
    "assumed_shape",
    "control_spec",
    "find_estimator_wrapper",
]

PIPELINE_NAME = "est+slip-pi"
FIELD_V_HAT = "v_hat"
SHAPE_NAMES = ("B", "C", "E", "theta")
USABLE = (Health.OK, Health.NOT_EXCITED)  # estimates a reference may come from (NOT_EXCITED: held near the prior)
SHAPE_DECIMALS = 3  # estimated (B, C, E) are rounded to this many decimals to cache the peak search


def find_estimator_wrapper(env) -> EstimatorObservation:
    """The :class:`EstimatorObservation` in ``env``'s wrapper chain; ValueError if there is none."""
    e = env
    while e is not None:
        if isinstance(e, EstimatorObservation):
            return e
        e = getattr(e, "env", None)
    raise ValueError("the estimator pipeline needs an env made with make_braking(estimator=...) (an "
                     "EstimatorObservation wrapper); got one without an estimator")


def assumed_shape(estimator_name: str) -> dict[str, float]:
    """The curve shape an estimator assumes for what it does not estimate (its registry entry's
    ``assumed_shape``: the EKF/RLS maps its slip slope on the dry-asphalt family, the EKF and MHE hold eq. (18));
    eq. (18) for the oracle, whose estimate carries the whole true shape.

    :raises ValueError: an estimator without a Magic Formula shape (the EKF/RLS with the paper's linear map).
    """
    entry = ESTIMATORS.get(estimator_name)
    if entry is None:
        return dict(NOMINAL_SHAPE)
    if entry.assumed_shape is None:
        shaped = ", ".join(n for n, e in ESTIMATORS.items() if e.assumed_shape is not None)
        raise ValueError(f"estimator {estimator_name!r} assumes no Magic Formula shape: it cannot give a slip "
                         f"reference; use one with a shape ({shaped})")
    return dict(entry.assumed_shape)


class EstimatedPeakSource:
    """:class:`agents.controllers.SlipSource` from estimator outputs: ``v_hat`` and the estimated curve's peak.

    :param estimate_fn: callable returning the last estimate's values (a mapping with ``B``, ``C``, ``E`` if
        estimated) and its health, or None before the first estimate.
    :param shape: the curve shape assumed for what the estimator does not estimate (default eq. (18)).
    """

    def __init__(self, estimate_fn: Callable[[], tuple[dict, int] | None], shape: dict | None = None):
        self.estimate_fn = estimate_fn
        self.shape = dict(shape or NOMINAL_SHAPE)
        self._cache: dict[tuple[float, float, float], float] = {}
        self.reset()

    def reset(self) -> None:
        self.lambda_ref = self._peak(self.shape)

    def _peak(self, values) -> float:
        key = tuple(round(float(values.get(n, self.shape[n])), SHAPE_DECIMALS) for n in SHAPE_NAMES[:3])
        if key not in self._cache:
            # theta does not move the peak: the shape (B, C, E) alone sets it.
            self._cache[key] = slip_reference(MagicFormula(*key, theta=1.0))[0]
        return self._cache[key]

    def __call__(self, values):
        if FIELD_V_HAT not in values:
            raise ValueError("EstimatedPeakSource needs the observation entry 'v_hat' (an estimator wrapper)")
        last = self.estimate_fn()
        if last is not None:
            est, health = last
            if health in USABLE:
                self.lambda_ref = self._peak(est)
        v_hat = values[FIELD_V_HAT]
        return v_hat, np.full_like(v_hat, self.lambda_ref)


def control_spec(env) -> ControlSpec:
    """A :class:`ControlSpec` with the observation layout *as the wrappers leave it* (estimator entries included),
    so any name-based controller runs on an estimator-wrapped env."""
    base = env.unwrapped
    e, fields = env, None
    while e is not None and fields is None:
        fields = getattr(e, "observation_fields", None) if isinstance(e, EstimatorObservation) or e is base \
            else None
        e = getattr(e, "env", None)
    c = base.config
    return ControlSpec(fields=tuple(fields), t_max=c.t_max, dt=c.dt, action_mode=c.action_mode,
                       torque_rate_max=c.torque_rate_max, params=c.params)


class EstimatorSlipPipeline(SlipController):
    """Estimator + gain-scheduled slip controller on a ``make_braking(estimator=...)`` env.

    :param env: the estimator-wrapped env (any outer wrappers allowed).
    :param gains: PI gains of the slip controller.
    """

    name = PIPELINE_NAME

    def __init__(self, env, gains: SlipControllerParams | None = None):
        wrapper = find_estimator_wrapper(env)
        base = env.unwrapped
        spec = control_spec(env)

        def estimate_fn():
            if wrapper.estimator_name == "oracle":
                road = base.road
                return ({"B": road.B, "C": road.C, "E": road.E, "theta": road.theta}, Health.OK) \
                    if road is not None else None
            est = wrapper.last_estimate
            return None if est is None else (dict(est.values), int(est.health))

        super().__init__(spec, EstimatedPeakSource(estimate_fn, assumed_shape(wrapper.estimator_name)), gains)
        self.estimator_name = wrapper.estimator_name
