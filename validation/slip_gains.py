"""What a fixed-gain controller can reach on cells of the effect grid: the slip PI on the true slip (or on an
estimator's), its gains chosen for those cells.

The effect grid's policy table (``fricenv evaluate --effect-grid``) runs every controller with its nominal tuning.
Where every policy stays above a target, this asks whether the target is within reach of a controller at all: the
slip controller that reads the true slip (:class:`agents.controllers.OracleSlipController`) with each pair of PI
gains of a grid, on dry and wet at 20 m/s on each chosen cell (``effect:size``). The gains are chosen on the tuning
reset seeds (``--tune-seeds``, default 100-102): among the pairs that lock the wheel in no episode of any cell, the
one whose worst cell (mean ratio of the two roads) is lowest. They are reported on the evaluation seeds of the
policy table (``--seeds``, default 0-2), which never chose them. With ``--estimator NAME`` the controller is the
classical pipeline on that estimator's outputs instead (:class:`agents.pipeline.EstimatorSlipPipeline`: the slip
from ``v_hat``, the reference from the estimated curve's peak), the row "slip PI on EKF/RLS" of the policy table
with other gains; ``--feedforward road`` gives that pipeline the true road's friction at its reference slip in place
of the measured deceleration (a bound that reads the truth, to tell what the estimates cost from what the
feedforward does behind a delay).

Command::

    python -m validation.slip_gains --cells brake_delay:high [brake_gain:high ...] [--kp 5 10 20 40]
        [--ki 25 50 100 200 400] [--tune-seeds 100 101 102] [--seeds 0 1 2] [--estimator ekf-rls
        [--feedforward road]]
"""

from __future__ import annotations

import argparse
import itertools

import gymnasium as gym
import numpy as np

import fricenv  # noqa: F401  (registers the envs)
from agents.controllers import OracleSlipController, SlipControllerParams, rollout
from agents.effect_scenarios import GRID_SCENARIOS
from agents.evaluation import CHANGE_DISTANCE
from agents.pipeline import EstimatorSlipPipeline
from estimators.registry import OBSERVATION_ESTIMATORS
from fricenv.effects.grid import EFFECT_GRID, GRID_SIZES, grid_effect
from fricenv.envs.factory import make_braking
from fricenv.plants.tire import magic_formula

__all__ = ["RoadFeedforwardPipeline", "main", "parse_cell", "score"]


class RoadFeedforwardPipeline(EstimatorSlipPipeline):
    """The classical pipeline whose feedforward holds the reference slip at the true road's friction there, in place
    of the friction the accelerometer measures (it reads the truth: a bound, not a controller)."""

    def __init__(self, env, gains: SlipControllerParams | None = None):
        super().__init__(env, gains)
        self._plant = env.unwrapped

    def _feedforward_mu(self, values: dict, lam_ref: np.ndarray) -> np.ndarray:
        road = self._plant.road  # the road under the car now
        return magic_formula(np.asarray(lam_ref, dtype=float), road.B, road.C, road.E, road.theta)


def parse_cell(text: str) -> tuple[str, str]:
    """``effect:size`` -> (effect, size), checked against the grid."""
    effect, _, size = text.partition(":")
    if effect not in EFFECT_GRID or size not in GRID_SIZES:
        raise argparse.ArgumentTypeError(f"cell {text!r}: expected EFFECT:SIZE with EFFECT one of "
                                         f"{', '.join(EFFECT_GRID)} and SIZE one of {', '.join(GRID_SIZES)}")
    return effect, size


