"""Evaluate ABS policies and classical controllers on one fixed scenario set, over several seeds.

Scenario set (:data:`SCENARIOS`), sensor noise on (the env's defaults): every road preset (dry, wet, snow, ice) at
20 and 30 m/s, and the friction changes dry->ice and ice->dry (at 15 m) at 20 and 30 m/s. Each (policy, scenario)
runs over ``seeds`` episodes with ``reset(seed=s)``, ``s = 0..seeds-1``: the same seed gives the same noise to
every policy, and the whole table is deterministic for a fixed seed list.

Metrics per (policy, scenario): mean and std over seeds of the stopping-distance ratio to the physical limit
(``info["ratio"]``; an episode that does not stop before the time limit counts with its distance travelled, a
lower bound, and ``stopped`` says how many did stop), the number of episodes in which the wheel locked, and the
mean ``|slip - lambda*|`` over the stop (``lambda*`` the peak slip of the road under the car, capped at 0.4 as by
every slip controller, :func:`agents.controllers.slip_reference`).

Policies are named by a spec string, parsed by :func:`agents.policy_spec.parse_policy_spec` (a controller of
:data:`agents.controllers.CONTROLLERS`, ``pipeline:EST`` for estimator EST + slip controller, or a trained run
directory; see that module for the table).

Jobs (one per policy, scenario and seed) run in ``workers`` local processes, or as Ray tasks with ``ray="auto"`` or
a cluster address (:func:`fricenv.gap.core.pool.map_tasks`, the one parallel map of the project): the same jobs give the
same rows on either.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from agents.policy_spec import PIPELINE_PREFIX, PolicySpec, PolicySpecError, parse_policy_spec
from fricenv import progress as progress_events
from fricenv.gap.core.pool import default_jobs, map_tasks
from fricenv.utils import atomic_write, write_json

__all__ = [
    "ROW_KEYS",
    "SCENARIOS",
    "PolicySpec",
    "PolicySpecError",
    "Scenario",
    "evaluate",
    "format_table",
    "parse_policy",
    "policy_controller",
    "run_controller",
    "run_episode",
    "summarize",
    "write_outputs",
]

SPEEDS = (20.0, 30.0)  # initial speeds of the scenario set [m/s]
ROAD_NAMES = ("dry", "wet", "snow", "ice")
TRANSITIONS = ("dry->ice", "ice->dry")
CHANGE_DISTANCE = 15.0  # [m]
DEFAULT_SEEDS = 3
ROW_KEYS = ("policy", "estimator", "scenario", "cell", "effects", "ratio_mean", "ratio_std", "locks", "slip_err_mean", "stopped",
            "episodes")


@dataclass(frozen=True)
class Scenario:
    """One evaluation scenario: a road, a speed and the plant's effects (``[]``: the nominal plant)."""

    road: str  # road spec of Braking-v0
    v0: float  # initial speed [m/s]
    effects: tuple = field(default=(), compare=False)  # {"effect", "params"} entries of Braking-v0's effects=
    cell: str = "nominal"  # the effects' label in tables (an effect-grid cell, "custom" or "nominal")

    @property
    def name(self) -> str:
        return f"{self.road}@{self.v0:g}"


SCENARIOS: tuple[Scenario, ...] = tuple(Scenario(r, v) for v in SPEEDS for r in ROAD_NAMES) + tuple(
    Scenario(r, v) for v in SPEEDS for r in TRANSITIONS)


def parse_policy(spec: str) -> PolicySpec:
    """Parse a policy spec (:func:`agents.policy_spec.parse_policy_spec`); PolicySpecError (a ValueError) listing
    the valid forms."""
    return parse_policy_spec(spec)


_POLICY_CACHE: dict[str, Any] = {}


