"""Tune the ABS task's hyperparameters with Optuna (TPE sampler, median pruner), for ``fricenv train --hyperparams``.

Each trial samples PPO's hyperparameters (``--algos ppo sac`` also searches SAC, the algorithm being one more
parameter), trains with ``fricenv train``'s curriculum for ``--steps`` on the TUNING training seeds and, after each
of ``--evals`` stages, scores the policy on the TUNING scenarios (dry, wet with its early peak, ice, dry->ice and
ice->dry at 25 m/s) over the TUNING evaluation seeds:

    score = mean stopping-distance ratio + 0.5 x (worst scenario's mean ratio - 1) + 0.1 x share of locked episodes

(lower is better; agents.tuning.WORST_WEIGHT and LOCK_PENALTY); the pruner stops trials worse than the median at
the same stage.

Seed split: tuning trains on seeds 100..899 (default 101; env seeds s*1000+i) and evaluates on reset seeds
>= 900000 (default 900000, 900001), disjoint from the reset seeds 0..N-1 of ``fricenv evaluate`` and ``compare``
and from compare's training seeds 0, 1, 2. Both output files state the split.

A new study first runs the committed configuration of each algorithm (``agents/hyperparams/braking.json``) on the
same seeds, so its score is the bar the search must beat (``--no-baseline``: not).

Writes into ``--out``: ``hyperparams.json`` (the best trial's configuration per algorithm, the format of
``agents/hyperparams/braking.json``: ``fricenv train --hyperparams OUT/hyperparams.json``) and ``trials.json``
(every trial with its parameters, intermediate scores and state).

Parallel: ``--storage`` names an Optuna storage shared by the workers (``sqlite:///study.db``, or a file path: an
Optuna journal file, safest for several processes); ``--workers N`` local processes or, with ``--ray auto|ADDRESS``,
N Ray tasks each run ``study.optimize`` on it (on a cluster the storage must be reachable from every node: a
journal file on a shared file system or a database URL). Re-running with the same ``--storage`` and
``--study-name`` resumes the study: ``--trials`` more trials are added.
"""

from __future__ import annotations

import argparse

ALGO_CHOICES = ("ppo", "sac")  # agents.tuning.ALGOS (not imported: CLI start-up)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``fricenv tune``."""
    parser.add_argument("--out", default="runs/tune", metavar="DIR",
                        help="output directory for hyperparams.json and trials.json (default %(default)s)")
    parser.add_argument("--trials", type=int, default=8, help="trials this run adds (default %(default)s)")
    parser.add_argument("--steps", type=int, default=30_000, help="training steps per trial (default %(default)s)")
    parser.add_argument("--evals", type=int, default=3,
                        help="scoring stages per trial, the pruning points (default %(default)s)")
    parser.add_argument("--algos", nargs="+", choices=ALGO_CHOICES, default=["ppo"],
                        help="algorithms searched (default: %(default)s)")
    parser.add_argument("--estimator", default="ekf-rls",
                        help="observation estimator of the tuned policies (default %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="sampler seed (default %(default)s)")
    parser.add_argument("--train-seeds", type=int, nargs="+", default=None, metavar="S",
                        help="tuning training seeds, in 100..899 (default 101)")
    parser.add_argument("--eval-seeds", type=int, nargs="+", default=None, metavar="S",
                        help="tuning evaluation reset seeds, >= 900000 (default 900000 900001)")
    parser.add_argument("--no-baseline", action="store_true",
                        help="do not run the committed configuration as the first trial of a new study")
    parser.add_argument("--storage", default=None, metavar="URL|PATH",
                        help="Optuna storage shared by the workers: sqlite:///study.db or a journal file path "
                             "(default: in memory, one worker, no resume)")
    parser.add_argument("--study-name", default="fricenv-tune", help="study name in --storage (default %(default)s)")
    parser.add_argument("--workers", type=int, default=1,
                        help="worker processes, or Ray tasks with --ray, each running study.optimize (default "
                             "%(default)s)")
    parser.add_argument("--ray", metavar="auto|ADDRESS", default=None,
                        help="run the workers as Ray tasks: 'auto' (a running instance, else a local one) or a "
                             "cluster address")


def run(args) -> int:
    """Run or resume the study; print the best trial and the files written."""
    from agents.tuning import TUNING_EVAL_SEEDS, TUNING_TRAIN_SEEDS, TuneSettings, run_study

    settings = TuneSettings(out=args.out, algos=tuple(args.algos), estimator=args.estimator, steps=args.steps,
                            n_trials=args.trials, n_evals=args.evals, seed=args.seed,
                            train_seeds=tuple(args.train_seeds or TUNING_TRAIN_SEEDS),
                            eval_seeds=tuple(args.eval_seeds or TUNING_EVAL_SEEDS), storage=args.storage,
                            study_name=args.study_name, workers=args.workers, ray=args.ray,
                            baseline=not args.no_baseline)
    settings.check()  # a TuningError is one line on the CLI's error path, before any work
    engine = f"{args.workers} Ray task(s) on {args.ray}" if args.ray else f"{args.workers} worker(s)"
    print(f"study {args.study_name!r}: {args.trials} trial(s) x {args.steps} steps, {engine}, storage "
          f"{args.storage or 'in memory'}; tuning seeds: train {list(settings.train_seeds)}, evaluation "
          f"{list(settings.eval_seeds)}")
    result = run_study(settings)
    best = result.best
    attrs = best["user_attrs"]
    print(f"{result.n_new} new trial(s), {result.n_trials} in the study, {result.wall_time_s:.0f} s")
    print(f"best trial {best['number']} ({best['algo']}): score {best['value']:.4f}, mean ratio "
          f"{attrs.get('ratio_mean', float('nan')):.4f}, {attrs.get('locks', 0)} lock episode(s)")
    print(f"wrote {result.hyperparams_path} (fricenv train --hyperparams {result.hyperparams_path})")
    print(f"wrote {result.trials_path}")
    return 0
