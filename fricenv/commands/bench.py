"""Benchmark fricenv's speed against a reference, in one process: medians over repeats, ratios, --json.

Targets (run one, or all when none is given):
  env         single fricenv/Braking-v0 env steps per second (default observation), and Gymnasium's Pendulum-v1
              in the same run as the reference, with their ratio.
  pendulum    Pendulum-v1 alone (the reference).
  vector      the native vector env (make_vec, vector_entry_point) at 1, 64 and 1024 sub-envs, env-steps/s.
  estimators  mean update time per estimator (estimators.bench), microseconds.
  ppo         a fixed SB3 PPO training slice on the vector env: steps/s and the share of time spent in the env.
  gap         one 5 s log diagnosed by `fricenv gap diagnose` on 2 cores, with all channels and with t, T_b, omega
              only (wall seconds), with the compiled window simulator and projected Jacobian and with the numpy
              simulator and forward differences (the reference path) in the same run, and their ratio; the
              speed reconstruction of the latter against its sample-by-sample reference (ms per call). Not part of
              "all": about a minute per repeat.
  training    PPO training speed as `fricenv train` runs it (committed hyperparameters): env-steps/s without
              estimates, with the EKF/RLS and with the MHE in the same run, and the ratios to the first. Not part of
              "all": about a minute per repeat.
  all         all of the above except gap and training (default).
Every figure is a median over --repeats; ratios divide by Pendulum-v1 measured in the same run (a target that
needs the reference measures it too). --json PATH writes single_steps_per_s, pendulum_steps_per_s,
vector_steps_per_s {"1", "64", "1024"}, estimator_update_us {name: mean}, ppo_steps_per_s, ratio_to_pendulum
(and gap_diagnose_seconds {all_channels, required_only} of the compiled path, gap_diagnose_seconds_numpy of the
numpy path, gap_speedup = numpy / compiled, gap_diagnose_cpu_seconds and gap_diagnose_cpu_seconds_numpy: the CPU
seconds of each diagnosis with its worker processes, the figure to compare on a loaded machine, and
speed_reconstruction_ms for the gap target).
More targets plug in with one line in TARGETS (or fricenv.bench_targets.TARGETS).
"""

from __future__ import annotations

import argparse
import statistics
from collections.abc import Callable

from fricenv import bench_targets
from fricenv.bench_targets import BRAKING_ENV, REFERENCE_ENV
from fricenv.bench_targets import env_steps_per_s as _env_steps_per_s
from fricenv.errors import InvalidInputError

DEFAULT_REPEATS = 5
DEFAULT_STEPS = 5000


def bench_env(args) -> dict:
    """Single Braking-v0 and Pendulum-v1 steps per second, interleaved repeats, medians and their ratio."""
    import fricenv  # noqa: F401  (registers the envs)

    single, pendulum = [], []
    for k in range(args.repeats):
        single.append(_env_steps_per_s(BRAKING_ENV, args.steps, seed=args.seed + k))
        pendulum.append(_env_steps_per_s(REFERENCE_ENV, args.steps, seed=args.seed + k))
    out = {
        "single_steps_per_s": statistics.median(single),
        "pendulum_steps_per_s": statistics.median(pendulum),
        "single_steps_per_s_all": single,
        "pendulum_steps_per_s_all": pendulum,
    }
    out["single_vs_pendulum"] = out["single_steps_per_s"] / out["pendulum_steps_per_s"]
    print(f"env: {BRAKING_ENV} {out['single_steps_per_s']:,.0f} steps/s, {REFERENCE_ENV} "
          f"{out['pendulum_steps_per_s']:,.0f} steps/s (median of {args.repeats} x {args.steps} steps), "
          f"ratio {out['single_vs_pendulum']:.3f}")
    return out


# target name -> function(args) -> dict of figures (merged into the --json output). Add a target with one line.
TARGETS: dict[str, Callable[[argparse.Namespace], dict]] = {"env": bench_env, **bench_targets.TARGETS}
# Targets whose figures are divided by the reference: they measure Pendulum-v1 too when run alone.
NEEDS_REFERENCE = ("vector", "ppo")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("target", nargs="?", default="all", choices=[*TARGETS, "all"],
                        help="what to benchmark (default: all)")
    parser.add_argument("--repeats", type=int, default=DEFAULT_REPEATS,
                        help=f"repeats per measurement; the median is reported (default: {DEFAULT_REPEATS})")
    parser.add_argument("--steps", type=int, default=DEFAULT_STEPS,
                        help=f"env steps per repeat (default: {DEFAULT_STEPS})")
    parser.add_argument("--seed", type=int, default=0, help="base seed of the env resets (default: 0)")
    parser.add_argument("--json", metavar="PATH", default=None, help="also write the figures as JSON")


def run(args) -> int:
    from fricenv.bench_targets import ratios
    from fricenv.utils import progress, write_json

    if args.repeats < 1 or args.steps < 1:
        raise InvalidInputError(f"--repeats and --steps must be >= 1, got {args.repeats} and {args.steps}")
    if args.target == "all":
        # "env" measures the reference
        targets = [name for name in TARGETS if name != "pendulum" and name not in bench_targets.SLOW_TARGETS]
    elif args.target in NEEDS_REFERENCE:
        targets = ["pendulum", args.target]
    else:
        targets = [args.target]
    figures: dict = {}
    for name in progress(targets, desc="bench targets"):
        figures.update(TARGETS[name](args))
    figures.update(ratios(figures))
    for key, value in figures.get("ratio_to_pendulum", {}).items():
        shown = ", ".join(f"{n}: {r:.2f}" for n, r in value.items()) if isinstance(value, dict) else f"{value:.3f}"
        print(f"ratio to {REFERENCE_ENV}: {key} {shown}")
    if args.json:
        write_json(args.json, figures)
        print(f"json: {args.json}")
    return 0
