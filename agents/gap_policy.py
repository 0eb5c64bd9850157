"""Policy-level sim-to-real gap (issue 6, item 4): how far the simulator's prediction of a controller's stopping
distance is off on the "real" plant, before and after the diagnosed effect is added to the simulator.

For a controller (``rule-abs``, ``slip-pi``, ``oracle-slip``, ``locked``), an estimator pipeline
(``pipeline:<estimator>``) or a saved SB3 policy (a training run directory), :func:`policy_gap` measures the
stopping distance, averaged over noise seeds (the same seeds in every simulator, so the measurement noise is equal):

1. in the **nominal** simulator (the quarter car of :mod:`fricenv.plants.quarter_car`, no effect);
2. on the **real stand-in** (the plant with the given effects, integrated twice as finely as the models, as
   ``fricenv gap simulate`` does); or, for a real log, nothing: only its diagnosis report is given;
3. in the **augmented** simulator: the nominal one plus the diagnosed effect with its fitted parameters. The typical
   flow: the controller brakes the stand-in once more with a free-rolling start and that run is logged (DESIGN.md
   log format); :func:`fricenv.gap.diagnose.diagnose` names the effect and fits it; or the verdict and parameters
   come from a ``report.json``.

``prediction_error_before = (d_nominal - d_real) / d_real`` and ``prediction_error_after = (d_augmented - d_real) /
d_real`` (signed shares) say how far the simulator's prediction of the real stopping distance was off. Optionally
a controller parameter is retuned on a small grid in the augmented simulator (and, for comparison, in the nominal
one) and each choice is measured on the stand-in: the real-side gain of tuning in the augmented simulator.

Closed loop. :class:`EffectBrakingEnv` is ``fricenv/Braking-v0``'s interface (action, observation layout and
scaling of :func:`fricenv.envs.braking_core.observation_layout`, measurement model, noise stream, ``info``) over
the effect simulator :class:`fricenv.effects.quarter_car.EffectSimulator`: every 10 ms the controller's command is
held on the effect-augmented plant, which does the actuator effects, the Magic Formula and the integration (none of
it is re-implemented here). ``BrakingSim`` itself cannot be driven with another plant (its substep kernel is
internal), so the ECU measurement model is rebuilt from the same constants (``BrakingConfig``) and the same noise
stream (blocks of ``NOISE_BLOCK`` standard normals from the reset seed's generator): with no effect and no
free-rolling start it gives ``Braking-v0``'s trajectory for the same seed (checked in the tests). Being a Gymnasium
env with ``observation_fields``, ``config``, ``road`` and ``sim``, it takes the estimator wrapper
:class:`fricenv.envs.estimator_observation.EstimatorObservation`, so estimator pipelines and SB3 policies trained
with an estimator see the observation they were trained on.

Time base. Each run starts with ``free_roll`` seconds of free rolling (zero torque; the log's free-rolling stretch),
then the controller brakes from ``v0``; time 0 (``mu_change``'s ``t_change``) is the start of the free roll, and the
stopping distance is counted from the brake onset to ``v_stop`` (the env's, 2 m/s).
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from agents.controllers import (
    CONTROLLERS,
    ControlSpec,
    FullBraking,
    OracleSlipController,
    OracleSource,
    RuleABSParams,
    RuleBasedABS,
    SlipController,
    slip_reference,
)
from fricenv.effects.quarter_car import (
    DEFAULT_SUBSTEPS,
    EFFECTS,
    EffectSimulator,
    ModelBatch,
    effect_params,
    make_effect,
)
from fricenv.envs import braking_core as core
from fricenv.gap.simulate import STAND_IN_SUBSTEPS, V_END, NoiseSpec
from fricenv.logs import QuarterCarLog
from fricenv.plants.tire import MagicFormula, get_road, longitudinal_slip

__all__ = [
    "FREE_ROLL",
    "RETUNE",
    "EffectBrakingEnv",
    "GapPolicy",
    "UnknownPolicyError",
    "closed_loop_log",
    "format_table",
    "policy_gap",
    "resolve_policy",
    "stopping_distances",
]

FREE_ROLL = 0.4  # free-rolling stretch before the brake onset [s] (gap simulate draws 0.3-0.6 s)
DEFAULT_SEEDS = 10  # noise seeds averaged over: rule-abs under an actuator effect has a bimodal distance
V0 = core.V0_DEFAULT  # initial speed [m/s], the ABS figure's 20 m/s
LOG_MAX_TIME = 8.0  # longest closed-loop log handed to the diagnosis [s] (snow from 20 m/s takes ~7 s)
LOG_STREAM = 0x6C6F67  # seed-sequence key of the log-only noise (v, a_x columns, free-roll wheel speed)
PIPELINE_PREFIX = "pipeline:"
# Retune grids: controller -> (parameter, values). rule-abs: the excess wheel deceleration that starts a dump from
# hold [m/s^2] (under a brake lag it decides how deep the wheel goes past the peak); slip-pi: the slip reference as
# a multiple of the road's peak slip [-].
RETUNE: dict[str, tuple[str, tuple[float, ...]]] = {
    "rule-abs": ("decel_dump", (15.0, 20.0, 25.0, 32.0, 40.0)),
    "slip-pi": ("slip_ref_factor", (0.6, 0.8, 1.0, 1.2, 1.4)),
}


class UnknownPolicyError(ValueError):
    """A policy spec that is neither a controller, an estimator pipeline nor a training run directory."""


# --------------------------------------------------------------------------------------------- closed-loop env
class EffectBrakingEnv(gym.Env):
    """``Braking-v0``'s observation and action interface over the effect-augmented quarter car (one car).

    :param road: road preset name or :class:`~fricenv.plants.tire.MagicFormula` (the road before any ``mu_change``).
    :param effects: effect specs (:func:`fricenv.effects.quarter_car.make_effect`); empty for the nominal plant.
    :param config: the env constants (action mode, observation mode, noise, stop speed, time limit).
    :param v0: initial speed [m/s].
    :param free_roll: free-rolling stretch before the brake onset [s].
    :param substeps: physics substeps per 10 ms sample of the effect simulator.
    :param record: keep the log rows (:meth:`log`) of each episode.
    :param log_noise: noise of the log's ``v`` and ``a_x`` columns (and of the free-roll wheel speed, whose
        noise is the env's wheel-speed noise).
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": []}

    def __init__(self, road: str | MagicFormula = "dry", effects: Sequence = (),
                 config: core.BrakingConfig | None = None, v0: float = V0, free_roll: float = FREE_ROLL,
                 substeps: int = DEFAULT_SUBSTEPS, record: bool = False, log_noise: NoiseSpec | None = None):
        self.config = config if config is not None else core.BrakingConfig()
        c = self.config
        self.road_a = road if isinstance(road, MagicFormula) else get_road(road)
        self.effects = tuple(effects)
        if not math.isfinite(v0) or v0 <= c.v_stop:
            raise ValueError(f"v0 must be finite and > v_stop={c.v_stop} m/s, got {v0!r}")
        if not math.isfinite(free_roll) or free_roll < 0:
            raise ValueError(f"free_roll must be finite and >= 0 s, got {free_roll!r}")
        self.v0, self.free_roll, self.substeps, self.record = float(v0), float(free_roll), int(substeps), record
        self.log_noise = log_noise if log_noise is not None else NoiseSpec()
        self.batch = ModelBatch.from_effects(self.road_a, self.effects, c.params)
        self.free_steps = round(self.free_roll / c.dt)
        self.observation_fields = core.observation_layout(c.observation)
        self.observation_names = tuple(f.name for f in self.observation_fields)
        # Observation scaling of BrakingSim: the torque entry is T_b / t_max.
        self._scale = np.array([f.scale for f in self.observation_fields])
        self._scale[self.observation_names.index("torque")] *= c.t_max
        self._low = np.array([f.low for f in self.observation_fields])
        self._high = np.array([f.high for f in self.observation_fields])
        self._noise_std = np.array([math.sqrt(c.omega_noise_var), c.decel_noise_std, c.ax_noise_std])
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.observation_space = spaces.Box(low=self._low.astype(np.float32), high=self._high.astype(np.float32),
                                            dtype=np.float32)
        self.sim: EffectSimulator | None = None
        self.torque = np.zeros(1)  # last command [N m] (an array: BrakingSim.command_to_torque's state)
        self._rows: dict[str, list[float]] = {}

    # ------------------------------------------------------------------ helpers
    @property
    def road(self) -> MagicFormula:
        """The road under the car now (theta switched after a ``mu_change``)."""
        b = self.batch
        if self.sim is not None and math.isfinite(b.t_change[0]) and self._t_log() >= b.t_change[0]:
            return replace(self.road_a, theta=float(b.theta_after[0]), name=f"{self.road_a.name}*")
        return self.road_a

    def _t_log(self) -> float:
        return float(self.sim.k[0]) * self.config.dt

    def _next_noise(self) -> np.ndarray:
        """The next (scaled) noise row of the car's stream, BrakingSim's block scheme."""
        if self._noise_idx >= core.NOISE_BLOCK:
            self._noise = self.np_random.standard_normal((core.NOISE_BLOCK, core.N_NOISE))
            self._noise_idx = 0
        row = self._noise[self._noise_idx] * self._noise_std
        self._noise_idx += 1
        return row

    def _truth(self) -> tuple[float, float, float]:
        """(v, slip, mu in use) of the plant now."""
        sim, p = self.sim, self.config.params
        v, w = float(sim.v[0]), float(sim.omega[0])
        slip = float(longitudinal_slip(v, w, float(self.batch.r_eff[0])))
        return v, slip, float(sim.tire_force()[0]) / p.Fz

    def _observe(self) -> np.ndarray:
        vals = [self.meas[0], self.meas[1], float(self.torque[0]), self.meas[2]]
        if self.config.observation == "oracle":
            vals += list(self._truth())
        return np.clip(np.array(vals) / self._scale, self._low, self._high).astype(np.float32)

    def _log_row(self, torque: float, omega_meas: float) -> None:
        if not self.record:
            return
        sim, ln = self.sim, self.log_noise
        self._rows["t"].append(self._t_log())
        self._rows["T_b"].append(torque)
        self._rows["omega"].append(omega_meas)
        self._rows["v"].append(float(sim.v[0]) + ln.v_std * float(self._log_rng.standard_normal()))
        self._rows["a_x"].append(float(sim.accel()[0]) + ln.a_x_std * float(self._log_rng.standard_normal()))

    def _info(self) -> dict[str, Any]:
        v, slip, mu = self._truth()
        c = self.config
        info = {"v": v, "slip": slip, "mu": mu, "distance": self.x, "road": self.road.name,
                "torque": float(self.torque[0]), "locked": self.lock_count > c.lock_steps,
                "time": self.steps * c.dt}
        if self.stopped or self.steps >= c.max_steps:
            info.update(stopping_distance=self.stop_distance, stopped=self.stopped, lock_seen=self.lock_seen,
                        limit_distance=self.limit, ratio=self.stop_distance / self.limit, v0=self.v0)
        return info

    # ------------------------------------------------------------------ Gymnasium API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Free-roll for ``free_roll`` seconds, then return the first observation of the braking episode."""
        super().reset(seed=seed)
        if options:
            raise ValueError(f"EffectBrakingEnv takes no reset options, got {sorted(options)}")
        c, p = self.config, self.config.params
        # Log-only noise from a child of the seed sequence: the measurement stream is the one Braking-v0 draws.
        self._log_rng = np.random.default_rng(self.np_random.bit_generator.seed_seq.spawn(1)[0])
        self._noise = self.np_random.standard_normal((core.NOISE_BLOCK, core.N_NOISE))
        self._noise_idx = 0
        n_samples = self.free_steps + c.max_steps + 1
        self.sim = EffectSimulator(self.batch, c.dt, n_samples, p, self.substeps, t0=0.0)
        self.sim.reset(np.array([self.v0]), np.array([self.v0 / self.batch.r_eff[0]]))
        self._rows = {k: [] for k in ("t", "T_b", "omega", "v", "a_x")}
        w_std = math.sqrt(c.omega_noise_var)
        v_prev = w_prev = None
        for _ in range(self.free_steps):
            self._log_row(0.0, float(self.sim.omega[0]) + w_std * float(self._log_rng.standard_normal()))
            v_prev, w_prev = float(self.sim.v[0]), float(self.sim.omega[0])
            self.sim.step(np.zeros(1))
        self.torque = np.zeros(1)
        self.x, self.steps = 0.0, 0
        self.stopped, self.stop_distance, self.stop_time = False, math.nan, math.nan
        self.lock_count, self.lock_seen = 0, False
        self.limit = float(core.limit_distance(self.v0, c.v_stop, self.road_a.mu_max, self.road_a.mu_max, math.inf,
                                               p.g))
        noise = self._next_noise()
        v, w = float(self.sim.v[0]), float(self.sim.omega[0])
        if v_prev is None:  # no previous sample: BrakingSim's reset measurement
            self.meas = np.array([w + noise[0], noise[1], noise[2]])
        else:
            self.meas = np.array([w + noise[0], (w_prev - w) * (p.r / c.dt) + noise[1],
                                  (v - v_prev) / c.dt + noise[2]])
        return self._observe(), self._info()

    def step(self, action):
        if self.sim is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        a = np.asarray(action, dtype=float)
        if a.shape not in ((1,), (1, 1)):
            raise ValueError(f"action must have shape (1,), got shape {a.shape}")
        a = a.reshape(1)
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action must be finite, got {a[0]!r} (NaN or inf)")
        c, p = self.config, self.config.params
        # The env's actuator command (torque or torque-rate mode), BrakingSim's own code on this env's state.
        self.torque = core.BrakingSim.command_to_torque(self, np.clip(a, -1.0, 1.0))
        Tb = float(self.torque[0])
        self._log_row(Tb, float(self.meas[0]))
        v0, w0 = float(self.sim.v[0]), float(self.sim.omega[0])
        self.sim.step(self.torque)
        v, w = float(self.sim.v[0]), float(self.sim.omega[0])
        dx = 0.5 * c.dt * (v0 + v)  # trapezoid over the sample
        if not self.stopped and v0 > c.v_stop >= v:
            # v^2 is linear in distance at constant deceleration: locate the stop crossing in the sample
            frac = (v0 * v0 - c.v_stop**2) / max(v0 * v0 - v * v, 1e-300)
            self.stop_distance = self.x + frac * dx
            self.stop_time = (self.steps + (v0 - c.v_stop) / max(v0 - v, 1e-300)) * c.dt
            self.stopped = True
        self.x += dx
        self.steps += 1
        r_eff = float(self.batch.r_eff[0])
        self.lock_count = self.lock_count + 1 if (w * r_eff < c.lock_speed_ratio * v and v > c.v_stop) else 0
        self.lock_seen |= self.lock_count > c.lock_steps
        noise = self._next_noise()
        self.meas = np.array([w + noise[0], (w0 - w) * (p.r / c.dt) + noise[1], (v - v0) / c.dt + noise[2]])
        truncated = self.steps >= c.max_steps and not self.stopped
        return self._observe(), 0.0, self.stopped, truncated, self._info()

    def log(self, comments: Sequence[str] = ()) -> QuarterCarLog:
        """The recorded episode as a DESIGN.md log (commanded torque, measured wheel speed, noisy v and a_x)."""
        if not self.record or not self._rows.get("t"):
            raise ValueError("nothing recorded: make the env with record=True and run an episode")
        arr = {k: np.asarray(v, dtype=float) for k, v in self._rows.items()}
        return QuarterCarLog(t=arr["t"], T_b=arr["T_b"], omega=arr["omega"], v=arr["v"], a_x=arr["a_x"],
                             comments=tuple(comments))


