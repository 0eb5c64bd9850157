"""What a controller can reach under an effect of the grid: the slip PI on the true slip, its gains chosen for that
plant.

The effect grid's policy table (``fricenv evaluate --effect-grid``) runs every controller with its nominal tuning.
Where every policy stays above a target, this asks whether the target is within reach of a controller at all: the
slip controller that reads the true slip (:class:`agents.controllers.OracleSlipController`) with each pair of PI
gains of a grid, on dry and wet at 20 m/s with the effect at the chosen size. The gains are chosen on the tuning
reset seeds (``--tune-seeds``, default 100-102: the lowest mean ratio of the two roads among the pairs without a
lock) and reported on the evaluation seeds of the policy table (``--seeds``, default 0-2), which never chose them.

Command::

    python -m validation.slip_gains --effect brake_delay [--size high] [--kp 5 10 20 40] [--ki 25 50 100 200 400]
        [--tune-seeds 100 101 102] [--seeds 0 1 2]
"""

from __future__ import annotations

import argparse
import itertools

import gymnasium as gym
import numpy as np

import fricenv  # noqa: F401  (registers the envs)
from agents.controllers import OracleSlipController, SlipControllerParams, rollout
from agents.effect_scenarios import GRID_SCENARIOS
from fricenv.effects.grid import EFFECT_GRID, GRID_SIZES, grid_effect

__all__ = ["main", "score"]


def score(effect: str, size: str, gains: SlipControllerParams, seeds: list[int]) -> tuple[float, int]:
    """Mean stopping ratio over the grid's scenarios (dry and wet at 20 m/s) and ``seeds``, and the lock events.

    :param effect: a grid effect; :param size: ``low`` or ``high``; :param gains: the slip PI's gains.
    :param seeds: reset seeds.
    :return: (mean ratio, episodes that locked the wheel); the ratio is inf if an episode did not stop.
    """
    ratios, locks = [], 0
    for sc in GRID_SCENARIOS:
        effects = [grid_effect(effect, size, sc.road, sc.v0)]
        env = gym.make("fricenv/Braking-v0", road=sc.road, v0=sc.v0, observation="oracle", effects=effects)
        for seed in seeds:
            info = rollout(env, OracleSlipController(env.unwrapped, gains=gains), seed=seed).info
            ratios.append(info["ratio"] if info["stopped"] else np.inf)
            locks += bool(info["lock_seen"])
    return float(np.mean(ratios)), locks


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(prog="python -m validation.slip_gains", description=__doc__.split("\n\n")[0])
    ap.add_argument("--effect", required=True, choices=tuple(EFFECT_GRID), help="grid effect")
    ap.add_argument("--size", default="high", choices=GRID_SIZES, help="its size (default high)")
    ap.add_argument("--kp", type=float, nargs="+", default=[5.0, 10.0, 20.0, 40.0], help="proportional gains [1/s]")
    ap.add_argument("--ki", type=float, nargs="+", default=[25.0, 50.0, 100.0, 200.0, 400.0],
                    help="integral gains [1/s^2]")
    ap.add_argument("--tune-seeds", type=int, nargs="+", default=[100, 101, 102], help="seeds that choose the gains")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="seeds the chosen gains are reported on")
    args = ap.parse_args(argv)
    nominal = SlipControllerParams()
    tuned = []
    for kp, ki in itertools.product(args.kp, args.ki):
        ratio, locks = score(args.effect, args.size, SlipControllerParams(kp=kp, ki=ki), args.tune_seeds)
        tuned.append((locks > 0, ratio, kp, ki))
        print(f"tuning seeds: kp {kp:g} ki {ki:g}: ratio {ratio:.3f}, lock episodes {locks}", flush=True)
    _, _, kp, ki = min(tuned)
    chosen = SlipControllerParams(kp=kp, ki=ki)
    out = {"effect": args.effect, "size": args.size, "seeds": args.seeds, "tune_seeds": args.tune_seeds}
    for name, gains in (("nominal", nominal), ("chosen", chosen)):
        ratio, locks = score(args.effect, args.size, gains, args.seeds)
        out[name] = {"kp": gains.kp, "ki": gains.ki, "ratio": ratio, "lock_episodes": locks}
        print(f"{name} gains (kp {gains.kp:g}, ki {gains.ki:g}) on seeds {args.seeds}: ratio {ratio:.3f}, "
              f"lock episodes {locks}")
    return out


if __name__ == "__main__":
    main()
