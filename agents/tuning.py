"""Optuna hyperparameter search for ``fricenv train`` on the ABS task, as
rl-baselines3-zoo does it: a seeded TPE sampler, a median pruner, and an objective that trains with
:mod:`agents.training` and scores the policy on held-out episodes.

Objective of a trial: sample an algorithm (among ``algos``; PPO by default, SAC where asked: both run on
``Braking-v0`` and both are read by ``fricenv train --hyperparams``) and its hyperparameters (:data:`SAMPLERS`),
train one policy per *tuning training seed* for ``steps`` env steps in ``n_evals`` stages, and after each stage
score every policy on the *tuning scenario set* (:data:`TUNING_SCENARIOS`: dry, wet with its early peak at slip
0.088, ice, and the friction jumps dry->ice and ice->dry, all at 25 m/s) over the *tuning evaluation seeds*::

    score = mean ratio + WORST_WEIGHT * (worst scenario's mean ratio - 1) + LOCK_PENALTY * (share of episodes
            with a wheel lock)                                                                   (lower is better)

(the worst scenario counts because the target is every scenario within 5 %, not the mean: a policy that
over-brakes wet by 25 % and is perfect elsewhere must not win).

The stage's score is reported to the pruner, which stops a trial whose score is worse than the median of the
earlier trials at the same stage (never after the last stage: a finished trial keeps its score). A new study first runs the committed configuration of each algorithm
(:func:`committed_params`), so the search is measured against it on the same seeds. Parameter names carry their
algorithm (``ppo_gamma``, ``sac_gamma``).

Seed split (:func:`seed_split`, written into both output files): ``fricenv evaluate`` and ``compare`` reset their
episodes with seeds ``0..N-1`` and ``compare`` trains on seeds 0, 1, 2 (env ``i`` of a run with seed ``s`` is
seeded ``s * 1000 + i``). Tuning trains on seeds in ``[100, 899]`` (env seeds ``100000..899999``) and evaluates on
reset seeds ``>= 900000``: the chosen hyperparameters never saw an episode of the final evaluation.

Parallel search: ``workers`` processes, or Ray tasks with ``ray``, each calling ``study.optimize`` on one shared
Optuna ``storage`` (an RDB URL such as ``sqlite:///study.db``, or a path: an Optuna journal file, the safer choice
for several processes). A study resumes when run again with the same storage and study name: the new trials are
added to the old ones. Optuna is imported only when a study runs.

Outputs in ``out``: :data:`HYPERPARAMS_FILE` (the best trial's configuration per algorithm, in the format of
``agents/hyperparams/braking.json``) and :data:`TRIALS_FILE` (every trial: number, state, value, parameters,
intermediate scores, attributes).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from agents.evaluation import CHANGE_DISTANCE, Scenario, run_controller
from agents.training import DEFAULT_CONFIGS, SEED_STRIDE, PPOConfig, SACConfig
from fricenv.errors import InvalidInputError
from fricenv.gap.core.pool import map_tasks
from fricenv.utils import write_json

__all__ = [
    "HYPERPARAMS_FILE",
    "SAMPLERS",
    "TRIALS_FILE",
    "TUNING_EVAL_SEEDS",
    "TUNING_SCENARIOS",
    "TUNING_TRAIN_SEEDS",
    "TuneResult",
    "TuneSettings",
    "TuningError",
    "committed_params",
    "config_from_params",
    "run_study",
    "sample_config",
    "seed_split",
    "train_and_score",
]

TUNING_V0 = 25.0  # initial speed of the tuning scenarios [m/s] (evaluation: 20 and 30)
TUNING_SCENARIOS: tuple[Scenario, ...] = tuple(
    Scenario(road, TUNING_V0) for road in ("dry", "wet", "ice", "dry->ice", "ice->dry"))
TRAIN_SEED_RANGE = (100, 899)  # tuning training seeds (env seeds s * SEED_STRIDE + i: 100000..899999)
EVAL_SEED_MIN = 900_000  # tuning evaluation reset seeds start here (evaluate/compare use 0..N-1)
TUNING_TRAIN_SEEDS = (101,)
TUNING_EVAL_SEEDS = (900_000, 900_001)
LOCK_PENALTY = 0.1  # score added per unit share of episodes with a wheel lock [-]
WORST_WEIGHT = 0.5  # score added per unit excess ratio of the worst tuning scenario (its mean over seeds) [-]
N_STARTUP_TRIALS = 4  # random trials before TPE models the results (and before the pruner prunes)
HYPERPARAMS_FILE = "hyperparams.json"
TRIALS_FILE = "trials.json"
ALGOS = ("ppo", "sac")  # the algorithms `fricenv train --hyperparams` reads
CONFIG_CLASSES: dict[str, type] = {"ppo": PPOConfig, "sac": SACConfig}
NET_ARCHS = {"small": (64, 64), "medium": (128, 128), "large": (256, 256)}


class TuningError(InvalidInputError):
    """Settings of a study that cannot run (one line saying what to change)."""


# --------------------------------------------------------------------------------------------- search spaces
def sample_ppo(trial) -> dict[str, Any]:
    """PPO fields (rl-baselines3-zoo's space, narrowed to the ABS task's 10 ms steps and dense reward)."""
    n_envs = trial.suggest_categorical("n_envs", [16, 32])
    n_steps = trial.suggest_categorical("n_steps", [64, 128, 256])
    return {
        "n_envs": n_envs, "n_steps": n_steps,
        "batch_size": min(trial.suggest_categorical("batch_size", [64, 128, 256, 512, 1024]), n_envs * n_steps),
        "n_epochs": trial.suggest_categorical("n_epochs", [5, 10, 20]),
        "learning_rate": trial.suggest_float("learning_rate", 5e-5, 3e-3, log=True),
        "gamma": trial.suggest_categorical("gamma", [0.9, 0.95, 0.98, 0.99]),
        "gae_lambda": trial.suggest_categorical("gae_lambda", [0.8, 0.9, 0.95, 0.98]),
        "clip_range": trial.suggest_categorical("clip_range", [0.1, 0.2, 0.3]),
        "ent_coef": trial.suggest_categorical("ent_coef", [0.0, 1e-4, 1e-3, 1e-2]),
        "vf_coef": trial.suggest_float("vf_coef", 0.2, 1.0),
        "max_grad_norm": trial.suggest_categorical("max_grad_norm", [0.3, 0.5, 1.0, 2.0]),
        "log_std_init": trial.suggest_float("log_std_init", -2.5, -0.5),
        "net_arch": NET_ARCHS[trial.suggest_categorical("net_arch", ["small", "medium"])],
    }


def sample_sac(trial) -> dict[str, Any]:
    """SAC fields (rl-baselines3-zoo's space; one gradient step per env step collected)."""
    train_freq = trial.suggest_categorical("train_freq", [1, 4, 8])
    return {
        "learning_rate": trial.suggest_float("learning_rate", 5e-5, 3e-3, log=True),
        "batch_size": trial.suggest_categorical("batch_size", [128, 256, 512]),
        "gamma": trial.suggest_categorical("gamma", [0.9, 0.95, 0.98, 0.99]),
        "tau": trial.suggest_categorical("tau", [0.005, 0.01, 0.02]),
        "learning_starts": trial.suggest_categorical("learning_starts", [1000, 5000]),
        "train_freq": train_freq, "gradient_steps": train_freq,
        "net_arch": NET_ARCHS[trial.suggest_categorical("net_arch", ["small", "large"])],
    }


SAMPLERS: dict[str, Callable[[Any], dict[str, Any]]] = {"ppo": sample_ppo, "sac": sample_sac}


class _Named:
    """A trial whose parameter names carry the algorithm (``ppo_gamma``, ``sac_gamma``): Optuna needs one
    distribution per name in a study, and the algorithms' spaces differ."""

    def __init__(self, trial, algo: str):
        self.trial, self.prefix = trial, f"{algo}_"

    def suggest_categorical(self, name: str, choices: list):
        return self.trial.suggest_categorical(self.prefix + name, choices)

    def suggest_float(self, name: str, low: float, high: float, log: bool = False) -> float:
        return self.trial.suggest_float(self.prefix + name, low, high, log=log)


def sample_config(trial, algos: Sequence[str]) -> tuple[str, PPOConfig | SACConfig]:
    """The algorithm (a categorical ``algo`` when ``algos`` has several) and its config: the committed braking
    defaults with the sampled fields replaced.

    :param trial: an Optuna trial (or ``optuna.trial.FixedTrial`` to rebuild a config from its parameters).
    :param algos: the algorithms searched (of :data:`ALGOS`).
    """
    algo = trial.suggest_categorical("algo", list(algos)) if len(algos) > 1 else algos[0]
    return algo, dataclasses.replace(DEFAULT_CONFIGS[("braking", algo)], **SAMPLERS[algo](_Named(trial, algo)))


class _Recorder:
    """A trial that records the parameter names a sampler asks for (and answers with the first choice)."""

    def __init__(self):
        self.names: list[str] = []

    def suggest_categorical(self, name: str, choices: list):
        self.names.append(name)
        return choices[0]

    def suggest_float(self, name: str, low: float, high: float, log: bool = False) -> float:
        self.names.append(name)
        return low


def committed_params(algo: str, algos: Sequence[str]) -> dict[str, Any] | None:
    """The trial parameters of the committed configuration (``agents/hyperparams/braking.json``), or None when it
    lies outside the search space. A new study runs it first, so its score is the bar the search must beat."""
    cfg = DEFAULT_CONFIGS[("braking", algo)]
    recorder = _Recorder()
    SAMPLERS[algo](recorder)
    arch = {v: k for k, v in NET_ARCHS.items()}.get(tuple(cfg.net_arch))
    params = {f"{algo}_{n}": arch if n == "net_arch" else getattr(cfg, n) for n in recorder.names}
    if len(algos) > 1:
        params["algo"] = algo
    try:
        replayed = config_from_params(params, algos)
    except ValueError:  # a committed value that is not among the choices
        return None
    return params if replayed == (algo, cfg) else None


def config_from_params(params: dict[str, Any], algos: Sequence[str]) -> tuple[str, PPOConfig | SACConfig]:
    """The algorithm and config a trial with these parameters trained (:func:`sample_config` replayed)."""
    from optuna.trial import FixedTrial

    return sample_config(FixedTrial(params), algos)


# --------------------------------------------------------------------------------------------------- settings
def _check_seeds(train_seeds: Sequence[int], eval_seeds: Sequence[int]) -> None:
    lo, hi = TRAIN_SEED_RANGE
    if not train_seeds or any(not lo <= int(s) <= hi for s in train_seeds):
        raise TuningError(f"tuning training seeds must be in [{lo}, {hi}] (apart from the training seeds 0, 1, 2 "
                          f"of fricenv compare), got {list(train_seeds)}")
    if not eval_seeds or any(int(s) < EVAL_SEED_MIN for s in eval_seeds):
        raise TuningError(f"tuning evaluation seeds must be >= {EVAL_SEED_MIN} (fricenv evaluate and compare use "
                          f"0..N-1), got {list(eval_seeds)}")


@dataclass(frozen=True)
class TuneSettings:
    """One study: what is searched, on which seeds and scenarios, stored where, run by how many workers.

    :param out: output directory (:data:`HYPERPARAMS_FILE`, :data:`TRIALS_FILE`).
    :param algos: algorithms searched (of :data:`ALGOS`).
    :param estimator: observation estimator of the trained policies.
    :param steps: env steps per training run of a trial.
    :param n_trials: trials this run adds to the study.
    :param n_evals: scoring stages per trial (pruning points).
    :param seed: sampler seed.
    :param train_seeds: tuning training seeds (in :data:`TRAIN_SEED_RANGE`).
    :param eval_seeds: tuning evaluation reset seeds (>= :data:`EVAL_SEED_MIN`).
    :param scenarios: the scenario set of the score.
    :param baseline: a new study first runs the committed configuration of each algorithm.
    :param storage: Optuna storage shared by the workers (RDB URL or journal file path); None: in memory.
    :param study_name: the study's name in the storage.
    :param workers: local worker processes (each runs ``study.optimize``); not used with ``ray``.
    :param ray: None, ``"auto"`` or a Ray address: one Ray task per worker.
    """

    out: str
    algos: tuple[str, ...] = ("ppo",)
    estimator: str = "ekf-rls"
    steps: int = 30_000
    n_trials: int = 8
    n_evals: int = 3
    seed: int = 0
    train_seeds: tuple[int, ...] = TUNING_TRAIN_SEEDS
    eval_seeds: tuple[int, ...] = TUNING_EVAL_SEEDS
    scenarios: tuple[Scenario, ...] = field(default=TUNING_SCENARIOS, hash=False)
    storage: str | None = None
    study_name: str = "fricenv-tune"
    baseline: bool = True
    workers: int = 1
    ray: str | None = None

    def check(self) -> None:
        """Raise :class:`TuningError` (one line) on settings that cannot run."""
        from fricenv.envs.estimator_observation import check_estimator_name

        bad = [a for a in self.algos if a not in ALGOS]
        if not self.algos or bad:
            raise TuningError(f"unknown algorithm(s) {bad or '(none given)'}; valid: {', '.join(ALGOS)}")
        for name in ("steps", "n_trials", "n_evals", "workers"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise TuningError(f"{name} must be a positive integer, got {value!r}")
        if self.steps < self.n_evals:
            raise TuningError(f"steps ({self.steps}) must be at least n_evals ({self.n_evals})")
        if self.storage is None and (self.workers > 1 or self.ray is not None):
            raise TuningError("several workers or --ray need a shared --storage (sqlite:///study.db or a journal "
                              "file path)")
        if not self.scenarios:
            raise TuningError("the scenario set of the objective is empty")
        _check_seeds(self.train_seeds, self.eval_seeds)
        try:
            check_estimator_name(self.estimator)
        except ValueError as exc:
            raise TuningError(f"estimator: {exc}") from None


def seed_split(settings: TuneSettings) -> dict[str, Any]:
    """The seeds of the study and those of the final evaluation, for the output files and the help."""
    return {
        "tuning_train_seeds": list(settings.train_seeds),
        "tuning_train_env_seeds": f"s * {SEED_STRIDE} + i for s in tuning_train_seeds, i < n_envs",
        "tuning_eval_seeds": list(settings.eval_seeds),
        "tuning_scenarios": [s.name for s in settings.scenarios],
        "evaluation_seeds": f"fricenv evaluate / compare reset seeds 0..N-1 (disjoint for N <= {EVAL_SEED_MIN})",
        "compare_train_seeds": "0, 1, 2 (fricenv compare --train-seeds default)",
    }


# -------------------------------------------------------------------------------------------------- objective
def _model(algo: str, cfg, estimator: str, seed: int):
    """An SB3 model on the training curriculum, as :func:`agents.training.train` builds it (no files)."""
    from agents.training import make_training_model, native_vec_available

    vec = "native" if native_vec_available("braking", estimator) else "dummy"
    return make_training_model("braking", estimator, algo, cfg, seed, vec)


def _score(model, algo: str, cfg, settings: TuneSettings) -> tuple[float, int, int, float]:
    """Mean ratio, lock episodes, episodes and the worst scenario's mean ratio of the model's deterministic policy
    on the tuning set."""
    from agents.training import TrainedPolicy
    from fricenv.envs.factory import make_braking

    policy = TrainedPolicy(model, model.get_env(), {"estimator": settings.estimator, "algo": algo,
                                                    "config": dataclasses.asdict(cfg)})
    ratios, locks = [], 0
    for sc in settings.scenarios:
        env = make_braking(settings.estimator, road=sc.road, v0=sc.v0, change_distance=CHANGE_DISTANCE)
        try:
            for seed in settings.eval_seeds:
                episode = run_controller(policy, env, int(seed))
                ratios.append(episode["ratio"])
                locks += episode["lock"]
        finally:
            env.close()
    per_scenario = np.reshape(ratios, (len(settings.scenarios), len(settings.eval_seeds))).mean(axis=1)
    return float(np.mean(ratios)), locks, len(ratios), float(per_scenario.max())


def train_and_score(trial, settings: TuneSettings) -> float:
    """The objective (module docstring): train on every tuning training seed in stages, report each stage's
    score to the pruner, return the last one.

    :raises optuna.TrialPruned: the pruner stopped the trial.
    """
    import optuna
    import torch

    torch.set_num_threads(1)
    algo, cfg = sample_config(trial, settings.algos)
    models = [_model(algo, cfg, settings.estimator, seed) for seed in settings.train_seeds]
    chunk = settings.steps // settings.n_evals
    t0 = time.perf_counter()
    score = float("inf")
    for stage in range(settings.n_evals):
        for m in models:
            m.learn(total_timesteps=chunk, reset_num_timesteps=stage == 0)
        scored = [_score(m, algo, cfg, settings) for m in models]
        ratio = float(np.mean([s[0] for s in scored]))
        locks, episodes = sum(s[1] for s in scored), sum(s[2] for s in scored)
        worst = max(s[3] for s in scored)
        score = ratio + WORST_WEIGHT * (worst - 1.0) + LOCK_PENALTY * locks / episodes
        trial.set_user_attr("ratio_mean", ratio)
        trial.set_user_attr("ratio_worst", worst)
        trial.set_user_attr("locks", locks)
        trial.set_user_attr("steps", int(models[0].num_timesteps))
        trial.set_user_attr("train_eval_seconds", time.perf_counter() - t0)
        trial.report(score, stage)
        if stage < settings.n_evals - 1 and trial.should_prune():  # a finished trial keeps its score
            raise optuna.TrialPruned()
    return score


# ----------------------------------------------------------------------------------------------- study and workers
def _storage(url: str | None):
    """An Optuna storage: None (in memory), an RDB URL (``scheme://...``) or a journal file path."""
    if url is None or "://" in url:
        return url
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    return JournalStorage(JournalFileBackend(str(url)))


def _study(settings: TuneSettings, worker: int, storage=None):
    """Create or load the study. The sampler's seed depends on the seed, the worker and the trials already in the
    study, so a resumed or parallel study does not repeat earlier draws, and one worker on one study state always
    draws the same parameters."""
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    storage = storage if storage is not None else _storage(settings.storage)
    study = optuna.create_study(storage=storage, study_name=settings.study_name, direction="minimize",
                                load_if_exists=True,
                                pruner=optuna.pruners.MedianPruner(n_startup_trials=N_STARTUP_TRIALS,
                                                                   n_warmup_steps=1))
    done = len(study.trials)
    seed = int(np.random.SeedSequence([settings.seed, worker, done]).generate_state(1)[0])
    study.sampler = optuna.samplers.TPESampler(seed=seed, n_startup_trials=N_STARTUP_TRIALS)
    return study


def _optimize(settings: TuneSettings, n_trials: int, worker: int, objective: Callable, study=None) -> int:
    """One worker: ``study.optimize`` for ``n_trials`` on the shared study; the number of trials it ran."""
    study = study if study is not None else _study(settings, worker)
    study.optimize(lambda trial: objective(trial, settings), n_trials=n_trials, catch=(ValueError,))
    return n_trials


def _open(settings: TuneSettings, worker: int = 0):
    """The study, opened in this process; one-line :class:`TuningError` when the storage cannot be opened."""
    try:
        return _study(settings, worker)
    except Exception as exc:  # noqa: BLE001 - SQLAlchemy, journal and URL errors alike meet the user here
        from fricenv.errors import one_line

        raise TuningError(f"cannot open Optuna storage {settings.storage!r}: {one_line(exc)}; give "
                          f"sqlite:///FILE.db or a journal file path") from None


@dataclass
class TuneResult:
    """What a study run produced."""

    hyperparams_path: Path
    trials_path: Path
    n_trials: int  # trials in the study after this run
    n_new: int  # trials this run added
    best: dict[str, Any]  # number, value, algo, params, user_attrs of the best trial
    wall_time_s: float


def run_study(settings: TuneSettings, objective: Callable = train_and_score) -> TuneResult:
    """Run (or resume) the study and write :data:`HYPERPARAMS_FILE` and :data:`TRIALS_FILE` into ``settings.out``.

    :param settings: the study.
    :param objective: ``(trial, settings) -> score`` to minimise, a module-level function (workers import it);
        :func:`train_and_score` by default.
    """
    settings.check()
    t0 = time.perf_counter()
    study = _open(settings)
    before = len(study.trials)
    if before == 0 and settings.baseline:
        for algo in settings.algos:
            params = committed_params(algo, settings.algos)
            if params is not None:
                study.enqueue_trial(params, user_attrs={"baseline": "agents/hyperparams/braking.json"})
    if settings.storage is None:
        _optimize(settings, settings.n_trials, 0, objective, study)
    else:
        n_workers = settings.workers  # local processes, or Ray tasks
        share = [settings.n_trials // n_workers + (w < settings.n_trials % n_workers) for w in range(n_workers)]
        tasks = [(settings, n, w, objective) for w, n in enumerate(share) if n]
        map_tasks(_optimize, tasks, len(tasks), "tune", ray=settings.ray)
        study = _open(settings)
    return _write(study, settings, len(study.trials) - before, time.perf_counter() - t0)


def _trial_row(trial) -> dict[str, Any]:
    return {"number": trial.number, "state": trial.state.name, "value": trial.value, "params": trial.params,
            "intermediate": {str(k): v for k, v in sorted(trial.intermediate_values.items())},
            "user_attrs": trial.user_attrs,
            "seconds": (trial.datetime_complete - trial.datetime_start).total_seconds()
            if trial.datetime_complete and trial.datetime_start else None}


def _write(study, settings: TuneSettings, n_new: int, wall: float) -> TuneResult:
    """Write the best configuration per algorithm and every trial (module docstring)."""
    complete = sorted((t for t in study.trials if t.state.name == "COMPLETE"), key=lambda t: t.value)
    if not complete:
        raise TuningError(f"no trial of study {settings.study_name!r} completed (all pruned or failed); "
                          f"run more trials or more steps")
    out = Path(settings.out)
    out.mkdir(parents=True, exist_ok=True)
    best_by_algo: dict[str, Any] = {}
    for t in complete:  # best first
        algo, cfg = config_from_params(t.params, settings.algos)
        best_by_algo.setdefault(algo, (t, cfg))
    best = complete[0]
    summary = {"number": best.number, "value": best.value, "algo": config_from_params(best.params,
                                                                                         settings.algos)[0],
               "params": best.params, "user_attrs": best.user_attrs}
    split = seed_split(settings)
    doc = {"_comment": (f"Optuna study {settings.study_name!r} (fricenv tune): best of {len(complete)} complete "
                        f"trial(s) per algorithm, {settings.steps} steps each, estimator {settings.estimator}; "
                        f"score = mean ratio + {WORST_WEIGHT} x (worst scenario's mean ratio - 1) + "
                        f"{LOCK_PENALTY} x lock share on the tuning scenarios and seeds."),
           "_seeds": split,
           "_best": {algo: {"trial": t.number, "score": t.value} for algo, (t, _) in best_by_algo.items()}}
    doc.update({algo: dataclasses.asdict(cfg) for algo, (_, cfg) in best_by_algo.items()})
    hp, tr = out / HYPERPARAMS_FILE, out / TRIALS_FILE
    write_json(hp, doc)
    write_json(tr, {"study": settings.study_name, "storage": settings.storage, "direction": "minimize",
                    "estimator": settings.estimator, "steps": settings.steps, "n_evals": settings.n_evals,
                    "seeds": split, "best": summary, "trials": [_trial_row(t) for t in study.trials]})
    return TuneResult(hp, tr, len(study.trials), n_new, summary, wall)
