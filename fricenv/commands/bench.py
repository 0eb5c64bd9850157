"""Benchmark fricenv's speed against a reference, in one process: medians over repeats, ratios, --json.

Targets (run one, or all when none is given):
  env    single fricenv/Braking-v0 env steps per second (default observation), and Gymnasium's Pendulum-v1 in the
         same run as the reference, with their ratio.
More targets plug in with one line in TARGETS.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

DEFAULT_REPEATS = 5
DEFAULT_STEPS = 5000
REFERENCE_ENV = "Pendulum-v1"
BRAKING_ENV = "fricenv/Braking-v0"


def _env_steps_per_s(env_id: str, steps: int, seed: int, **kwargs) -> float:
    """Steps per second of ``gymnasium.make(env_id)`` under a fixed action, resetting at episode end."""
    import gymnasium as gym
    import numpy as np

    env = gym.make(env_id, **kwargs)
    action = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
    env.reset(seed=seed)
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    elapsed = time.perf_counter() - start
    env.close()
    return steps / elapsed


def bench_env(args) -> dict:
    """Single Braking-v0 and Pendulum-v1 steps per second, interleaved repeats, medians and their ratio."""
    import fricenv  # noqa: F401  (registers the envs)

    single, pendulum = [], []
    for k in range(args.repeats):
        single.append(_env_steps_per_s(BRAKING_ENV, args.steps, seed=k))
        pendulum.append(_env_steps_per_s(REFERENCE_ENV, args.steps, seed=k))
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
TARGETS: dict[str, Callable[[argparse.Namespace], dict]] = {
    "env": bench_env,
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("target", nargs="?", default="all", choices=[*TARGETS, "all"],
                        help="what to benchmark (default: all)")
    parser.add_argument("--repeats", type=int, default=DEFAULT_REPEATS,
                        help=f"repeats per measurement; the median is reported (default: {DEFAULT_REPEATS})")
    parser.add_argument("--steps", type=int, default=DEFAULT_STEPS,
                        help=f"env steps per repeat (default: {DEFAULT_STEPS})")
    parser.add_argument("--json", metavar="PATH", default=None, help="also write the figures as JSON")


def run(args) -> int:
    from fricenv.utils import write_json

    if args.repeats < 1 or args.steps < 1:
        raise SystemExit("fricenv bench: --repeats and --steps must be >= 1")
    targets = list(TARGETS) if args.target == "all" else [args.target]
    figures: dict = {}
    for name in targets:
        figures.update(TARGETS[name](args))
    if args.json:
        write_json(args.json, figures)
        print(f"json: {args.json}")
    return 0