def policy_controller(spec: PolicySpec, env):
    """The controller of a policy spec on ``env``: a classical controller, the estimator-slip pipeline, or a
    trained run (loaded once per process)."""
    from agents.controllers import make_controller

    if spec.kind == "controller":
        return make_controller(spec.source, env)
    if spec.kind == "pipeline":
        from agents.pipeline import EstimatorSlipPipeline

        return EstimatorSlipPipeline(env)
    if spec.source not in _POLICY_CACHE:
        from agents.training import load_policy

        _POLICY_CACHE[spec.source] = load_policy(spec.source)
    return _POLICY_CACHE[spec.source]


def run_episode(spec: PolicySpec, scenario: Scenario, seed: int) -> dict[str, Any]:
    """One episode of a policy on a scenario (its plant's effects on): ratio, lock, mean |slip - lambda*|, stopped.

    :param spec: the policy.
    :param scenario: the scenario.
    :param seed: reset seed (noise).
    """
    from fricenv.envs.factory import make_braking

    env = make_braking(spec.estimator, road=scenario.road, v0=scenario.v0, change_distance=CHANGE_DISTANCE,
                       observation=spec.observation, effects=list(scenario.effects) or None)
    try:
        return run_controller(policy_controller(spec, env), env, seed)
    finally:
        env.close()


def run_controller(ctl, env, seed: int) -> dict[str, Any]:
    """One episode of a controller (``reset()``, ``act(obs)``) on a Braking-v0 env set up for its scenario.

    :param ctl: the controller or trained policy.
    :param env: the env (``make_braking`` with the scenario's road, speed and change distance).
    :param seed: reset seed (noise).
    :return: ``ratio``, ``lock``, ``slip_err``, ``stopped`` (see the module docstring).
    """
    from agents.controllers import slip_reference

    obs, info = env.reset(seed=seed)
    ctl.reset()
    base = env.unwrapped
    refs = {}
    errs = []
    while True:
        obs, _, terminated, truncated, info = env.step(ctl.act(obs))
        road = base.road
        if road.name not in refs:
            refs[road.name] = slip_reference(road)[0]
        if not terminated or info["v"] > base.config.v_stop:
            errs.append(abs(info["slip"] - refs[road.name]))
        if terminated or truncated:
            break
    stopped = bool(info["stopped"])
    distance = info["stopping_distance"] if stopped else info["distance"]
    return {"ratio": float(distance / info["limit_distance"]), "lock": bool(info["lock_seen"]),
            "slip_err": float(np.mean(errs)) if errs else float("nan"), "stopped": stopped}


def _job(spec: PolicySpec, scenario: Scenario, seed: int) -> dict[str, Any]:
    """One episode in a worker (one torch thread)."""
    import torch

    torch.set_num_threads(1)
    return run_episode(spec, scenario, seed)


def evaluate(policies: Sequence[str | PolicySpec], scenarios: Sequence[Scenario] = SCENARIOS,
             seeds: int | Sequence[int] = DEFAULT_SEEDS, workers: int | None = None,
             progress: bool = True, ray: str | None = None) -> list[dict[str, Any]]:
    """Run every policy on every scenario and seed; one summary row per (policy, scenario).

    :param policies: policy specs (strings or :class:`PolicySpec`).
    :param scenarios: the scenario set.
    :param seeds: number of seeds (0..n-1) or an explicit list.
    :param workers: worker processes (default: min(2, CPUs)); 1 runs in this process. Not used with ``ray``.
    :param progress: report progress (to the front end's sink, :mod:`fricenv.progress`).
    :param ray: None (local processes), ``"auto"`` or a Ray cluster address (one CPU per episode).
    :return: rows with :data:`ROW_KEYS`.
    """
    specs = [p if isinstance(p, PolicySpec) else parse_policy(p) for p in policies]
    labels = [s.label for s in specs]
    if len(set(labels)) < len(labels):  # e.g. several runs of one algorithm and estimator: name them by directory
        specs = [dataclasses.replace(s, label=f"{s.label}@{Path(s.source).name}") if labels.count(s.label) > 1
                 else s for s in specs]
        if len({s.label for s in specs}) < len(specs):
            raise ValueError(f"policies must be distinct, got {[s.source for s in specs]}")
    seed_list = list(range(seeds)) if isinstance(seeds, int) else [int(s) for s in seeds]
    if not seed_list:
        raise ValueError("seeds must be a positive number or a non-empty list")
    jobs = [(spec, sc, s) for spec in specs for sc in scenarios for s in seed_list]
    with contextlib.nullcontext() if progress else progress_events.use_sink(None):
        results = map_tasks(_job, jobs, default_jobs(workers), "evaluate", ray=ray)
    return summarize(jobs, results)