# --------------------------------------------------------------------------------------------- policies
@dataclass
class GapPolicy:
    """A policy to run closed loop: how to configure the env, and how to build its controller on an env.

    :param label: name in tables.
    :param kind: ``controller`` | ``pipeline`` | ``trained``.
    :param source: the spec string.
    :param estimator: estimator whose outputs the policy sees (``none`` for plain controllers).
    :param config_kwargs: :class:`~fricenv.envs.braking_core.BrakingConfig` fields the policy needs.
    """

    label: str
    kind: str
    source: str
    estimator: str = "none"
    config_kwargs: dict = field(default_factory=dict)
    _trained: Any = None

    def config(self) -> core.BrakingConfig:
        return core.BrakingConfig(**self.config_kwargs)

    def build(self, env: gym.Env, tune: dict[str, float] | None = None):
        """The controller (``reset()``, ``act(obs)``) for ``env``, with retuned parameters ``tune``."""
        if tune and (self.kind != "controller" or self.source not in RETUNE):
            raise ValueError(f"retuning supports {', '.join(RETUNE)}, not {self.label!r}")
        if self.kind == "trained":
            return self._trained
        if self.kind == "pipeline":
            from agents.pipeline import EstimatorSlipPipeline

            return EstimatorSlipPipeline(env)
        base = env.unwrapped
        c = base.config
        spec = ControlSpec(fields=tuple(base.observation_fields), t_max=c.t_max, dt=c.dt,
                           action_mode=c.action_mode, torque_rate_max=c.torque_rate_max, params=c.params)
        tune = dict(tune or {})
        if self.source == "rule-abs":
            return RuleBasedABS(spec, RuleABSParams(**tune))
        if self.source == "slip-pi":
            if tune:
                lam = slip_reference(base.road_a)[0] * tune["slip_ref_factor"]
                return SlipController(spec, OracleSource(road_fn=None, slip_ref=lam))
            return SlipController(spec, OracleSource(road_fn=lambda: base.road))
        if self.source == "oracle-slip":
            return OracleSlipController(spec, road_fn=lambda: base.road)
        return FullBraking(spec)


