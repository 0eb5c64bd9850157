"""Train an ABS (Braking-v0) or excitation (PayloadExcitation-v0) policy with stable-baselines3 (PPO or SAC).

Braking: randomised roads per episode (a preset, or a friction change between two presets during the stop),
initial speed 15-32 m/s, the chosen estimator's outputs appended to the observation. Payload: random calibration
S per episode, with (``--estimator rls``) or without (``none``) the RLS estimate of S in the observation.
Writes ``model.zip``, ``vecnormalize.pkl``, ``config.yml``, ``env_kwargs.yml``, ``checkpoints/``, ``train.json``
(and ``tb/`` if TensorBoard is installed) into ``--out``: the policy loads with plain Stable-Baselines3 on
``gymnasium.make(env_id, **env_kwargs)`` (``config.yml`` names the env id; the action map is in that env).

``--steps`` is rounded up to whole rollouts (PPO: n_envs x n_steps env steps; SAC: n_envs), and a note on stderr
says so when it is. ``--effects-randomization grid`` trains a braking policy on plants with effects: every
episode draws each effect of the effect grid but the friction change (which the road mix already draws) over a
range from the nominal plant through both grid sizes (brake lag 0.001-0.08 s, delay 0-0.06 s, gain 0.80-1.25, rolling
radius 0.97-1.04 r, relaxation length 0.001-0.6 m, drag c0 0-150 N and c2 0-0.6 N s^2/m^2);
``--effects-randomization grid-one`` draws one of those effects or none per episode, each with equal probability.
``--init RUN`` starts from a finished run's policy and normalisation statistics (fine-tuning: a nominal-trained
policy trained on over the grid's distribution); the two runs need the same env, estimator, algorithm and network.
"""

from __future__ import annotations

import argparse

ENV_CHOICES = ("braking", "payload")
VEC_CHOICES = ("auto", "native", "dummy", "subproc")  # agents.training.VEC_KINDS (not imported: CLI start-up)
# fricenv.envs.estimator_observation.ESTIMATOR_NAMES (not imported: CLI start-up; a test holds them equal)
BRAKING_ESTIMATORS = ("none", "ekf", "mhe", "ekf-rls", "ekf-full", "mhe-full", "ekf-ax", "mhe-ax", "oracle")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``fricenv train``."""
    parser.add_argument("--env", choices=ENV_CHOICES, default="braking", help="task (default %(default)s)")
    parser.add_argument("--estimator", default="none",
                        help="observation estimator: braking " + "|".join(BRAKING_ESTIMATORS) + ", "
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
    parser.add_argument("--effects-randomization", choices=("none", "grid", "grid-one"), default="none",
                        help="braking: draw the plant's effects per episode over the effect grid's ranges: every "
                             "effect at once (grid), or one of them or none (grid-one, the grid's own "
                             "distribution) (default %(default)s)")
    parser.add_argument("--init", metavar="RUN", default=None,
                        help="start from the policy weights and normalisation statistics of a finished run "
                             "(fine-tuning; same env, estimator, algorithm and network)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--json", metavar="PATH", help="write the run summary (wall time, steps/s) as JSON")


def run(args) -> int:
    """Train and save; print wall time and steps per second."""
    import sys

    from agents.hyperparams import load_hyperparams
    from agents.run_files import rounded_steps
    from agents.training import CONFIG_CLASSES, check_train_args, train
    from fricenv.errors import InvalidInputError, one_line, user_input
    from fricenv.utils import write_json

    if args.steps < 1:
        raise InvalidInputError("--steps must be >= 1")
    env_kwargs = None
    if args.effects_randomization != "none":
        if args.env != "braking":
            raise InvalidInputError(f"--effects-randomization {args.effects_randomization} is for --env braking")
        from fricenv.effects.grid import grid_randomization
        from fricenv.envs.effect_spec import ONE_OF

        ranges = grid_randomization()
        env_kwargs = {"effects_randomization": {ONE_OF: ranges} if args.effects_randomization == "grid-one"
                      else ranges}
    with user_input("--hyperparams"):
        config = None
        if args.hyperparams:
            config = load_hyperparams(args.hyperparams, CONFIG_CLASSES).get(args.algo)
            if config is None:
                raise ValueError(f"{args.hyperparams} has no {args.algo!r} entry")
    try:
        cfg = check_train_args(args.env, args.estimator, args.algo, args.steps, args.vec, config)
    except (ValueError, TypeError) as exc:
        raise InvalidInputError(one_line(exc)) from None
    if args.init is not None:
        from agents.warm_start import check_warm_start

        try:
            check_warm_start(args.init, args.env, args.estimator, args.algo, 0, list(cfg.net_arch))
        except ValueError as exc:
            raise InvalidInputError(f"--init: {one_line(exc)}") from None
    if rounded_steps(args.algo, cfg, args.steps) != args.steps:
        unit = "whole rounds of n_envs x train_freq" if args.algo == "sac" else "whole rollouts of n_envs x n_steps"
        print(f"{args._prog}: note: --steps {args.steps} rounds up to {rounded_steps(args.algo, cfg, args.steps)} "
              f"env steps ({args.algo} trains {unit})", file=sys.stderr)
    print(f"{args._prog}: training {args.algo} on {args.env} (estimator {args.estimator}) into {args.out}",
          file=sys.stderr, flush=True)
    result = train(args.out, env=args.env, estimator=args.estimator, algo=args.algo, steps=args.steps,
                   seed=args.seed, config=config, vec=args.vec, env_kwargs=env_kwargs,
                   progress_bar=getattr(args, "show_progress", True) and not args.no_progress, init=args.init)
    print(f"trained {args.algo} on {args.env} (estimator {args.estimator}): {result.steps} steps in "
          f"{result.wall_time:.1f} s ({result.steps_per_second:.0f} steps/s); saved {result.model_path}")
    if args.json:
        write_json(args.json, result.meta)
        print(f"wrote {args.json}")
    return 0