def summarize(jobs, results) -> list[dict[str, Any]]:
    """Group episode results by (policy, scenario) into summary rows."""
    groups: dict[tuple[str, str, str], dict[str, Any]] = {}
    for (spec, sc, _), res in zip(jobs, results):
        g = groups.setdefault((spec.label, sc.name, sc.cell), {"spec": spec, "effects": sc.effects, "res": []})
        g["res"].append(res)
    rows = []
    for (label, scenario, cell), g in groups.items():
        ratios = np.array([r["ratio"] for r in g["res"]])
        rows.append({
            "policy": label,
            "estimator": g["spec"].estimator,
            "scenario": scenario,
            "cell": cell,
            "effects": [dict(e) for e in g["effects"]],
            "ratio_mean": float(np.mean(ratios)),
            "ratio_std": float(np.std(ratios)),
            "locks": int(sum(r["lock"] for r in g["res"])),
            "slip_err_mean": float(np.nanmean([r["slip_err"] for r in g["res"]])),
            "stopped": int(sum(r["stopped"] for r in g["res"])),
            "episodes": len(g["res"]),
        })
    return rows


def format_table(rows: Sequence[dict[str, Any]]) -> str:
    """A plain-text table: one line per (policy, scenario)."""
    cells = any(r.get("cell", "nominal") != "nominal" for r in rows)
    head = f"{'policy':<26} {'scenario':<14} " + (f"{'plant':<24} " if cells else "") + \
        f"{'ratio':>16} {'locks':>5} {'|slip-l*|':>9} {'stopped':>7}"
    lines = [head, "-" * len(head)]
    for r in rows:
        plant = f"{r.get('cell', 'nominal'):<24} " if cells else ""
        lines.append(f"{r['policy']:<26} {r['scenario']:<14} {plant}{r['ratio_mean']:>8.3f} +- {r['ratio_std']:<5.3f} "
                     f"{r['locks']:>5d} {r['slip_err_mean']:>9.3f} {r['stopped']:>3d}/{r['episodes']:<3d}")
    return "\n".join(lines)


def write_outputs(rows: Sequence[dict[str, Any]], out_dir: str | Path | None = None,
                  json_path: str | Path | None = None, title: str = "stopping-distance ratio") -> dict[str, Path]:
    """Write ``results.csv`` and ``ratios.png`` in ``out_dir`` and ``{"rows": [...]}`` to ``json_path``.

    :return: the written paths by kind.
    """
    written: dict[str, Path] = {}
    if json_path is not None:
        write_json(json_path, {"rows": list(rows)})
        written["json"] = Path(json_path)
    if out_dir is None:
        return written
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    with atomic_write(out / "results.csv") as fh:
        w = csv.DictWriter(fh, fieldnames=list(ROW_KEYS), lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: json.dumps(r[k]) if k == "effects" else r.get(k, "nominal") if k == "cell" else r[k]
                        for k in ROW_KEYS})
    written["csv"] = out / "results.csv"
    cells = {r.get("cell", "nominal") for r in rows}
    chart = [r for r in rows if r.get("cell", "nominal") == "nominal"] if len(cells) > 1 else rows
    written["png"] = _bar_chart(chart, out / "ratios.png", title)  # one plant per chart: the nominal of a grid
    return written