def _valid_forms() -> str:
    return (f"valid: {', '.join(CONTROLLERS)}, {PIPELINE_PREFIX}<estimator>, or a training run directory "
            f"(with train.json)")


def resolve_policy(spec: str) -> GapPolicy:
    """A policy from its spec: a controller name, ``pipeline:<estimator>`` or a saved SB3 run directory.

    :raises UnknownPolicyError: anything else (lists the valid controllers and forms).
    """
    if spec in CONTROLLERS:
        observation = "oracle" if spec in ("slip-pi", "oracle-slip") else "default"
        return GapPolicy(spec, "controller", spec, config_kwargs={"observation": observation})
    if spec.startswith(PIPELINE_PREFIX):
        from fricenv.envs.estimator_observation import ESTIMATOR_NAMES

        est = spec[len(PIPELINE_PREFIX):]
        valid = [n for n in ESTIMATOR_NAMES if n != "none"]
        if est not in valid:
            raise UnknownPolicyError(f"unknown pipeline estimator {est!r}; valid: {', '.join(valid)}")
        return GapPolicy(f"est+slip-pi[{est}]", "pipeline", spec, estimator=est)
    path = Path(spec)
    if (path / "train.json").is_file():
        meta = json.loads((path / "train.json").read_text())
        if meta.get("env", "braking") != "braking":
            raise UnknownPolicyError(f"{spec} is a {meta.get('env')} policy; gap policy takes braking policies")
        from agents.training import load_policy

        trained = load_policy(path)
        names = {f.name for f in fields(core.BrakingConfig)}
        kwargs = {k: v for k, v in (meta.get("env_kwargs") or {}).items() if k in names}
        policy = GapPolicy(f"{meta.get('algo', 'ppo')}[{meta.get('estimator', 'none')}]", "trained", spec,
                           estimator=meta.get("estimator", "none"), config_kwargs=kwargs, _trained=trained)
        return policy
    raise UnknownPolicyError(f"unknown policy {spec!r}; {_valid_forms()}")


