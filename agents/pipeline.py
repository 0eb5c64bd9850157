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
  0.088, ice at 0.39), and why the ``*-full`` estimators (theta, B, C, E) exist. An estimator that reports
  ``peak_slip`` (the EKF/RLS, whose curve-shape fit, :mod:`estimators.curve_shape`, places the peak of every road
  preset) gives the reference directly, capped at ``SLIP_REF_MAX``. The shape fit needs the slip to move (held at
  one slip, every shape fits the data with its own theta): with such an estimator the reference is dithered,
  ``lambda_ref (1 + DITHER_AMPLITUDE sin(2 pi k / DITHER_STEPS))`` (+-30 %, 0.5 s), the probe of extremum-seeking
  ABS (the mean reference is capped, the probe may pass the cap by 30 %). Without it the pipeline stayed on the
  dry prior on wet in 2 of 3 evaluation seeds (wet@20 1.097, 1.098); with it wet is found in all 3 (1.052, 1.055,
  1.064), at the price of about 1 % on dry;
* feedforward and PI: :class:`agents.controllers.SlipController` (Johansen et al. 2003), unchanged.

After a failed or skipped update (health ``SOLVER_FAILED`` / ``INVALID_INPUT`` / ``OUTLIER``) the reference is held
at its last value (initially the peak of the nominal curve). ``OUTLIER`` stays out of ``USABLE``: its estimate rests
on the gate's prediction of the wheel speed, not on a measurement, holding the reference for that sample costs
nothing, and the gate re-initialises after ``max_rejections`` (10) in a row, fewer than ``STALE_STEPS`` (20), so
outliers alone never make the estimate stale. Safe fallback: when the estimate is stale
(no usable update for ``STALE_STEPS`` control steps in a row) or implausible (a non-finite or negative ``v_hat``, or
one more than ``V_MARGIN`` below the measured wheel's surface speed ``omega_m r`` for ``BELOW_STEPS`` steps in a row,
which braking never gives), the
source falls back to ``SAFE_SLIP_REF``, a slip below the peak of every preset road (wet, the earliest, peaks at
0.088), where the wheel is stable whatever the road, and to the speed ``max(v_hat, omega_m r)`` (finite); its
``fallback`` attribute (and :attr:`EstimatorSlipPipeline.health`) says so until the estimate is usable again.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from agents.controllers import SLIP_REF_MAX, ControlSpec, SlipController, SlipControllerParams, slip_reference
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
STALE_STEPS = 20  # control steps (0.2 s) without a usable estimate before the safe fallback [-]
SAFE_SLIP_REF = 0.07  # slip reference of the fallback: below every preset road's peak (wet: 0.088) [-]
V_MARGIN = 0.5  # v_hat this far below the wheel's surface speed is implausible while braking [m/s]
BELOW_STEPS = 3  # ... for this many control steps in a row (a single wheel-speed spike is not) [-]
FIELD_WHEEL_SPEED = "wheel_speed"
DITHER_AMPLITUDE = 0.3  # relative amplitude of the slip-reference dither (extremum-seeking probe) [-]
DITHER_STEPS = 50  # its period in control steps (0.5 s) [-]
FIELD_PEAK_SLIP = "peak_slip"  # an estimate value: the estimated curve's peak slip (EKF/RLS shape fit)


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
    :param wheel_radius: r of the wheel [m], for the plausibility test of ``v_hat`` (module docstring).
    """

    def __init__(self, estimate_fn: Callable[[], tuple[dict, int] | None], shape: dict | None = None,
                 wheel_radius: float | None = None):
        self.estimate_fn = estimate_fn
        self.shape = dict(shape or NOMINAL_SHAPE)
        self.wheel_radius = wheel_radius
        self._cache: dict[tuple[float, float, float], float] = {}
        self.reset()

    def reset(self) -> None:
        self.dither = False  # set once the estimator reports a peak slip: its shape fit needs the slip to move
        self.lambda_ref = self._peak(self.shape)
        self.stale = 0  # control steps in a row without a usable estimate
        self.steps = 0  # control steps since the reset (phase of the dither)
        self.below = 0  # control steps in a row with v_hat below the wheel's surface speed
        self.fallback = False  # the safe reference is in use (module docstring)

    def _peak(self, values) -> float:
        peak = values.get(FIELD_PEAK_SLIP)
        if peak is not None and np.isfinite(peak):  # the estimator fits the curve's shape (EKF/RLS)
            self.dither = True
            return min(float(peak), SLIP_REF_MAX)
        key = tuple(round(float(values.get(n, self.shape[n])), SHAPE_DECIMALS) for n in SHAPE_NAMES[:3])
        if key not in self._cache:
            # theta does not move the peak: the shape (B, C, E) alone sets it.
            self._cache[key] = slip_reference(MagicFormula(*key, theta=1.0))[0]
        return self._cache[key]

    def __call__(self, values):
        if FIELD_V_HAT not in values:
            raise ValueError("EstimatedPeakSource needs the observation entry 'v_hat' (an estimator wrapper)")
        last = self.estimate_fn()
        usable = last is not None and last[1] in USABLE
        if usable:
            self.lambda_ref = self._peak(last[0])
        self.stale = 0 if usable else self.stale + 1
        v_hat = np.asarray(values[FIELD_V_HAT], dtype=float)
        wheel = np.zeros_like(v_hat)
        if self.wheel_radius is not None and FIELD_WHEEL_SPEED in values:
            wheel = np.asarray(values[FIELD_WHEEL_SPEED], dtype=float) * self.wheel_radius
        below = bool(np.any(v_hat < wheel - V_MARGIN))
        self.below = self.below + 1 if below else 0  # one spike of the wheel speed is not evidence
        implausible = ~np.isfinite(v_hat) | (v_hat < 0.0) | (self.below >= BELOW_STEPS)
        self.fallback = bool(np.any(implausible)) or self.stale >= STALE_STEPS
        if self.fallback:
            v = np.where(np.isfinite(v_hat), np.maximum(v_hat, wheel), wheel)
            return v, np.full_like(v, SAFE_SLIP_REF)
        self.steps += 1
        return v_hat, np.full_like(v_hat, self.lambda_ref * self._dither())

    def _dither(self) -> float:
        """Factor on the reference: ``1 + a sin(2 pi k / P)`` with ``a = DITHER_AMPLITUDE`` and ``P =
        DITHER_STEPS`` (module docstring); 1 without a shape fit to excite."""
        if not self.dither:
            return 1.0
        return 1.0 + DITHER_AMPLITUDE * float(np.sin(2.0 * np.pi * self.steps / DITHER_STEPS))


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

        source = EstimatedPeakSource(estimate_fn, assumed_shape(wrapper.estimator_name), spec.params.r)
        super().__init__(spec, source, gains)
        self.estimator_name = wrapper.estimator_name

    @property
    def health(self) -> str:
        """``fallback`` while the safe reference is in use (stale or implausible estimate), else ``ok``."""
        return "fallback" if self.source.fallback else "ok"