def _bar_chart(rows, path: Path, title: str) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    policies = list(dict.fromkeys(r["policy"] for r in rows))
    scenarios = list(dict.fromkeys(r["scenario"] for r in rows))
    table = {(r["policy"], r["scenario"]): r for r in rows}
    width = 0.8 / max(len(policies), 1)
    fig, ax = plt.subplots(figsize=(max(8.0, 0.9 * len(scenarios) * max(1, len(policies)) / 3), 4.5))
    x = np.arange(len(scenarios))
    for i, p in enumerate(policies):
        means = [table[(p, s)]["ratio_mean"] if (p, s) in table else np.nan for s in scenarios]
        stds = [table[(p, s)]["ratio_std"] if (p, s) in table else 0.0 for s in scenarios]
        ax.bar(x + (i - (len(policies) - 1) / 2) * width, np.minimum(means, 2.0), width, yerr=stds, label=p,
               capsize=2)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xticks(x, scenarios, rotation=30, ha="right")
    ax.set_ylabel("stopping distance / physical limit")
    ax.set_ylim(0.9, 2.0)
    ax.set_title(title + " (bars clipped at 2)")
    ax.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, dpi=110, format="png")
    plt.close(fig)
    return path


# ---------------------------------------------------------------------------------------------- headline comparison
def summarize_policies(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per policy (and training seed, rows that carry one) over all scenarios: mean and worst ratio, total lock
    events, and the scenarios covered."""
    out = []
    for p, seed in dict.fromkeys((r["policy"], r.get("train_seed")) for r in rows):
        mine = [r for r in rows if r["policy"] == p and r.get("train_seed") == seed]
        out.append({"policy": p, "train_seed": seed, "estimator": mine[0]["estimator"],
                    "ratio_mean": float(np.mean([r["ratio_mean"] for r in mine])),
                    "ratio_worst": float(np.max([r["ratio_mean"] for r in mine])),
                    "locks": int(sum(r["locks"] for r in mine)),
                    "scenarios": [r["scenario"] for r in mine]})
    return out


def _train_job(kwargs: dict) -> dict:
    """One :func:`agents.training.train` run in a worker (one torch thread); its metadata."""
    import torch

    torch.set_num_threads(1)
    from agents.training import train

    result = train(**kwargs)
    return result.meta


# Training cost per env step relative to PPO (measured in fricenv compare: RecurrentPPO's 32-unit LSTM about 5x, the
# MHE in the observation about 2x), for the order in which trainings start
_STEP_COST = {"recurrent-ppo": 5.0}
_ESTIMATOR_STEP_COST = {"mhe": 2.0, "mhe-full": 2.0}


def _training_cost(job: dict) -> float:
    return job["steps"] * _STEP_COST.get(job.get("algo", "ppo"), 1.0) * \
        _ESTIMATOR_STEP_COST.get(job.get("estimator", "none"), 1.0)


def _run_trainings(jobs: list[dict], workers: int, ray: str | None = None) -> list[dict]:
    """Run :func:`agents.training.train` jobs, ``workers`` at a time (or as Ray tasks with ``ray``), the longest
    first, so that no long training is left to run alone at the end; returns their metadata in the jobs' order
    (each training is seeded by its job, so the order does not change a policy)."""
    order = sorted(range(len(jobs)), key=lambda i: -_training_cost(jobs[i]))
    done = map_tasks(_train_job, [(jobs[i],) for i in order], default_jobs(workers), "train", ray=ray)
    metas: list[dict] = [{} for _ in jobs]
    for i, meta in zip(order, done):
        metas[i] = meta
    return metas


def _finished_run(run_dir: Path) -> dict | None:
    meta, model = run_dir / "train.json", run_dir / "model.zip"
    return json.loads(meta.read_text()) if meta.is_file() and model.is_file() else None


# Memory baselines of the headline comparison: no estimate, but memory of the raw ECU observations.
MEMORY_BASELINES: dict[str, dict[str, Any]] = {
    "ppo-stack4": {"algo": "ppo", "frame_stack": 4},  # PPO on the last 4 observations
    "recurrent-ppo": {"algo": "recurrent-ppo"},  # sb3-contrib's RecurrentPPO (LSTM)
}
COMPARE_KEYS = ("policy", "estimator", "train_seed", "scenario", "ratio_mean", "ratio_std", "locks")
TRAINING_KEYS = ("policy", "estimator", "train_seed", "steps", "wall_time_s", "steps_per_second", "cpu_time_s")


def _training_jobs(out: Path, estimators: Sequence[str], baselines: Sequence[str], algo: str, steps: int,
                   train_seeds: Sequence[int]) -> dict[str, dict]:
    """Row label with seed -> :func:`agents.training.train` arguments, one per (row, training seed)."""
    rows: dict[str, dict] = {f"{algo}-{est}": {"estimator": est, "algo": algo} for est in estimators}
    for name in baselines:
        if name not in MEMORY_BASELINES:
            raise ValueError(f"unknown memory baseline {name!r}; valid: {', '.join(MEMORY_BASELINES)}")
        rows[name] = {"estimator": "none", **MEMORY_BASELINES[name]}
    return {f"{name}#s{seed}": {"out": out / f"{name}-s{seed}", "env": "braking", "steps": steps, "seed": seed,
                                "progress_bar": False, **kw}
            for name, kw in rows.items() for seed in train_seeds}


def check_compare_args(estimators: Sequence[str], baselines: Sequence[str], pipeline: str,
                       train_seeds: Sequence[int]) -> None:
    """Validate the rows of :func:`compare_abs` before any training (ValueError naming the bad one)."""
    from fricenv.envs.estimator_observation import check_estimator_name

    for est in estimators:
        check_estimator_name(est)
    for name in baselines:
        if name not in MEMORY_BASELINES:
            raise ValueError(f"unknown memory baseline {name!r}; valid: {', '.join(MEMORY_BASELINES)}")
    parse_policy(f"{PIPELINE_PREFIX}{pipeline}")
    if not train_seeds:
        raise ValueError("train_seeds must name at least one training seed")


def compare_abs(out: str | Path, estimators: Sequence[str] = ("none", "ekf-rls", "oracle"),
                algo: str = "ppo", steps: int = 300_000, pipeline: str = "ekf-rls", train_seeds: Sequence[int] = (0,),
                seeds: int = DEFAULT_SEEDS, workers: int = 2, reuse: bool = False,
                baselines: Sequence[str] = tuple(MEMORY_BASELINES), ray: str | None = None,
                scenarios: Sequence[Scenario] | None = None) -> dict[str, Any]:
    """Train every row on every training seed, then evaluate them with the rule ABS and the pipeline.

    :param out: directory; runs go to ``out/<row>-s<seed>`` (rows ``<algo>-<estimator>`` and the baselines).
    :param estimators: observation estimators of the trained rows.
    :param algo: ``ppo`` or ``sac`` (the estimator rows).
    :param steps: training steps per policy.
    :param pipeline: estimator of the estimator + slip controller row.
    :param train_seeds: training seeds; every trained row is trained once per seed.
    :param seeds: evaluation seeds (0..seeds-1; the training scenarios are drawn from other generators).
    :param workers: parallel processes (trainings, then evaluation jobs).
    :param reuse: reuse finished runs in ``out``.
    :param baselines: memory baselines (:data:`MEMORY_BASELINES`) trained without estimates.
    :param ray: None (local processes), ``"auto"`` or a Ray cluster address: trainings and evaluation jobs run as
        Ray tasks (``out`` must then be on a file system every node sees).
    :param scenarios: evaluation scenarios (default :data:`SCENARIOS`; the effect grid's:
        :func:`agents.effect_scenarios.grid_scenarios`).
    :return: ``rows`` (:data:`COMPARE_KEYS` and more), ``training`` (:data:`TRAINING_KEYS` per run),
        ``evaluation_time_s``.
    """
    import time

    out = Path(out)
    check_compare_args(estimators, baselines, pipeline, train_seeds)
    jobs = _training_jobs(out, estimators, baselines, algo, steps, train_seeds)
    metas = {key: _finished_run(job["out"]) if reuse else None for key, job in jobs.items()}
    todo = [key for key, meta in metas.items() if meta is None]
    metas.update(zip(todo, _run_trainings([jobs[k] for k in todo], workers, ray)))
    specs = []
    for job in jobs.values():
        spec = parse_policy(str(job["out"]))
        specs.append(dataclasses.replace(spec, label=f"{spec.label}#s{job['seed']}"))
    t0 = time.perf_counter()
    rows = evaluate(specs + ["rule-abs", f"{PIPELINE_PREFIX}{pipeline}"], scenarios=scenarios or SCENARIOS,
                    seeds=seeds, workers=workers, ray=ray)
    for row in rows:
        label, _, seed = row["policy"].partition("#s")
        row["policy"], row["train_seed"] = label, int(seed) if seed else None
    training = [{"policy": spec.label.partition("#s")[0], "estimator": metas[key]["estimator"],
                 "train_seed": jobs[key]["seed"], "steps": metas[key]["steps"],
                 "wall_time_s": metas[key]["wall_time_s"], "steps_per_second": metas[key]["steps_per_second"],
                 "cpu_time_s": metas[key].get("cpu_time_s")}  # None for runs made before it was recorded
                for key, spec in zip(jobs, specs)]
    return {"rows": rows, "training": training, "evaluation_time_s": time.perf_counter() - t0}


def compare_excitation(out: str | Path, steps: int = 100_000, seed: int = 0, episodes: int = 3, workers: int = 2,
                       reuse: bool = False, calibration: str = "paper", ray: str | None = None) -> dict[str, Any]:
    """Excitation policies on PayloadExcitation-v0: PPO without and with the RLS estimate S_hat in the
    observation, against the paper's multi-sine and a PRBS (same episodes, workspace and actuator limits). The
    two trainings run in ``workers`` processes or as Ray tasks (``ray``: ``"auto"`` or an address).

    :return: ``rows`` (policy, ``t_below_1e-2`` median [s] or None, ``E_end`` median, ``effort`` mean,
        ``left_workspace``), ``training`` metadata.
    """
    from agents.excitation import evaluate as evaluate_excitation
    from agents.excitation import run_episode as run_excitation
    from agents.training import load_policy
    from fricenv.envs.factory import make_payload

    out = Path(out)
    run_dirs = {est: out / f"ppo-payload-{est}" for est in ("none", "rls")}
    metas, jobs = {}, []
    for est, d in run_dirs.items():
        done = _finished_run(d) if reuse else None
        if done is not None:
            metas[est] = done
        else:
            jobs.append({"out": d, "env": "payload", "estimator": est, "algo": "ppo", "steps": steps, "seed": seed,
                         "progress_bar": False})
    for job, meta in zip(jobs, _run_trainings(jobs, workers, ray)):
        metas[job["estimator"]] = meta
    rows = evaluate_excitation(("multisine", "prbs"), episodes=episodes, seed=0,
                               env_kwargs={"calibration": calibration})
    for est, d in run_dirs.items():
        policy = load_policy(d)
        env = make_payload(est, calibration=calibration)
        eps = [run_excitation(env, policy, seed=k) for k in range(episodes)]
        tb = [np.inf if r.t_below is None else r.t_below for r in eps]
        med = float(np.median(tb))
        rows.append({"policy": f"ppo[{'S_hat' if est == 'rls' else 'no S_hat'}]",
                     "t_below_1e-2": med if np.isfinite(med) else None,
                     "E_end": float(np.median([r.E_end for r in eps])),
                     "effort": float(np.mean([r.effort for r in eps])),
                     "return": float(np.mean([r.ret for r in eps])),
                     "left_workspace": int(sum(r.left_workspace for r in eps))})
    for r in rows:
        r.pop("episodes", None)
    return {"rows": rows, "training": [metas[e] for e in run_dirs]}