def make_env(policy: GapPolicy, road: str | MagicFormula, effects: Sequence = (), v0: float = V0,
             free_roll: float = FREE_ROLL, substeps: int = DEFAULT_SUBSTEPS, record: bool = False) -> gym.Env:
    """The closed-loop env for ``policy``: :class:`EffectBrakingEnv`, estimator-wrapped if the policy needs it."""
    env = EffectBrakingEnv(road, effects, policy.config(), v0=v0, free_roll=free_roll, substeps=substeps,
                           record=record)
    if policy.estimator != "none":
        from fricenv.envs.estimator_observation import EstimatorObservation

        env = EstimatorObservation(env, policy.estimator)
    if policy.kind == "trained":
        space = policy._trained.model.observation_space
        if space.shape != env.observation_space.shape:
            raise ValueError(f"policy {policy.source} expects observations of shape {space.shape}, the env gives "
                             f"{env.observation_space.shape} (estimator {policy.estimator!r})")
    return env


# --------------------------------------------------------------------------------------------- runs
@dataclass
class Episode:
    """Figures of one closed-loop run."""

    distance: float  # stopping distance from the brake onset to v_stop [m] (NaN if it did not stop)
    stopped: bool
    lock_seen: bool
    ratio: float  # distance / physical-limit distance