def score(effect: str, size: str, gains: SlipControllerParams, seeds: list[int],
          estimator: str | None = None, feedforward: str = "measured") -> tuple[float, int]:
    """Mean stopping ratio over the grid's scenarios (dry and wet at 20 m/s) and ``seeds``, and the lock events.

    :param effect: a grid effect; :param size: ``low`` or ``high``; :param gains: the slip PI's gains.
    :param seeds: reset seeds.
    :param estimator: None: the PI on the true slip; else the pipeline on this estimator's outputs.
    :param feedforward: the pipeline's feedforward friction: ``measured`` (its own, from ``a_x``) or ``road`` (the
        true road's at the reference slip, :class:`RoadFeedforwardPipeline`).
    :return: (mean ratio, episodes that locked the wheel); the ratio is inf if an episode did not stop.
    """
    ratios, locks = [], 0
    for sc in GRID_SCENARIOS:
        effects = [grid_effect(effect, size, sc.road, sc.v0)]
        if estimator is None:
            env = gym.make("fricenv/Braking-v0", road=sc.road, v0=sc.v0, observation="oracle", effects=effects)
        else:
            env = make_braking(estimator, road=sc.road, v0=sc.v0, change_distance=CHANGE_DISTANCE, effects=effects)
        for seed in seeds:
            if estimator is None:
                ctl = OracleSlipController(env.unwrapped, gains=gains)
            elif feedforward == "road":
                ctl = RoadFeedforwardPipeline(env, gains=gains)
            else:
                ctl = EstimatorSlipPipeline(env, gains=gains)
            info = rollout(env, ctl, seed=seed).info
            ratios.append(info["ratio"] if info["stopped"] else np.inf)
            locks += bool(info["lock_seen"])
        env.close()
    return float(np.mean(ratios)), locks


def _line(cells, scores) -> str:
    return ", ".join(f"{e}:{s} {r:.3f} ({n} locked)" for (e, s), (r, n) in zip(cells, scores))


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(prog="python -m validation.slip_gains", description=__doc__.split("\n\n")[0])
    ap.add_argument("--cells", type=parse_cell, nargs="+", required=True, help="grid cells EFFECT:SIZE")
    ap.add_argument("--kp", type=float, nargs="+", default=[5.0, 10.0, 20.0, 40.0], help="proportional gains [1/s]")
    ap.add_argument("--ki", type=float, nargs="+", default=[25.0, 50.0, 100.0, 200.0, 400.0],
                    help="integral gains [1/s^2]")
    ap.add_argument("--tune-seeds", type=int, nargs="+", default=[100, 101, 102], help="seeds that choose the gains")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="seeds the chosen gains are reported on")
    ap.add_argument("--estimator", choices=OBSERVATION_ESTIMATORS, default=None,
                    help="the pipeline on this estimator's outputs (default: the PI on the true slip)")
    ap.add_argument("--feedforward", choices=("measured", "road"), default="measured",
                    help="with --estimator: the feedforward friction, measured (a_x) or the true road's")
    args = ap.parse_args(argv)
    if args.feedforward == "road" and args.estimator is None:
        ap.error("--feedforward road needs --estimator (the true-slip controller's feedforward is the road's already)")
    tuned = []
    for kp, ki in itertools.product(args.kp, args.ki):
        scores = [score(e, s, SlipControllerParams(kp=kp, ki=ki), args.tune_seeds, args.estimator, args.feedforward)
                  for e, s in args.cells]
        tuned.append((any(n for _, n in scores), max(r for r, _ in scores), kp, ki))
        print(f"tuning seeds, kp {kp:g} ki {ki:g}: {_line(args.cells, scores)}", flush=True)
    locked, _, kp, ki = min(tuned)
    if locked:
        print("every pair of gains locks the wheel in some cell; the lowest worst cell among them:")
    out = {"cells": [f"{e}:{s}" for e, s in args.cells], "seeds": args.seeds, "tune_seeds": args.tune_seeds,
           "every_pair_locks": locked, "estimator": args.estimator,
           "feedforward": args.feedforward}
    for name, gains in (("nominal", SlipControllerParams()), ("chosen", SlipControllerParams(kp=kp, ki=ki))):
        scores = [score(e, s, gains, args.seeds, args.estimator, args.feedforward) for e, s in args.cells]
        out[name] = {"kp": gains.kp, "ki": gains.ki, "cells": [{"ratio": r, "lock_episodes": n} for r, n in scores]}
        print(f"{name} gains (kp {gains.kp:g}, ki {gains.ki:g}) on seeds {args.seeds}: {_line(args.cells, scores)}")
    return out


if __name__ == "__main__":
    main()
