"""Evaluate excitation policies (multi-sine, PRBS, zero) in PayloadExcitation-v0: time to E < 1e-2, final E.

Each policy runs the same episodes (seeds --seed, --seed+1, ...) of ``fricenv/PayloadExcitation-v0``: 20 s, the
applied wrench set at 50 Hz, the plant and the RLS calibrator at 1 ms inside. Printed per policy: the median time
after which the calibration error E = ||I - S_hat S^-1||_2 stays below 1e-2 ("never" if it does not in most
episodes), the median E at the end, the mean effort (mean squared normalised action) and the number of episodes
that left the workspace.
"""

from __future__ import annotations

import argparse

from agents.excitation import POLICIES

CALIBRATION_CHOICES = ("paper", "random")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``fricenv excitation``."""
    parser.add_argument("--policies", nargs="+", default=list(POLICIES), choices=list(POLICIES),
                        help="policies to evaluate (default: all)")
    parser.add_argument("--episodes", type=int, default=3, help="episodes per policy (default %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the first episode")
    parser.add_argument("--calibration", choices=CALIBRATION_CHOICES, default="paper",
                        help="true S: the paper's, or random entries in [-3, 3] (default %(default)s)")
    parser.add_argument("--noise-scale", type=float, default=1.0,
                        help="multiplies the paper's stated sensor and vision noise (default %(default)s)")
    parser.add_argument("--json", metavar="PATH", help="write the figures as JSON")


def run(args) -> int:
    """Evaluate, print a table, optionally write JSON."""
    import gymnasium as gym

    import fricenv  # noqa: F401  (registers the envs)
    from agents.excitation import evaluate
    from fricenv.errors import InvalidInputError, user_input
    from fricenv.utils import write_json

    if args.episodes < 1:
        raise InvalidInputError(f"--episodes must be >= 1, got {args.episodes}")
    env_kwargs = {"calibration": args.calibration, "noise_scale": args.noise_scale}
    with user_input("--noise-scale"):
        gym.make("fricenv/PayloadExcitation-v0", **env_kwargs).close()
    rows = evaluate(args.policies, episodes=args.episodes, seed=args.seed, env_kwargs=env_kwargs, progress_bar=True)
    print(f"PayloadExcitation-v0, calibration={args.calibration}, noise x{args.noise_scale:g}, "
          f"{args.episodes} episode(s) per policy (medians; effort = mean a^2)")
    print(f"{'policy':<10} {'t_below_1e-2':>13} {'E_end':>10} {'effort':>8} {'return':>8} {'left ws':>8}")
    for r in rows:
        tb = "never" if r["t_below_1e-2"] is None else f"{r['t_below_1e-2']:.2f} s"
        print(f"{r['policy']:<10} {tb:>13} {r['E_end']:>10.3e} {r['effort']:>8.3f} {r['return']:>8.3f} "
              f"{r['left_workspace']:>8d}")
    if args.json:
        write_json(args.json, {"results": rows, "calibration": args.calibration, "noise_scale": args.noise_scale,
                               "episodes": args.episodes, "seed": args.seed})
        print(f"wrote {args.json}")
    return 0