def run_episode(env: gym.Env, controller, seed: int) -> Episode:
    """One braking run of ``controller`` on ``env`` with reset seed ``seed``."""
    obs, info = env.reset(seed=seed)
    controller.reset()
    while True:
        obs, _, terminated, truncated, info = env.step(controller.act(obs))
        if terminated or truncated:
            break
    return Episode(distance=float(info["stopping_distance"]), stopped=bool(info["stopped"]),
                   lock_seen=bool(info["lock_seen"]), ratio=float(info["ratio"]))


def stopping_distances(policy: GapPolicy, road: str | MagicFormula, effects: Sequence = (), seeds: Sequence[int] = (0,),
                       v0: float = V0, free_roll: float = FREE_ROLL, substeps: int = DEFAULT_SUBSTEPS,
                       tune: dict[str, float] | None = None) -> list[Episode]:
    """Closed-loop runs of ``policy`` on the plant with ``effects``, one per seed.

    :param policy: from :func:`resolve_policy`.
    :param road: road preset or MagicFormula.
    :param effects: effect specs (empty: nominal simulator).
    :param seeds: reset seeds (measurement noise).
    :param v0: initial speed [m/s]; :param free_roll: free-rolling stretch [s]; :param substeps: physics substeps.
    :param tune: retuned controller parameters (see :data:`RETUNE`).
    """
    env = make_env(policy, road, effects, v0, free_roll, substeps)
    controller = policy.build(env, tune)
    return [run_episode(env, controller, int(s)) for s in seeds]


