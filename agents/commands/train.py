"""Train an ABS (Braking-v0) or excitation (PayloadExcitation-v0) policy with stable-baselines3 (PPO or SAC).

Braking: randomised roads per episode (a preset, or a friction change between two presets during the stop),
initial speed 15-32 m/s, the chosen estimator's outputs appended to the observation. Payload: random calibration
S per episode, with (``--estimator rls``) or without (``none``) the RLS estimate of S in the observation.
Writes ``model.zip``, ``vecnormalize.pkl``, ``checkpoints/``, ``train.json`` (and ``tb/`` if TensorBoard is
installed) into ``--out``.
"""

from __future__ import annotations

import argparse

ENV_CHOICES = ("braking", "payload")
VEC_CHOICES = ("auto", "native", "dummy", "subproc")  # agents.training.VEC_KINDS (not imported: CLI start-up)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``fricenv train``."""
    parser.add_argument("--env", choices=ENV_CHOICES, default="braking", help="task (default %(default)s)")
    parser.add_argument("--estimator", default="none",
                        help="observation estimator: braking none|ekf|mhe|ekf-rls|oracle|ekf-full|mhe-full, "
                             "payload none|rls|oracle (default %(default)s)")
    parser.add_argument("--algo", choices=("ppo", "sac", "recurrent-ppo"), default="ppo",
                        help="algorithm (default %(default)s)")
    parser.add_argument("--steps", type=int, default=500_000, help="env steps (default %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="seed (default %(default)s)")
    parser.add_argument("--out", required=True, metavar="DIR", help="run directory")
    parser.add_argument("--vec", choices=VEC_CHOICES, default="auto",
                        help="vector env: native (all cars and a batched estimator in one numpy call), dummy (single "
                             "envs in one process), subproc (one process each); auto: native where the estimator "
                             "has a batched form (default %(default)s)")
    parser.add_argument("--hyperparams", metavar="PATH", default=None,
                        help="hyperparameter JSON file (algorithm -> config fields); default: the committed "
                             "agents/hyperparams/braking.json for braking")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--json", metavar="PATH", help="write the run summary (wall time, steps/s) as JSON")


def run(args) -> int:
    """Train and save; print wall time and steps per second."""
    from agents.hyperparams import load_hyperparams
    from agents.training import CONFIG_CLASSES, train
    from fricenv.utils import write_json

    if args.steps < 1:
        raise SystemExit("fricenv train: --steps must be >= 1")
    try:
        config = None
        if args.hyperparams:
            config = load_hyperparams(args.hyperparams, CONFIG_CLASSES).get(args.algo)
            if config is None:
                raise ValueError(f"{args.hyperparams} has no {args.algo!r} entry")
        result = train(args.out, env=args.env, estimator=args.estimator, algo=args.algo, steps=args.steps,
                       seed=args.seed, config=config, vec=args.vec, progress_bar=getattr(args, "show_progress", True) and not args.no_progress)
    except ValueError as exc:
        raise SystemExit(f"fricenv train: {exc}") from None
    print(f"trained {args.algo} on {args.env} (estimator {args.estimator}): {result.steps} steps in "
          f"{result.wall_time:.1f} s ({result.steps_per_second:.0f} steps/s); saved {result.model_path}")
    if args.json:
        write_json(args.json, result.meta)
        print(f"wrote {args.json}")
    return 0
