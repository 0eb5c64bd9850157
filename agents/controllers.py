"""Classical ABS controllers for ``fricenv/Braking-v0`` (and the batched :class:`~fricenv.envs.braking_sim.BrakingSim`).

All controllers share one interface: ``reset()`` at the start of an episode and ``act(obs) -> action`` with the
env's normalised action (shape ``(1,)`` for one observation ``(obs_dim,)``, shape ``(n,)`` for a batch
``(n, obs_dim)``). They read the observation by entry *name* through :class:`ObsReader` (never by index), so they
work with any observation layout that has the entries they need, and with both action modes (``torque`` and
``torque_rate``): each computes a desired brake torque and :class:`ControlSpec` turns it into the action.

=====================  =================================================================================
controller             uses
=====================  =================================================================================
RuleBasedABS           measured wheel speed, wheel deceleration, last command, a_x (what an ABS ECU has)
SlipController         measured signals + a :class:`SlipSource` giving the speed estimate and slip reference
OracleSlipController   true speed and slip (``observation="oracle"``) and the true road
FullBraking            nothing: full torque, the wheel locks
=====================  =================================================================================
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from agents.controller_base import (  # noqa: F401 (re-exported: the public names of the controllers)
    CONTROL_SPEED_FLOOR,
    FIELD_AX,
    FIELD_SLIP,
    FIELD_TORQUE,
    FIELD_V,
    FIELD_WHEEL_DECEL,
    FIELD_WHEEL_SPEED,
    Controller,
    ControlSpec,
    ObsReader,
    _spec,
)
from fricenv.plants.quarter_car import QuarterCarParams
from fricenv.plants.sui_johansen import OMEGA_NOISE_STD
from fricenv.plants.tire import MagicFormula, ecu_slip

__all__ = [
    "CONTROLLERS",
    "ControlSpec",
    "Controller",
    "FullBraking",
    "ObsReader",
    "OracleSlipController",
    "OracleSource",
    "Rollout",
    "RuleABSParams",
    "RuleBasedABS",
    "SlipController",
    "SlipControllerParams",
    "SlipSource",
    "make_controller",
    "rollout",
    "slip_reference",
]

# The paper's snow has no friction peak below slip 1 (C < 1): a slip reference is capped here instead, where
# its friction is within 0.3 % of the peak and the wheel is far from the lock definition (omega r < 0.05 v).
SLIP_REF_MAX = 0.4
class FullBraking(Controller):
    """Full brake torque from the first step: the wheel locks (the ``1.27x`` baseline on dry asphalt)."""

    name = "locked"

    def _torque(self, obs, torque_now):
        return np.full(obs.shape[0], self.spec.t_max)


# ---------------------------------------------------------------------------------------------- rule-based ABS
# Phases of the rule-based cycle (after the Bosch Automotive Handbook's 8-phase control cycle).
PH_BUILD, PH_HOLD, PH_DUMP, PH_HOLD_LOW, PH_REAPPLY = 0, 1, 2, 3, 4
PHASE_NAMES = ("build-up", "hold", "dump", "hold-low", "reapply")


@dataclass(frozen=True)
class RuleABSParams:
    """Thresholds and rates of :class:`RuleBasedABS`.

    The wheel-deceleration thresholds act on the *excess* wheel deceleration ``e = a_w + a_x`` (wheel
    deceleration minus the measured vehicle deceleration). On the stable side of the friction curve the wheel
    follows the vehicle and ``e ~ 0``; past the peak it grows by ``r (T_b - T_peak) / J``, so ``e`` detects an
    excess brake torque on any road. Fields may be arrays (one value per car of a batch), e.g. for tuning.
    """

    decel_minus: float = 7.0  # -a: excess wheel deceleration that ends a torque rise [m/s^2]
    decel_dump: float = 25.0  # excess wheel deceleration that starts a dump from hold [m/s^2]
    accel_plus: float = 0.5  # +a: wheel re-acceleration (relative) that ends the dump [m/s^2]
    accel_big: float = 5.5  # +A: strong re-acceleration, reapply fast [m/s^2]
    slip_high: float = 0.5  # lambda_1: slip above which torque is dumped whatever the deceleration [-]
    rate_build: float = 120000.0  # initial build-up rate [N m/s]
    rate_dump: float = 14000.0  # dump rate [N m/s]
    rate_reapply: float = 2700.0  # slow reapply rate [N m/s]
    rate_reapply_fast: float = 9400.0  # reapply rate after a +A re-acceleration [N m/s]
    dump_fraction: float = 0.08  # step drop of the torque on entering dump, fraction of the torque [-]
    omega_margin: float = 2.0  # wheel-speed noise margin (in noise standard deviations) for v_ref [-]
    omega_noise_std: float = OMEGA_NOISE_STD  # wheel-speed noise the ECU assumes [rad/s], Sui & Johansen


class RuleBasedABS(Controller):
    """Bosch-style rule-based ABS on measured signals only.

    The ECU builds a reference speed from its sensors: ``v_ref`` integrates the measured longitudinal acceleration
    and is pulled up to the wheel's circumferential speed whenever the wheel is faster (minus a noise margin), the
    classic reference-speed logic. With it, the slip estimate is ``1 - omega_m r / v_ref``. The phases act on the
    excess wheel deceleration ``e = a_w + a_x`` (see :class:`RuleABSParams`):

    ========  =======================================================  ==================================
    phase     torque                                                   leaves when
    ========  =======================================================  ==================================
    build-up  rises at ``rate_build``                                  e > -a -> hold
    hold      held                                                     e > decel_dump or slip >
                                                                       lambda_1 -> dump; e < -a -> reapply
    dump      drops by ``dump_fraction``, then falls at ``rate_dump``  e < -(+a) (wheel re-accelerates)
                                                                       and slip < lambda_1 -> hold-low
    hold-low  held                                                     -e > +A -> fast reapply;
                                                                       -e < +a -> reapply
    reapply   rises at ``rate_reapply`` (``rate_reapply_fast`` after   e > -a -> hold;
              +A)                                                      slip > lambda_1 -> dump
    ========  =======================================================  ==================================

    In every phase, a slip above ``lambda_1`` forces a dump (a locked wheel has no deceleration to show).
    """

    name = "rule-abs"
    needs = (FIELD_WHEEL_SPEED, FIELD_WHEEL_DECEL, FIELD_TORQUE, FIELD_AX)

    def __init__(self, env_or_spec, params: RuleABSParams | None = None):
        super().__init__(env_or_spec)
        self.params = params if params is not None else RuleABSParams()

    def _init_state(self, batch, size=None):
        n = batch.shape[0] if batch is not None else size
        return {"phase": np.full(n, PH_BUILD), "v_ref": np.zeros(n), "fast": np.zeros(n, dtype=bool),
                "fresh": np.ones(n, dtype=bool), "torque": np.zeros(n)}

    def _torque(self, obs, torque_now):
        p, s, dt, r = self.params, self._state, self.spec.dt, self.spec.params.r
        wheel = self.reader.get(obs, FIELD_WHEEL_SPEED) * r
        ax = self.reader.get(obs, FIELD_AX)
        excess = self.reader.get(obs, FIELD_WHEEL_DECEL) + ax
        # Cars at the start of an episode take their reference speed from the (free-rolling) wheel.
        s["v_ref"] = np.where(s["fresh"], wheel, s["v_ref"])
        s["fresh"][:] = False
        # Reference speed: a_x integration, pulled up to the wheel speed (the vehicle is never slower).
        s["v_ref"] = np.maximum(s["v_ref"] + ax * dt, wheel - p.omega_margin * p.omega_noise_std * r)
        slip = ecu_slip(self.reader.get(obs, FIELD_WHEEL_SPEED), s["v_ref"], r, CONTROL_SPEED_FLOOR)
        ph = s["phase"]
        rising = (ph == PH_BUILD) | (ph == PH_REAPPLY)
        new = np.where(rising & (excess > p.decel_minus), PH_HOLD, ph)
        new = np.where((ph == PH_HOLD) & (excess < p.decel_minus), PH_REAPPLY, new)
        new = np.where((ph == PH_HOLD) & (excess > p.decel_dump), PH_DUMP, new)
        deep = slip > p.slip_high
        new = np.where((ph == PH_DUMP) & (excess < -p.accel_plus) & ~deep, PH_HOLD_LOW, new)
        go_fast = (ph == PH_HOLD_LOW) & (-excess > p.accel_big)
        go_slow = (ph == PH_HOLD_LOW) & (-excess < p.accel_plus)
        new = np.where(go_fast | go_slow, PH_REAPPLY, new)
        # A wheel far past the peak (e.g. locked after a drop in friction, where its deceleration reads zero)
        # dumps whatever its deceleration says.
        new = np.where(deep, PH_DUMP, new)
        s["fast"] = np.where(go_fast, True, np.where(go_slow, False, s["fast"]))
        entering_dump = (new == PH_DUMP) & (ph != PH_DUMP)
        s["phase"] = new
        rate = np.select(
            [new == PH_BUILD, new == PH_DUMP, (new == PH_REAPPLY) & s["fast"], new == PH_REAPPLY],
            [p.rate_build, -p.rate_dump, p.rate_reapply_fast, p.rate_reapply], 0.0)
        torque = np.where(entering_dump, s["torque"] * (1.0 - p.dump_fraction), s["torque"])
        torque = np.clip(torque + rate * dt, 0.0, self.spec.t_max)
        s["torque"] = torque
        return torque


# ---------------------------------------------------------------------------------------------- slip control
def slip_reference(road: MagicFormula) -> tuple[float, float]:
    """Slip reference and its friction for a road: the true peak slip, capped at :data:`SLIP_REF_MAX`.

    The cap only matters for the paper's snow (``C < 1``), whose friction rises all the way to slip 1: braking at
    the cap gives up 0.3 % of friction and keeps the wheel rolling.

    :return: (lambda_ref [-], mu(lambda_ref) [-]).
    """
    lam = min(road.peak_slip, SLIP_REF_MAX)
    return lam, float(road.mu(lam))


class SlipSource(Protocol):
    """Where a slip controller gets its speed estimate and slip reference from (an estimator, or the truth)."""

    def reset(self) -> None:
        """Start of an episode."""

    def __call__(self, values: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """(v_hat [m/s], lambda_ref [-]) from the decoded observation (entries in physical units)."""


class OracleSource:
    """The truth as a :class:`SlipSource`: speed from the oracle observation entry ``v``, reference from the road.

    :param road_fn: callable returning the road under the car now (a MagicFormula), e.g. ``lambda: env.unwrapped.road``;
        or None to use the fixed ``slip_ref``.
    :param slip_ref: fixed slip reference when ``road_fn`` is None [-].
    """

    def __init__(self, road_fn: Callable[[], MagicFormula] | None = None, slip_ref: float = 0.1):
        self.road_fn = road_fn
        self.slip_ref = float(slip_ref)

    @classmethod
    def from_env(cls, env) -> OracleSource:
        """Speed and road reference of a ``Braking-v0`` env (needs ``observation="oracle"``)."""
        base = env.unwrapped
        return cls(road_fn=lambda: base.road)

    def reset(self) -> None:
        pass

    def __call__(self, values):
        if FIELD_V not in values:
            raise ValueError("OracleSource needs the observation entry 'v': make the env with observation='oracle'")
        lam = slip_reference(self.road_fn())[0] if self.road_fn is not None else self.slip_ref
        return values[FIELD_V], np.full_like(values[FIELD_V], lam)


@dataclass(frozen=True)
class SlipControllerParams:
    """Gains of the gain-scheduled slip controllers."""

    kp: float = 40.0  # proportional gain of the closed slip loop [1/s]
    ki: float = 400.0  # integral gain [1/s^2]
    integral_limit: float = 0.05  # anti-windup bound of the slip-error integral [s]


def _equilibrium_torque(mu, lam, p: QuarterCarParams):
    """Brake torque that holds slip ``lam`` steady at friction ``mu``: eq. (6b) with lambda' = 0 [N m].

    ``T = (J / r) ((1 - lambda) / m + r^2 / J) F_z mu = r F_z mu (1 + J (1 - lambda) / (m r^2))``.
    """
    return p.r * p.Fz * mu * (1.0 + p.J * (1.0 - lam) / (p.m * p.r ** 2))


class _GainScheduledSlip(Controller):
    """Slip tracking after Johansen et al. (2003): feedforward plus PI, scheduled on speed.

    Eq. (6b) gives ``lambda' = (r / (J v)) (T_b - T_eq(lambda))``, with ``T_eq`` the torque that holds the slip
    (:func:`_equilibrium_torque`). The control ``T_b = T_ff + (J v / r) (k_p e + k_i int e)``, ``e = lambda_ref -
    lambda``, cancels the ``1/v`` gain of the plant, so the slip loop has the same dynamics at every speed.
    """

    def __init__(self, env_or_spec, gains: SlipControllerParams | None = None):
        super().__init__(env_or_spec)
        self.gains = gains if gains is not None else SlipControllerParams()

    def _init_state(self, batch, size=None):
        n = batch.shape[0] if batch is not None else size
        return {"integral": np.zeros(n)}

    def _pi(self, v, lam, lam_ref, t_ff):
        g, s, p, dt = self.gains, self._state, self.spec.params, self.spec.dt
        err = lam_ref - lam
        s["integral"] = np.clip(s["integral"] + err * dt, -g.integral_limit, g.integral_limit)
        v = np.maximum(v, CONTROL_SPEED_FLOOR)
        return np.clip(t_ff + p.J * v / p.r * (g.kp * err + g.ki * s["integral"]), 0.0, self.spec.t_max)


class SlipController(_GainScheduledSlip):
    """Gain-scheduled PI slip controller on measured signals plus a speed/slip-reference source.

    The slip is ``1 - omega_m r / v_hat`` from the measured wheel speed and the source's speed estimate; the
    feedforward is the equilibrium torque at the friction measured by the accelerometer, ``mu_hat = -m a_x / F_z``.

    :param env_or_spec: env, BrakingSim or ControlSpec.
    :param source: a :class:`SlipSource` (object with ``reset()`` and ``__call__(values) -> (v_hat,
        lambda_ref)``) or a plain callable ``values -> (v_hat, lambda_ref)``.
    :param gains: PI gains.
    """

    name = "slip-pi"
    needs = (FIELD_WHEEL_SPEED, FIELD_TORQUE, FIELD_AX)

    def __init__(self, env_or_spec, source: SlipSource | Callable, gains: SlipControllerParams | None = None):
        super().__init__(env_or_spec, gains)
        if not callable(source):
            raise TypeError(f"source must be callable (values -> (v_hat, lambda_ref)), got {type(source).__name__}")
        self.source = source

    def reset(self) -> None:
        super().reset()
        if hasattr(self.source, "reset"):
            self.source.reset()

    def _torque(self, obs, torque_now):
        p = self.spec.params
        values = self.reader.decode(obs)
        v_hat, lam_ref = self.source(values)
        v_hat = np.asarray(v_hat, dtype=float)
        lam_ref = np.asarray(lam_ref, dtype=float)
        lam = ecu_slip(values[FIELD_WHEEL_SPEED], v_hat, p.r, CONTROL_SPEED_FLOOR)
        return self._pi(v_hat, lam, lam_ref, _equilibrium_torque(self._feedforward_mu(values, lam_ref), lam_ref, p))

    def _feedforward_mu(self, values: dict, lam_ref: np.ndarray) -> np.ndarray:
        """The friction the feedforward holds the reference slip at: the one the accelerometer measures,
        ``-m a_x / F_z``."""
        p = self.spec.params
        return np.maximum(-p.m * values[FIELD_AX] / p.Fz, 0.0)


class OracleSlipController(_GainScheduledSlip):
    """Slip controller with perfect knowledge: true speed and slip, and the true road's peak (upper bound).

    Tracks :func:`slip_reference` of the road under the car (after a friction change, the new road), with the
    exact equilibrium torque ``T_eq(mu(lambda_ref), lambda_ref)`` as feedforward.

    :param env_or_spec: env, BrakingSim or ControlSpec (needs ``observation="oracle"``).
    :param road_fn: callable returning the road under the car now, or for a batch a sequence of roads; with an
        env, defaults to ``lambda: env.unwrapped.road``.
    :param gains: PI gains.
    """

    name = "oracle-slip"
    needs = (FIELD_V, FIELD_SLIP)

    def __init__(self, env_or_spec, road_fn: Callable[[], Any] | None = None,
                 gains: SlipControllerParams | None = None):
        super().__init__(env_or_spec, gains)
        if road_fn is None:
            if not hasattr(env_or_spec, "unwrapped"):
                raise ValueError("OracleSlipController needs road_fn when not given an env")
            base = env_or_spec.unwrapped
            road_fn = lambda: base.road
        self.road_fn = road_fn

    def _torque(self, obs, torque_now):
        roads = self.road_fn()
        roads = [roads] if isinstance(roads, MagicFormula) else list(roads)
        ref = np.array([slip_reference(road) for road in roads])
        lam_ref, mu_ref = ref[:, 0], ref[:, 1]
        v = self.reader.get(obs, FIELD_V)
        lam = self.reader.get(obs, FIELD_SLIP)
        return self._pi(v, lam, lam_ref, _equilibrium_torque(mu_ref, lam_ref, self.spec.params))


CONTROLLERS = ("oracle-slip", "slip-pi", "rule-abs", "locked")


def make_controller(name: str, env) -> Controller:
    """A controller by name for a ``Braking-v0`` env (oracle-slip and slip-pi need ``observation="oracle"``)."""
    if name == "oracle-slip":
        return OracleSlipController(env)
    if name == "slip-pi":
        return SlipController(env, OracleSource.from_env(env))
    if name == "rule-abs":
        return RuleBasedABS(env)
    if name == "locked":
        return FullBraking(env)
    raise ValueError(f"unknown controller {name!r}; valid: {', '.join(CONTROLLERS)}")


@dataclass
class Rollout:
    """One braking episode: the final info dict and per-step traces (true values, SI units)."""

    info: dict[str, Any]
    t: np.ndarray  # time [s]
    v: np.ndarray  # vehicle speed [m/s]
    wheel: np.ndarray  # wheel circumferential speed omega r [m/s]
    slip: np.ndarray  # slip [-]
    torque: np.ndarray  # applied brake torque [N m]
    total_reward: float


def rollout(env, controller: Controller, seed: int | None = None, options: dict | None = None) -> Rollout:
    """Run one episode of ``controller`` on a ``Braking-v0`` env and record the true traces.

    :param env: the env (wrapped or not).
    :param controller: a controller made for this env.
    :param seed: reset seed.
    :param options: reset options.
    """
    obs, info = env.reset(seed=seed, options=options)
    controller.reset()
    r = env.unwrapped.config.params.r
    rows = [(info["time"], info["v"], info["v"], info["slip"], info["torque"])]
    total = 0.0
    while True:
        obs, reward, terminated, truncated, info = env.step(controller.act(obs))
        total += reward
        rows.append((info["time"], info["v"], float(env.unwrapped.sim.omega[0]) * r, info["slip"], info["torque"]))
        if terminated or truncated:
            break
    t, v, wheel, slip, torque = (np.array(col) for col in zip(*rows))
    return Rollout(info=info, t=t, v=v, wheel=wheel, slip=slip, torque=torque, total_reward=total)