def closed_loop_log(policy: GapPolicy, road: str | MagicFormula, effects: Sequence, seed: int, v0: float = V0,
                    free_roll: float = FREE_ROLL, substeps: int = STAND_IN_SUBSTEPS,
                    max_time: float = LOG_MAX_TIME) -> QuarterCarLog:
    """A DESIGN.md log of ``policy`` braking the stand-in: free roll, then the closed loop until the car is slower
    than ``fricenv.gap.simulate.V_END`` (the stand-in's log end) or ``max_time`` has passed."""
    env = make_env(policy, road, effects, v0, free_roll, substeps, record=True)
    base = env.unwrapped
    controller = policy.build(env)
    obs, _ = env.reset(seed=seed)
    controller.reset()
    n_max = round(max_time / base.config.dt)
    while base.sim.v[0] >= V_END and len(base._rows["t"]) < n_max:
        obs, _, terminated, truncated, _ = env.step(controller.act(obs))
        if terminated or truncated:
            break
    names = ", ".join(f"{e.name}({', '.join(f'{k}={v:g}' for k, v in effect_params(e).items())})"
                      for e in effects) or "none"
    head = f"fricenv gap policy: policy={policy.label}, road={base.road_a.name}, v0={v0:g}, seed={seed}"
    return base.log(comments=(head, f"effects: {names}"))


# --------------------------------------------------------------------------------------------- the gap
def _mean(episodes: Sequence[Episode]) -> float:
    d = np.array([e.distance for e in episodes])
    if not np.all(np.isfinite(d)):
        warnings.warn(f"{int(np.sum(~np.isfinite(d)))} of {len(d)} runs did not stop within the time limit",
                      RuntimeWarning, stacklevel=3)
    return float(np.nanmean(d)) if np.any(np.isfinite(d)) else math.nan


def _std(episodes: Sequence[Episode]) -> float:
    """Seed-to-seed standard deviation of the stopping distance [m] (runs that stopped)."""
    d = np.array([e.distance for e in episodes])
    d = d[np.isfinite(d)]
    return float(np.std(d, ddof=1)) if d.size > 1 else math.nan


def _not_stopped(episodes: Sequence[Episode]) -> int:
    return sum(not e.stopped for e in episodes)


def _describe(effects: Sequence) -> list[dict]:
    return [{"effect": e.name, "params": effect_params(e)} for e in effects]


def effects_from_report(report: dict) -> tuple[str, list]:
    """(verdict, effect specs) of a ``report.json`` object: the verdict's effect with its fitted parameters, none
    for the verdicts ``none`` and ``unexplained``."""
    for key in ("verdict", "params"):
        if key not in report:
            raise ValueError(f"report has no {key!r}: not a gap diagnose report.json")
    verdict = report["verdict"]
    if verdict in ("none", "unexplained"):
        return verdict, []
    if verdict not in EFFECTS:
        raise ValueError(f"report verdict {verdict!r} is not a library effect; valid: none, unexplained, "
                         f"{', '.join(EFFECTS)}")
    return verdict, [make_effect(verdict, **report["params"])]


def _rel(a: float, b: float) -> float:
    return (a - b) / b if b and math.isfinite(a) and math.isfinite(b) else math.nan


