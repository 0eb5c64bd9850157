"""Estimator-augmented observations: run an estimator inside the env and append its outputs.

:class:`EstimatorObservation` wraps ``fricenv/Braking-v0``. At every control step it feeds the estimator the
signals an ECU has (the measured wheel speed ``omega``, the commanded brake torque ``T_b`` and, if the estimator
asks for it, the measured longitudinal acceleration ``a_x``; matched by the estimator's ``measurement_columns``
and ``input_columns``) and appends the estimate to the observation:

==========  ======  =========  =====  =====  ===============================================================
name        unit    scale      min    max    value
==========  ======  =========  =====  =====  ===============================================================
v_hat       m/s     50         0      2      estimated vehicle speed
slip_hat    -       1          -1     1      estimated wheel slip
mu_hat      -       1          -2     2      estimated friction coefficient in use
theta_hat   -       1          0      2      estimated road coefficient theta (peak factor of the Magic Formula)
peak_slip_  -       1          0      1      estimated slip of the friction peak (``peak_slip_hat``; estimators that
hat                                          report one: ``ekf-rls`` with its curve-shape fit, and the oracle; while
                                             the fit cannot tell far-apart peaks apart, the slip that keeps most
                                             friction on the worst plausible curve, (S5) of
                                             :mod:`estimators.curve_shape`)
health      -       1          0      5      :class:`estimators.base.Health` of the last update (0 = OK, 4 = OUTLIER,
                                             5 = REINITIALISED, for ``ekf-rls`` also a friction jump,
                                             :mod:`estimators.jump`)
==========  ======  =========  =====  =====  ===============================================================

Timing. The estimator interface's ``update(y_k, u_k)`` takes the torque *held from k to k+1*, which is known only
once it has been commanded, so after the env step k -> k+1 the wrapper updates with ``(y_k, T_k)`` and gets
``x(k|k)``. The appended ``v_hat`` is that speed advanced to k+1 with the measured acceleration,
``v_hat = v(k|k) + dt a_x,m(k+1)`` (the accelerometer reads the speed change over the step, so this removes the
one-sample lag of the speed, ``|a| dt`` = up to 0.1 m/s); ``slip_hat``, ``mu_hat`` and ``theta_hat`` are the
estimate at k (one sample, 10 ms, old). At reset the estimator starts from the free-rolling speed measured by the
wheel (``v = omega_m r``, slip 0); one whose speed integrates ``a_x`` (``ekf-ax``, ``mhe-ax``) is also told that
speed's spread, one wheel sample's noise times r (:func:`estimators.base.reset_from_wheel`).

Estimators (:data:`ESTIMATOR_NAMES`; each is an entry of :data:`estimators.registry.ESTIMATORS` built with the
env's own plant parameters and sample time): ``ekf`` (:class:`estimators.ekf.QuarterCarEKF`, theta augmented),
``mhe`` (:class:`estimators.mhe.RegularizedMHE`, theta augmented), ``ekf-rls``
(:class:`estimators.ekf_rls.QuarterCarEkfRls`, which also uses ``a_x``; its ``mu_utilized`` fills ``mu_hat`` and
its peak-friction estimate ``mu`` fills ``theta_hat``, as its registry entry's ``values`` say; its ``peak_slip``,
from the online curve-shape fit of :mod:`estimators.curve_shape`, fills ``peak_slip_hat``), and ``ekf-full`` /
``mhe-full`` (theta, B, C, E augmented, Sui & Johansen's cases 3-4; the appended layout is the same, B, C, E are
in ``info`` of the estimate, ``EstimatorObservation.last_estimate``), and ``ekf-ax`` / ``mhe-ax`` (the EKF and the
MHE whose car speed follows the measured acceleration, ``v' = a_x``: their input over the step k -> k+1 is the torque
held over it and the a_x measured over it, the a_x of the observation at k+1). An unknown name raises ValueError
listing the choices.

``oracle`` appends the truth in the same layout (true speed, slip, friction, the theta and peak slip of the road
under the car, health 0): an upper bound. ``none`` appends nothing (use the env as it is).

A failed update never raises inside ``step``: the estimator's own fallback (held values, health flag) is used; if
an estimator raises anyway, or returns non-finite values, the last good values are held and ``health`` is
``SOLVER_FAILED`` (a warning is issued once per wrapper).

:class:`PayloadEstimatorObservation` does the same for ``fricenv/PayloadExcitation-v0`` with the oracle: it appends
the true calibration matrix ``S`` (9 entries); the RLS estimate of ``S`` (the env's own ``estimator="rls"``) runs
inside the env at 1 ms and needs no wrapper (see :mod:`fricenv.envs.factory`).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorWrapper
from gymnasium.vector.utils import batch_space

from estimators.base import Estimate, Estimator, Health, reset_from_wheel
from estimators.registry import OBSERVATION_ESTIMATORS, check_name, get_estimator
from fricenv.envs.config import ObsField
from fricenv.plants.quarter_car import QuarterCarParams

__all__ = [
    "ESTIMATE_FIELDS",
    "ESTIMATOR_NAMES",
    "PAYLOAD_ORACLE_FIELDS",
    "BatchedEstimatorObservation",
    "EstimatorObservation",
    "PayloadEstimatorObservation",
    "batched_names",
    "check_estimator_name",
    "make_estimator",
]

SPEED_SCALE = 50.0  # [m/s per observation unit], as the env's oracle entry
HEALTH_MAX = float(max(Health))
# Appended entries, in order, keyed by the standard quantity they carry (estimators.registry: EstimatorEntry.values).
ESTIMATE_FIELDS: dict[str, ObsField] = {
    "v": ObsField("v_hat", "m/s", SPEED_SCALE, 0.0, 2.0, "estimated vehicle speed"),
    "slip": ObsField("slip_hat", "-", 1.0, -1.0, 1.0, "estimated wheel slip"),
    "mu": ObsField("mu_hat", "-", 1.0, -2.0, 2.0, "estimated friction coefficient in use"),
    "theta": ObsField("theta_hat", "-", 1.0, 0.0, 2.0, "estimated road coefficient theta"),
    "peak_slip": ObsField("peak_slip_hat", "-", 1.0, 0.0, 1.0, "estimated slip of the friction curve's peak"),
}
HEALTH_FIELD = ObsField("health", "-", 1.0, 0.0, HEALTH_MAX, "estimator health flag (0 = OK)")
# Measured signals the wrapper can feed an estimator: estimator column name -> env observation entry.
MEASURED_COLUMNS = {"omega": "wheel_speed", "a_x": "a_x"}
# Inputs it can feed: the commanded torque held over the step, and the acceleration measured over that step (the
# a_x of the observation after it: the speed change over the step, :func:`fricenv.envs.episode.measure`).
INPUT_COLUMNS = ("T_b", "a_x")
# Observation choices: "none" appends nothing, "oracle" appends the truth, the others run a registered estimator.
NO_ESTIMATOR = "none"
ORACLE = "oracle"
ESTIMATOR_NAMES: tuple[str, ...] = (NO_ESTIMATOR,) + OBSERVATION_ESTIMATORS + (ORACLE,)


def check_estimator_name(name: str, valid: tuple[str, ...] = ESTIMATOR_NAMES) -> str:
    """Return ``name`` if it is a valid estimator choice, else raise ValueError listing the choices."""
    return check_name(name, valid)


def make_estimator(name: str, dt: float, params: QuarterCarParams) -> Estimator | None:
    """A fresh estimator by name (None for ``none`` and ``oracle``), built for the env's plant.

    :param name: one of :data:`ESTIMATOR_NAMES`.
    :param dt: sample time [s].
    :param params: the env's vehicle parameters (the estimator's model uses its m, J, r, F_z).
    """
    if check_estimator_name(name) in (NO_ESTIMATOR, ORACLE):
        return None
    return get_estimator(name).make(params, dt)


def batched_names() -> tuple[str, ...]:
    """Estimator names with a batched form (:data:`estimators.batched.BATCHED`: the EKF/RLS variants and the MHE)."""
    from estimators.batched import BATCHED

    return tuple(BATCHED)


class EstimatorObservation(gym.Wrapper):
    """Append an estimator's outputs (``v_hat``, ``slip_hat``, ``mu_hat``, ``theta_hat``, ``health``) to the
    observation of a ``fricenv/Braking-v0`` env (see the module docstring for layout and timing).

    The wrapped layout is available as ``observation_fields`` (and ``decode_observation(obs)``), the env's own
    fields followed by the appended ones, so name-based controllers (:class:`agents.controllers.ObsReader`) read
    it. ``info["estimate"]`` carries the appended values in physical units every step.

    :param env: a ``Braking-v0`` env (possibly wrapped) whose observation has ``wheel_speed``, ``torque``, ``a_x``.
    :param estimator: ``"ekf"``, ``"mhe"``, ``"ekf-rls"`` or ``"oracle"`` (``"none"`` is rejected: do not wrap).
    :param estimator_factory: optional factory ``(dt, params) -> Estimator`` overriding the registry (tests,
        custom tuning); ``estimator`` is then only the label.
    """

    def __init__(self, env: gym.Env, estimator: str = "ekf",
                 estimator_factory: Callable[[float, QuarterCarParams], Estimator] | None = None):
        super().__init__(env)
        if estimator_factory is None:
            check_estimator_name(estimator)
            if estimator == NO_ESTIMATOR:
                raise ValueError("estimator 'none' appends nothing: use the env unwrapped "
                                 f"(valid here: {', '.join(n for n in ESTIMATOR_NAMES if n != NO_ESTIMATOR)})")
        elif not callable(estimator_factory):
            raise TypeError(f"estimator_factory must be callable (dt, params) -> Estimator, "
                            f"got {type(estimator_factory).__name__}")
        base = env.unwrapped
        if not hasattr(base, "sim") or not hasattr(base, "observation_fields"):
            raise TypeError(f"EstimatorObservation wraps fricenv/Braking-v0, got {type(base).__name__}")
        self.estimator_name = estimator
        self._factory = estimator_factory
        self._dt = float(base.config.dt)
        self._params = base.config.params
        self._base_fields: tuple[ObsField, ...] = tuple(base.observation_fields)
        self._index = {f.name: j for j, f in enumerate(self._base_fields)}
        missing = [n for n in ("wheel_speed", "a_x") if n not in self._index]
        if missing:
            raise ValueError(f"the env observation lacks {missing}; has {list(self._index)}")
        self._estimator: Estimator | None = None
        self._estimator = self._build()
        self._value_names = dict(get_estimator(estimator).values) \
            if estimator_factory is None and self._estimator is not None else {}
        if self._estimator is None:  # oracle
            self._names: tuple[str, ...] = tuple(ESTIMATE_FIELDS)
        else:
            self._check_columns(self._estimator)
            self._names = tuple(n for n in ESTIMATE_FIELDS
                                if self._value_names.get(n, n) in self._estimator.names)
            if "v" not in self._names:
                raise ValueError(f"estimator {estimator!r} must estimate 'v'; its values: {self._estimator.names}")
        self.appended_fields: tuple[ObsField, ...] = tuple(ESTIMATE_FIELDS[n] for n in self._names) \
            + (HEALTH_FIELD,)
        self.observation_fields: tuple[ObsField, ...] = self._base_fields + self.appended_fields
        self.observation_names = tuple(f.name for f in self.observation_fields)
        self._scale = np.array([f.scale for f in self.appended_fields])
        self._low = np.array([f.low for f in self.appended_fields])
        self._high = np.array([f.high for f in self.appended_fields])
        inner = env.observation_space
        self.observation_space = spaces.Box(
            low=np.concatenate([inner.low, self._low.astype(np.float32)]).astype(np.float32),
            high=np.concatenate([inner.high, self._high.astype(np.float32)]).astype(np.float32),
            dtype=np.float32)
        self._last_obs: np.ndarray | None = None
        self._last_values: dict[str, float] = {}
        self._warned = False
        self.last_estimate: Estimate | None = None  # the last good Estimate (all its values, e.g. B, C, E)

    # ------------------------------------------------------------------ estimator plumbing
    def _build(self) -> Estimator | None:
        if self._factory is not None:
            return self._factory(self._dt, self._params)
        return make_estimator(self.estimator_name, self._dt, self._params)

    def _check_columns(self, est: Estimator) -> None:
        bad = [c for c in est.measurement_columns if c not in MEASURED_COLUMNS]
        bad += [c for c in est.input_columns if c not in INPUT_COLUMNS]
        if bad:
            raise ValueError(f"estimator {self.estimator_name!r} needs columns {bad} the braking env does not "
                             f"measure; available: {', '.join(MEASURED_COLUMNS)}, {', '.join(INPUT_COLUMNS)}")

    @property
    def estimator(self) -> Estimator | None:
        """The estimator instance (None for the oracle); rebuilt lazily after unpickling."""
        if self._estimator is None and self.estimator_name != ORACLE:
            self._estimator = self._build()
        return self._estimator

    def _measured(self, obs: np.ndarray, name: str) -> float:
        j = self._index[name]
        return float(obs[j]) * self._base_fields[j].scale

    def _truth(self, info: dict[str, Any]) -> Estimate:
        road = self.env.unwrapped.road
        return Estimate({"v": info["v"], "slip": info["slip"], "mu": info["mu"], "theta": float(road.theta),
                         "peak_slip": float(road.peak_slip)}, Health.OK)

    def _safe(self, call: Callable[[], Estimate]) -> tuple[dict[str, float], int]:
        """Values and health of an estimator call; never raises, holds the last values on failure."""
        try:
            est = call()
            values = {n: float(np.asarray(est.values[self._value_names.get(n, n)], dtype=float))
                      for n in self._names}
            health = int(est.health)
            if not all(np.isfinite(list(values.values()))):
                raise FloatingPointError("non-finite estimate")
            self.last_estimate = est
        except Exception as exc:  # noqa: BLE001 - an env step must not die on an estimator failure
            if not self._warned:
                warnings.warn(f"estimator {self.estimator_name!r} failed ({type(exc).__name__}: {exc}); holding "
                              f"its last values with health SOLVER_FAILED", RuntimeWarning, stacklevel=3)
                self._warned = True
            values = dict(self._last_values) or {n: 0.0 for n in self._names}
            health = int(Health.SOLVER_FAILED)
        return values, health

    def _augment(self, obs: np.ndarray, values: dict[str, float], health: int) -> np.ndarray:
        self._last_values = values
        raw = np.array([values[n] for n in self._names] + [float(health)])
        extra = np.clip(raw / self._scale, self._low, self._high)
        return np.concatenate([np.asarray(obs, dtype=np.float32), extra.astype(np.float32)])

    def _estimate_info(self, values: dict[str, float], health: int) -> dict[str, float]:
        out = {f"{n}_hat": values[n] for n in self._names}
        out["health"] = health
        return out

    # ------------------------------------------------------------------ Gymnasium API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._warned = False
        self._last_values = {}
        self.last_estimate = None
        if self.estimator_name == ORACLE and self._factory is None:
            values, health = self._safe(lambda: self._truth(info))
        else:
            est = self.estimator
            v0 = self._measured(obs, "wheel_speed") * self._params.r
            v_std = float(np.sqrt(self.env.unwrapped.config.omega_noise_var)) * self._params.r  # the sample's spread
            values, health = self._safe(lambda: reset_from_wheel(est, v0, v_std))
        self._last_obs = np.asarray(obs)
        info = dict(info, estimate=self._estimate_info(values, health))
        return self._augment(obs, values, health), info

    def step(self, action):
        if self._last_obs is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self.estimator_name == ORACLE and self._factory is None:
            values, health = self._safe(lambda: self._truth(info))
        else:
            est, prev = self.estimator, self._last_obs
            y = [self._measured(prev, MEASURED_COLUMNS[c]) for c in est.measurement_columns]
            u = [float(info["torque"]) if c == "T_b" else self._measured(obs, "a_x") for c in est.input_columns]
            values, health = self._safe(lambda: est.update(y, u))
            if "v" in values:  # advance x(k|k) to k+1 with the measured speed change over the step
                values = dict(values, v=values["v"] + self._dt * self._measured(obs, "a_x"))
        self._last_obs = np.asarray(obs)
        info = dict(info, estimate=self._estimate_info(values, health))
        return self._augment(obs, values, health), reward, terminated, truncated, info

    def decode_observation(self, obs) -> dict[str, float]:
        """Physical values of a wrapped observation, by name."""
        obs = np.asarray(obs, dtype=float)
        return {f.name: float(obs[j] * f.scale) for j, f in enumerate(self.observation_fields)}

    def __getstate__(self):
        state = self.__dict__.copy()
        state["_estimator"] = None  # compiled solvers are rebuilt on the other side
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)


# ---------------------------------------------------------------------------------------------- vector env
class BatchedEstimatorObservation(VectorWrapper):
    """:class:`EstimatorObservation` for the native vector env: one batched estimator
    (:mod:`estimators.batched`, :mod:`estimators.mhe_batched`) updates every sub-env in one numpy call, with the
    single wrapper's layout and timing, in every autoreset mode (an autoreset restarts that sub-env's estimator from its new wheel speed; in
    ``SAME_STEP`` mode ``final_obs`` carries the last update). Sub-env ``i`` equals an :class:`EstimatorObservation`
    fed the same observations (tests/test_batched_vector.py).

    :param env: a :class:`fricenv.envs.braking_vector.BrakingVectorEnv`.
    :param estimator: a registry name with a batched form (:func:`batched_names`: the EKF/RLS variants of
        :data:`estimators.batched.BATCHED`, ``mhe`` and ``mhe-full``).
    """

    def __init__(self, env, estimator: str = "ekf-rls"):
        super().__init__(env)
        from estimators.batched import make_batched

        check_estimator_name(estimator)
        cfg = env.config
        self.estimator_name = estimator
        self.batched = make_batched(estimator, env.num_envs, cfg.params, cfg.dt)
        if self.batched is None:
            raise ValueError(f"estimator {estimator!r} has no batched form; batched: {', '.join(batched_names())} "
                             f"(use make_vec's SyncVectorEnv fallback for the others)")
        self._dt, self._r = float(cfg.dt), float(cfg.params.r)
        value_names = get_estimator(estimator).values
        self._keys = tuple((n, value_names.get(n, n)) for n in ESTIMATE_FIELDS
                           if value_names.get(n, n) in self.batched.names)
        base = tuple(env.observation_fields)
        self._iw = next(j for j, f in enumerate(base) if f.name == "wheel_speed")
        self._iax = next(j for j, f in enumerate(base) if f.name == "a_x")
        self._scale_w, self._scale_ax = base[self._iw].scale, base[self._iax].scale
        self.appended_fields = tuple(ESTIMATE_FIELDS[n] for n, _ in self._keys) + (HEALTH_FIELD,)
        self.observation_fields = base + self.appended_fields
        self._scale = np.array([f.scale for f in self.appended_fields])
        self._low = np.array([f.low for f in self.appended_fields])
        self._high = np.array([f.high for f in self.appended_fields])
        inner = env.single_observation_space
        self.single_observation_space = spaces.Box(
            np.concatenate([inner.low, self._low.astype(np.float32)]),
            np.concatenate([inner.high, self._high.astype(np.float32)]), dtype=np.float32)
        self.observation_space = batch_space(self.single_observation_space, env.num_envs)
        self._last_obs: np.ndarray | None = None
        self._extra = np.zeros((env.num_envs, len(self.appended_fields)))
        self._pending = np.zeros(env.num_envs, dtype=bool)

    sim = property(lambda self: self.env.sim)
    config = property(lambda self: self.env.config)
    autoreset_mode = property(lambda self: self.env.autoreset_mode)

    def _set(self, rows: np.ndarray, values: dict, health: np.ndarray, a_x: np.ndarray | None = None) -> None:
        """Store the appended values of ``rows`` (physical units; v advanced by dt a_x when given)."""
        cols = [values[k] + (self._dt * a_x if a_x is not None and n == "v" else 0.0) for n, k in self._keys]
        raw = np.column_stack(cols + [health.astype(float)])
        good = np.all(np.isfinite(raw), axis=1)
        raw[~good, -1] = float(Health.SOLVER_FAILED)  # non-finite estimate: hold the last values, say so
        raw[~good, :-1] = self._extra[~good, :-1]
        self._extra[rows] = raw[rows]

    def _augment(self, obs: np.ndarray, rows: slice | np.ndarray = slice(None)) -> np.ndarray:
        extra = np.clip(self._extra[rows] / self._scale, self._low, self._high).astype(np.float32)
        return np.concatenate([np.asarray(obs, dtype=np.float32), extra], axis=-1)

    def _restart(self, obs: np.ndarray, rows: np.ndarray) -> None:
        v0 = obs[:, self._iw].astype(float) * self._scale_w * self._r
        self._set(rows, *self.batched.reset(rows, v0))

    def reset(self, *, seed=None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        mask = (options or {}).get("reset_mask")
        rows = np.ones(self.num_envs, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        self._restart(obs, rows)
        self._pending[rows] = False
        self._last_obs = np.asarray(obs).copy()
        return self._augment(obs), info

    def step(self, actions):
        if self._last_obs is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        obs, reward, terminated, truncated, infos = self.env.step(actions)
        torque, after = np.array(infos["torque"], dtype=float), np.asarray(obs)
        done = terminated | truncated
        same_step = self.env.autoreset_mode is AutoresetMode.SAME_STEP and done.any()
        if same_step:  # the ended episodes' last step: their final torque and observation
            torque[done] = infos["final_info"]["torque"][done]
            after = after.copy()
            after[done] = np.stack(infos["final_obs"][done])
        prev = self._last_obs
        omega = prev[:, self._iw].astype(float) * self._scale_w
        a_x = prev[:, self._iax].astype(float) * self._scale_ax
        values, health = self.batched.update(omega, a_x, torque)
        live = ~self._pending
        self._set(live, values, health, after[:, self._iax].astype(float) * self._scale_ax)
        if same_step:
            final = self._augment(after[done], done)
            infos["final_obs"] = infos["final_obs"].copy()
            for j, i in enumerate(np.flatnonzero(done)):
                infos["final_obs"][i] = final[j]
            self._restart(np.asarray(obs), done)
        if self._pending.any():  # NEXT_STEP: these sub-envs were reset by this step
            self._restart(np.asarray(obs), self._pending)
        self._pending = done & (self.env.autoreset_mode is AutoresetMode.NEXT_STEP)
        self._last_obs = np.asarray(obs).copy()
        return self._augment(obs), reward, terminated, truncated, infos


# ---------------------------------------------------------------------------------------------- payload
PAYLOAD_ORACLE_FIELDS: tuple[ObsField, ...] = tuple(
    ObsField(f"S_{i}{j}", "-", 1.0, -10.0, 10.0, f"true calibration entry S[{i},{j}]")
    for i in range(3) for j in range(3))


class PayloadEstimatorObservation(gym.ObservationWrapper):
    """Append the true calibration matrix ``S`` (row-major, 9 entries, clipped to [-10, 10]) to the observation
    of ``fricenv/PayloadExcitation-v0``: the ``oracle`` observation, an upper bound for excitation policies.

    :param env: a ``PayloadExcitation-v0`` env.
    """

    def __init__(self, env: gym.Env):
        super().__init__(env)
        base = env.unwrapped
        if not hasattr(base, "rls") or not hasattr(base, "observation_fields"):
            raise TypeError(f"PayloadEstimatorObservation wraps fricenv/PayloadExcitation-v0, "
                            f"got {type(base).__name__}")
        self.estimator_name = "oracle"
        self.observation_fields = tuple(base.observation_fields) + PAYLOAD_ORACLE_FIELDS
        low = np.array([f.low for f in PAYLOAD_ORACLE_FIELDS], dtype=np.float32)
        high = np.array([f.high for f in PAYLOAD_ORACLE_FIELDS], dtype=np.float32)
        inner = env.observation_space
        self.observation_space = spaces.Box(np.concatenate([inner.low, low]), np.concatenate([inner.high, high]),
                                            dtype=np.float32)
        self._low, self._high = low, high

    def observation(self, observation):
        S = np.asarray(self.env.unwrapped.S, dtype=np.float32).reshape(9)
        return np.concatenate([np.asarray(observation, dtype=np.float32), np.clip(S, self._low, self._high)])
