"""Policy-level sim-to-real gap: how far the simulator's prediction of a controller's stopping
distance is off on the "real" plant, before and after the diagnosed effect is added to the simulator.

For a controller (``rule-abs``, ``slip-pi``, ``oracle-slip``, ``locked``), an estimator pipeline
(``pipeline:<estimator>``) or a saved SB3 policy (a training run directory), :func:`policy_gap` measures the
stopping distance, averaged over noise seeds (the same seeds in every simulator, so the measurement noise is equal):

1. in the **nominal** simulator (the quarter car of :mod:`fricenv.plants.quarter_car`, no effect);
2. on the **real stand-in** (the plant with the given effects, integrated twice as finely as the models, as
   ``fricenv gap simulate`` does); or, for a real log, nothing: only its diagnosis report is given;
3. in the **augmented** (corrected) simulator: the nominal one plus the diagnosed effects with their fitted
   parameters. The typical
   flow: the controller brakes the stand-in once more with a free-rolling start and that run is logged (the log
   format of docs/contracts.md); :func:`fricenv.gap.quarter_car.diagnose.diagnose` names the effect and fits it; or
   the verdict and parameters come from a ``report.json``.

``prediction_error_before = (d_nominal - d_real) / d_real`` and ``prediction_error_after = (d_augmented - d_real) /
d_real`` (signed shares) say how far the simulator's prediction of the real stopping distance was off. Optionally
a controller parameter is retuned on a small grid in the augmented simulator (and, for comparison, in the nominal
one) and each choice is measured on the stand-in: the real-side gain of tuning in the augmented simulator.

Closed loop. Every simulator is ``fricenv/Braking-v0`` itself (:func:`fricenv.envs.factory.make_braking`, with the
policy's estimator wrapper when it needs one): ``effects=()`` is the nominal env, ``effects=...`` the corrected
simulator (:class:`fricenv.envs.effect_plant.EffectPlant` under the same episode logic), and the stand-in is the
corrected simulator with 10 physics substeps per 10 ms instead of 5. So the measurement model, noise stream, lock
test and stop location are the env's, whatever the plant.

Time base. Each run starts with ``free_roll`` seconds of free rolling (action -1, zero torque; the log's
free-rolling stretch), then the controller is reset and brakes; time 0 (``mu_change``'s ``t_change``) is the start
of the free roll (the env's episode start), and the stopping distance is counted from the brake onset to ``v_stop``
(the env's, 2 m/s, located inside the physics substep).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields
from typing import Any

import gymnasium as gym
import numpy as np

from agents.controllers import (
    ControlSpec,
    FullBraking,
    OracleSlipController,
    OracleSource,
    RuleABSParams,
    RuleBasedABS,
    SlipController,
    slip_reference,
)
from agents.policy_spec import PolicySpecError, parse_policy_spec
from fricenv.effects.quarter_car import DEFAULT_SUBSTEPS, EFFECTS, effect_params, make_effect
from fricenv.envs import config as core
from fricenv.envs.effect_spec import describe_effects, effects_from_report
from fricenv.envs.factory import make_braking
from fricenv.envs.scenario import V0_DEFAULT, limit_distance
from fricenv.gap.quarter_car.simulate import STAND_IN_SUBSTEPS, V_END, NoiseSpec
from fricenv.logs import QuarterCarLog
from fricenv.plants.tire import MagicFormula, get_road

__all__ = [
    "FREE_ROLL",
    "RETUNE",
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
V0 = V0_DEFAULT  # initial speed [m/s], the ABS figure's 20 m/s
LOG_MAX_TIME = 8.0  # longest closed-loop log handed to the diagnosis [s] (snow from 20 m/s takes ~7 s)
LOG_STREAM = 0x6C6F67  # seed-sequence key of the log-only noise (v, a_x columns, free-roll wheel speed)
# Retune grids: controller -> (parameter, values). rule-abs: the excess wheel deceleration that starts a dump from
# hold [m/s^2] (under a brake lag it decides how deep the wheel goes past the peak); slip-pi: the slip reference as
# a multiple of the road's peak slip [-].
RETUNE: dict[str, tuple[str, tuple[float, ...]]] = {
    "rule-abs": ("decel_dump", (15.0, 20.0, 25.0, 32.0, 40.0)),
    "slip-pi": ("slip_ref_factor", (0.6, 0.8, 1.0, 1.2, 1.4)),
}


UnknownPolicyError = PolicySpecError  # the one policy-spec error (kept under its old name)


# --------------------------------------------------------------------------------------------- policies
@dataclass
class GapPolicy:
    """A policy to run closed loop: how to configure the env, and how to build its controller on an env.

    :param label: name in tables.
    :param kind: ``controller`` | ``pipeline`` | ``trained``.
    :param source: the spec string.
    :param estimator: estimator whose outputs the policy sees (``none`` for plain controllers).
    :param config_kwargs: :class:`~fricenv.envs.config.BrakingConfig` fields the policy needs.
    """

    label: str
    kind: str
    source: str
    estimator: str = "none"
    config_kwargs: dict = field(default_factory=dict)
    _trained: Any = None

    def config(self) -> core.BrakingConfig:
        return core.BrakingConfig(**self.config_kwargs)

    def build(self, env: gym.Env, road: MagicFormula, tune: dict[str, float] | None = None):
        """The controller (``reset()``, ``act(obs)``) for ``env`` on ``road``, with retuned parameters ``tune``."""
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
                lam = slip_reference(road)[0] * tune["slip_ref_factor"]
                return SlipController(spec, OracleSource(road_fn=None, slip_ref=lam))
            return SlipController(spec, OracleSource(road_fn=lambda: base.road))
        if self.source == "oracle-slip":
            return OracleSlipController(spec, road_fn=lambda: base.road)
        return FullBraking(spec)


def resolve_policy(spec: str) -> GapPolicy:
    """A policy from its spec (:func:`agents.policy_spec.parse_policy_spec`: a controller name,
    ``pipeline:<estimator>`` or a saved SB3 run directory).

    :raises UnknownPolicyError: anything else (lists the valid forms).
    """
    parsed = parse_policy_spec(spec)
    if parsed.kind == "trained":
        from agents.training import load_policy

        names = {f.name for f in fields(core.BrakingConfig)}
        kwargs = {k: v for k, v in parsed.env_kwargs.items() if k in names}
        return GapPolicy(parsed.label, "trained", parsed.source, estimator=parsed.estimator, config_kwargs=kwargs,
                         _trained=load_policy(parsed.source))
    config = {"observation": parsed.observation} if parsed.kind == "controller" else {}
    return GapPolicy(parsed.label, parsed.kind, parsed.source, estimator=parsed.estimator, config_kwargs=config)


def make_env(policy: GapPolicy, road: str | MagicFormula, effects: Sequence = (), v0: float = V0,
             substeps: int = DEFAULT_SUBSTEPS) -> gym.Env:
    """The closed-loop env for ``policy``: ``Braking-v0`` with ``effects`` (the corrected simulator, or the stand-in
    with ``substeps`` physics substeps per 10 ms), estimator-wrapped if the policy needs it."""
    kwargs = {**policy.config_kwargs, "physics_dt": core.CONTROL_DT / substeps}
    env = make_braking(policy.estimator, road=road, v0=v0, effects=effects, **kwargs)
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


def _drive(env: gym.Env, controller, seed: int, free_steps: int,
           on_step: Callable[[int, Any, dict], None] | None = None,
           keep_going: Callable[[Any], bool] | None = None) -> tuple[dict, float]:
    """Reset with ``seed``, free-roll ``free_steps`` control steps (action -1: zero torque in both action modes),
    then let ``controller`` brake until the episode ends (or ``keep_going(sim)`` is false).

    :param on_step: called after every step with (step index, the sim, the step's info) before it is advanced.
    :return: (the last info, the distance at the brake onset [m]).
    """
    obs, info = env.reset(seed=seed)
    base = env.unwrapped
    release = np.full(env.action_space.shape, -1.0, dtype=env.action_space.dtype)
    x_onset, k = 0.0, 0
    while keep_going is None or keep_going(base.sim):
        if k == free_steps:
            controller.reset()
            x_onset = float(base.sim.x[0])
        before = (k, float(base.sim.meas[0, 0]), float(base.sim.v[0]), float(base.sim.accel()[0]))
        obs, _, terminated, truncated, info = env.step(release if k < free_steps else controller.act(obs))
        if on_step is not None:
            on_step(*before, info)
        k += 1
        if terminated or truncated:
            break
    return info, x_onset


def run_episode(env: gym.Env, controller, seed: int, free_roll: float = FREE_ROLL) -> Episode:
    """One braking run of ``controller`` on ``env`` with reset seed ``seed``, after ``free_roll`` seconds of free
    rolling; the distance counts from the brake onset."""
    info, x_onset = _drive(env, controller, seed, round(free_roll / core.CONTROL_DT))
    distance = float(info.get("stopping_distance") if info.get("stopped") else math.nan) - x_onset
    limit = float(info["limit_distance"])
    return Episode(distance=distance, stopped=bool(info["stopped"]), lock_seen=bool(info["lock_seen"]),
                   ratio=distance / limit)


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
    road_mf = get_road(road) if isinstance(road, str) else road
    env = make_env(policy, road_mf, effects, v0, substeps)
    controller = policy.build(env, road_mf, tune)
    return [run_episode(env, controller, int(s), free_roll) for s in seeds]


def closed_loop_log(policy: GapPolicy, road: str | MagicFormula, effects: Sequence, seed: int, v0: float = V0,
                    free_roll: float = FREE_ROLL, substeps: int = STAND_IN_SUBSTEPS,
                    max_time: float = LOG_MAX_TIME, log_noise: NoiseSpec | None = None) -> QuarterCarLog:
    """A log (docs/contracts.md format) of ``policy`` braking the stand-in: free roll, then the closed loop until the
    car is slower than ``fricenv.gap.quarter_car.simulate.V_END`` (the stand-in's log end) or ``max_time`` has passed. Columns: the commanded
    torque, the env's measured wheel speed, and the true speed and acceleration plus ``log_noise``."""
    road_mf = get_road(road) if isinstance(road, str) else road
    env = make_env(policy, road_mf, effects, v0, substeps)
    noise = log_noise if log_noise is not None else NoiseSpec()
    rng = np.random.default_rng([LOG_STREAM, seed])  # log-only noise: the env's measurement stream is untouched
    rows: dict[str, list[float]] = {k: [] for k in ("t", "T_b", "omega", "v", "a_x")}

    def record(k: int, w_meas: float, v: float, a_x: float, info: dict) -> None:
        for key, value in zip(rows, (k * core.CONTROL_DT, info["torque"], w_meas,
                                     v + noise.v_std * rng.standard_normal(),
                                     a_x + noise.a_x_std * rng.standard_normal())):
            rows[key].append(float(value))

    n_max = round(max_time / core.CONTROL_DT)
    _drive(env, policy.build(env, road_mf), seed, round(free_roll / core.CONTROL_DT), record,
           lambda sim: sim.v[0] >= V_END and len(rows["t"]) < n_max)
    names = ", ".join(f"{e.name}({', '.join(f'{k}={v:g}' for k, v in effect_params(e).items())})"
                      for e in effects) or "none"
    head = f"fricenv gap policy: policy={policy.label}, road={road_mf.name}, v0={v0:g}, seed={seed}"
    arr = {k: np.asarray(v, dtype=float) for k, v in rows.items()}
    return QuarterCarLog(t=arr["t"], T_b=arr["T_b"], omega=arr["omega"], v=arr["v"], a_x=arr["a_x"],
                         comments=(head, f"effects: {names}"))


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


_describe = describe_effects


def _rel(a: float, b: float) -> float:
    return (a - b) / b if b and math.isfinite(a) and math.isfinite(b) else math.nan


def policy_gap(policy: str | GapPolicy, road: str = "dry", effects: Sequence = (), report: dict | None = None,
               seeds: int = DEFAULT_SEEDS, seed: int = 0, v0: float = V0, free_roll: float = FREE_ROLL,
               retune: bool = False, log_path=None, report_dir=None, diagnose_jobs: int | None = None,
               progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Stopping distance of ``policy`` in the nominal simulator, on the real stand-in, and in the simulator
    corrected with the diagnosed effects (see the module docstring).

    :param policy: a policy spec (:func:`resolve_policy`) or a resolved :class:`GapPolicy`.
    :param road: road preset.
    :param effects: the stand-in's effects (empty with ``report``: no stand-in, the report's log is the real one).
    :param report: a ``report.json`` object; its effects make the corrected simulator (otherwise the stand-in's
        closed-loop log is diagnosed).
    :param seeds: noise seeds averaged over (``seed .. seed + seeds - 1``, the same in every simulator).
    :param seed: first seed; the diagnosed log uses it too.
    :param v0: initial speed [m/s]; :param free_roll: free-rolling stretch before the brake onset [s].
    :param retune: retune the controller's :data:`RETUNE` parameter in the corrected (and nominal) simulator.
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
    runs = {"nominal": stopping_distances(pol, road_mf, (), seed_list, **kw), "real": None}
    if effects:
        say(f"real stand-in ({', '.join(e.name for e in effects)}): {seeds} run(s)")
        runs["real"] = stopping_distances(pol, road_mf, effects, seed_list, substeps=STAND_IN_SUBSTEPS, **kw)
    if report is not None:
        verdict, aug_effects = effects_from_report(report)
        diagnosis = {"source": "report", "gap_before": report.get("gap_before"), "gap_after": report.get("gap_after"),
                     "params": report.get("params", {})}
    else:
        verdict, aug_effects, diagnosis = _diagnose_stand_in(pol, road_mf, effects, seed, kw, log_path, report_dir,
                                                             diagnose_jobs, say)
    say(f"corrected simulator ({verdict}): {seeds} run(s)")
    runs["augmented"] = stopping_distances(pol, road_mf, aug_effects, seed_list, **kw) if aug_effects \
        else runs["nominal"]
    out = _gap_figures(pol, road_mf, effects, verdict, aug_effects, runs, seed_list, v0)
    out["diagnosis"] = diagnosis
    if retune:
        out["retune"] = _retune(pol, road_mf, effects, aug_effects, seed_list, kw, say, out["distance_real_m"])
    return out


def _diagnose_stand_in(pol: GapPolicy, road: MagicFormula, effects: Sequence, seed: int, kw: dict, log_path,
                       report_dir, jobs: int | None, say: Callable[[str], None]) -> tuple[str, list, dict]:
    """Diagnose the stand-in's closed-loop log: (verdict, the corrected simulator's effects, diagnosis figures)."""
    from fricenv.gap.quarter_car.diagnose import DiagnoseConfig, diagnose

    log = closed_loop_log(pol, road, effects, seed, **kw)
    if log_path is not None:
        from fricenv.logs import write_log

        write_log(log_path, log, comments=log.comments)
    say(f"diagnosing the stand-in's closed-loop log ({len(log)} samples)")
    dg = diagnose(log, pol.config().params, DiagnoseConfig(jobs=jobs))
    if report_dir is not None:
        from fricenv.gap.quarter_car.report import write_report

        write_report(dg, report_dir)
    aug_effects = [make_effect(dg.verdict, **dg.params)] if dg.verdict in EFFECTS else []
    return dg.verdict, aug_effects, {"source": "closed-loop log", "samples": len(log), "gap_before": dg.gap_before,
                                     "gap_after": dg.gap_after, "params": dg.params, "seconds": dg.seconds}


def _gap_figures(pol: GapPolicy, road: MagicFormula, effects: Sequence, verdict: str, aug_effects: Sequence,
                 runs: dict[str, list[Episode] | None], seed_list: list[int], v0: float) -> dict[str, Any]:
    """The distances, ratios and prediction errors of the three simulators (the ``--json`` keys)."""
    c = pol.config()
    limit = float(limit_distance(v0, c.v_stop, road.mu_max, road.mu_max, math.inf, c.params.g))
    keys = ("nominal", "augmented", "real")
    dist = {k: _mean(runs[k]) if runs[k] is not None else None for k in keys}
    d_real = dist["real"]
    return {
        "policy": pol.label,
        "road": road.name,
        "effects": _describe(effects),
        "verdict": verdict,
        "augmented_effects": _describe(aug_effects),
        **{f"distance_{k}_m": dist[k] for k in keys},
        # the policy-level figure: stopping distance / physical limit in each simulator
        "ratio": {k: dist[k] / limit if dist[k] is not None else None for k in keys},
        "prediction_error_before": _rel(dist["nominal"], d_real) if d_real is not None else None,
        "prediction_error_after": _rel(dist["augmented"], d_real) if d_real is not None else None,
        "predicted_shift": _rel(dist["augmented"], dist["nominal"]),
        "limit_distance_m": limit,
        "distance_std_m": {k: _std(runs[k]) if runs[k] is not None else None for k in keys},
        "not_stopped": {k: _not_stopped(runs[k]) if runs[k] is not None else None for k in keys},
        "seeds": seed_list,
        "v0": v0,
        "per_seed": {k: [e.distance for e in runs[k]] if runs[k] is not None else None for k in keys},
        "lock_seen": {k: any(e.lock_seen for e in runs[k]) if runs[k] is not None else None for k in keys},
    }


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
             f"{'simulator':<12} {'distance [m]':>13} {'ratio':>7} {'seed std':>9} {'vs real':>9}"]
    for key, err in (("nominal", "prediction_error_before"), ("real", None), ("augmented", "prediction_error_after")):
        lines.append(f"{key:<12} {_fmt(res[f'distance_{key}_m']):>13} {_fmt(res['ratio'][key], '.3f'):>7} "
                     f"{_fmt(res['distance_std_m'][key]):>9} {_fmt(res[err], '+.2%') if err else '':>9}")
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