def policy_gap(policy: str | GapPolicy, road: str = "dry", effects: Sequence = (), report: dict | None = None,
               seeds: int = DEFAULT_SEEDS, seed: int = 0, v0: float = V0, free_roll: float = FREE_ROLL, retune: bool = False,
               log_path=None, report_dir=None, diagnose_jobs: int | None = None,
               progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Stopping distance of ``policy`` in the nominal simulator, on the real stand-in, and in the simulator
    augmented with the diagnosed effect (see the module docstring).

    :param policy: a policy spec (:func:`resolve_policy`) or a resolved :class:`GapPolicy`.
    :param road: road preset.
    :param effects: the stand-in's effects (empty with ``report``: no stand-in, the report's log is the real one).
    :param report: a ``report.json`` object; its verdict and parameters make the augmented simulator (otherwise the
        stand-in's closed-loop log is diagnosed).
    :param seeds: noise seeds averaged over (``seed .. seed + seeds - 1``, the same in every simulator).
    :param seed: first seed; the diagnosed log uses it too.
    :param v0: initial speed [m/s]; :param free_roll: free-rolling stretch before the brake onset [s].
    :param retune: retune the controller's :data:`RETUNE` parameter in the augmented (and nominal) simulator.
    :param log_path: write the stand-in's closed-loop log here (CSV).
    :param report_dir: write the diagnosis report (report.json, report.md, plots) here.
    :param diagnose_jobs: processes for the diagnosis' candidate fits.
    :param progress: optional callback for status lines.
    :return: the figures (keys of the ``--json`` output).
    """
    say = progress or (lambda msg: None)
    pol = policy if isinstance(policy, GapPolicy) else resolve_policy(policy)
    if seeds < 1:
        raise ValueError(f"seeds must be >= 1, got {seeds}")
    if not effects and report is None:
        raise ValueError("give the real stand-in's effects or a diagnosis report (or both)")
    if retune and (pol.kind != "controller" or pol.source not in RETUNE):
        raise ValueError(f"--retune supports {', '.join(RETUNE)}, not {pol.label!r}")
    road_mf = get_road(road) if isinstance(road, str) else road
    seed_list = list(range(seed, seed + seeds))
    kw = {"v0": v0, "free_roll": free_roll}
    say(f"nominal simulator: {seeds} run(s)")
    nominal = stopping_distances(pol, road_mf, (), seed_list, **kw)
    real = None
    if effects:
        say(f"real stand-in ({', '.join(e.name for e in effects)}): {seeds} run(s)")
        real = stopping_distances(pol, road_mf, effects, seed_list, substeps=STAND_IN_SUBSTEPS, **kw)
    diagnosis: dict[str, Any] = {}
    if report is not None:
        verdict, aug_effects = effects_from_report(report)
        diagnosis = {"source": "report", "gap_before": report.get("gap_before"), "gap_after": report.get("gap_after"),
                     "params": report.get("params", {})}
    else:
        from fricenv.gap.diagnose import DiagnoseConfig, diagnose

        log = closed_loop_log(pol, road_mf, effects, seed, **kw)
        if log_path is not None:
            from fricenv.logs import write_log

            write_log(log_path, log, comments=log.comments)
        say(f"diagnosing the stand-in's closed-loop log ({len(log)} samples)")
        dg = diagnose(log, pol.config().params, DiagnoseConfig(jobs=diagnose_jobs))
        if report_dir is not None:
            from fricenv.gap.report import write_report

            write_report(dg, report_dir)
        verdict = dg.verdict
        aug_effects = [make_effect(verdict, **dg.params)] if verdict in EFFECTS else []
        diagnosis = {"source": "closed-loop log", "samples": len(log), "gap_before": dg.gap_before,
                     "gap_after": dg.gap_after, "params": dg.params, "seconds": dg.seconds}
    say(f"augmented simulator ({verdict}): {seeds} run(s)")
    augmented = stopping_distances(pol, road_mf, aug_effects, seed_list, **kw) if aug_effects else nominal
    d_nom, d_aug = _mean(nominal), _mean(augmented)
    d_real = _mean(real) if real is not None else None
    out: dict[str, Any] = {
        "policy": pol.label,
        "road": road_mf.name,
        "effects": _describe(effects),
        "verdict": verdict,
        "augmented_effects": _describe(aug_effects),
        "distance_nominal_m": d_nom,
        "distance_real_m": d_real,
        "distance_augmented_m": d_aug,
        "prediction_error_before": _rel(d_nom, d_real) if d_real is not None else None,
        "prediction_error_after": _rel(d_aug, d_real) if d_real is not None else None,
        "predicted_shift": _rel(d_aug, d_nom),
        "limit_distance_m": float(core.limit_distance(v0, pol.config().v_stop, road_mf.mu_max, road_mf.mu_max,
                                                      math.inf, pol.config().params.g)),
        "distance_std_m": {"nominal": _std(nominal), "augmented": _std(augmented),
                           "real": _std(real) if real is not None else None},
        "not_stopped": {"nominal": _not_stopped(nominal), "augmented": _not_stopped(augmented),
                        "real": _not_stopped(real) if real is not None else None},
        "seeds": seed_list,
        "v0": v0,
        "per_seed": {"nominal": [e.distance for e in nominal], "augmented": [e.distance for e in augmented],
                     "real": [e.distance for e in real] if real is not None else None},
        "lock_seen": {"nominal": any(e.lock_seen for e in nominal), "augmented": any(e.lock_seen for e in augmented),
                      "real": any(e.lock_seen for e in real) if real is not None else None},
        "diagnosis": diagnosis,
    }
    if retune:
        out["retune"] = _retune(pol, road_mf, effects, aug_effects, seed_list, kw, say, d_real)
    return out


def _retune(pol: GapPolicy, road: MagicFormula, effects: Sequence, aug_effects: Sequence, seeds: list[int],
            kw: dict, say: Callable[[str], None], d_real: float | None) -> dict[str, Any]:
    """Grid over :data:`RETUNE` in the augmented and nominal simulators; each choice measured on the stand-in."""
    name, grid = RETUNE[pol.source]
    rows = []
    for value in grid:
        say(f"retune {name}={value:g}")
        tune = {name: value}
        row = {"value": value, "nominal": _mean(stopping_distances(pol, road, (), seeds, tune=tune, **kw)),
               "augmented": _mean(stopping_distances(pol, road, aug_effects, seeds, tune=tune, **kw))
               if aug_effects else None}
        if effects:
            row["real"] = _mean(stopping_distances(pol, road, effects, seeds, substeps=STAND_IN_SUBSTEPS, tune=tune,
                                                   **kw))
        rows.append(row)
    default = {f.name: f.default for f in fields(RuleABSParams)}.get(name, 1.0)

    def best(key: str) -> dict:
        return min(rows, key=lambda r: r[key] if r[key] is not None and math.isfinite(r[key]) else math.inf)

    b_aug = best("augmented") if aug_effects else best("nominal")
    b_nom = best("nominal")
    out = {"parameter": name, "default": default, "grid": rows, "best_augmented": b_aug["value"],
           "best_nominal": b_nom["value"]}
    if effects:
        d_default = d_real
        out.update(real_default_m=d_default, real_best_augmented_m=b_aug["real"], real_best_nominal_m=b_nom["real"],
                   real_gain_m=d_default - b_aug["real"],
                   real_gain_vs_nominal_tuning_m=b_nom["real"] - b_aug["real"])
    return out


# --------------------------------------------------------------------------------------------- table
def _fmt(x, spec: str = ".2f") -> str:
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def format_table(res: dict[str, Any]) -> str:
    """The figures as a plain-text table."""
    eff = ", ".join(f"{e['effect']}({', '.join(f'{k}={v:.4g}' for k, v in e['params'].items())})"
                    for e in res["effects"]) or "-"
    aug = ", ".join(f"{e['effect']}({', '.join(f'{k}={v:.4g}' for k, v in e['params'].items())})"
                    for e in res["augmented_effects"]) or "none"
    lines = [f"policy {res['policy']} on {res['road']} from {res['v0']:g} m/s, seeds {res['seeds']}",
             f"real stand-in effects: {eff}",
             f"verdict: {res['verdict']}; augmented simulator: {aug}", "",
             f"{'simulator':<12} {'distance [m]':>13} {'seed std':>9} {'vs real':>9}"]
    for key, err in (("nominal", "prediction_error_before"), ("real", None), ("augmented", "prediction_error_after")):
        lines.append(f"{key:<12} {_fmt(res[f'distance_{key}_m']):>13} {_fmt(res['distance_std_m'][key]):>9} "
                     f"{_fmt(res[err], '+.2%') if err else '':>9}")
    stuck = {k: v for k, v in res["not_stopped"].items() if v}
    if stuck:
        lines.append(f"runs that did not stop within the time limit (left out of the means): {stuck}")
    rt = res.get("retune")
    if rt:
        lines += ["", f"retune {rt['parameter']} (default {rt['default']:g}): stopping distance [m]",
                  f"{'value':>8} {'nominal':>9} {'augmented':>10} {'real':>8}"]
        for r in rt["grid"]:
            lines.append(f"{r['value']:>8g} {_fmt(r['nominal']):>9} {_fmt(r['augmented']):>10} "
                         f"{_fmt(r.get('real')):>8}")
        lines.append(f"best in augmented sim: {rt['best_augmented']:g}; best in nominal sim: {rt['best_nominal']:g}")
        if "real_gain_m" in rt:
            lines.append(f"real side: default {_fmt(rt['real_default_m'])} m -> tuned in augmented sim "
                         f"{_fmt(rt['real_best_augmented_m'])} m (gain {_fmt(rt['real_gain_m'], '+.2f')} m; tuned in "
                         f"nominal sim {_fmt(rt['real_best_nominal_m'])} m)")
    return "\n".join(lines)
