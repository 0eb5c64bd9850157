"""Where a policy brakes under an effect: its true slip, its slip estimate and its torque command.

The effect grid's policy table (``fricenv evaluate --effect-grid``) gives stopping ratios; this reads why one rose.
For each policy (a ``fricenv evaluate --policy`` spec) on the nominal plant and on each chosen cell (``effect:size``),
on the grid's scenarios (dry and wet at 20 m/s) and the evaluation reset seeds: the stopping ratio, and, while the
car is faster than the env's stop speed, the mean true slip, the mean slip estimate of the policy's observation (nan
without one), the road's reference slip (the peak of its curve) and the mean commanded torque.

Command::

    python -m validation.policy_slip --policy RUN [--policy ...] --cells brake_gain:low [...] [--seeds 0 1 2]
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

from agents.controllers import rollout, slip_reference
from agents.effect_scenarios import GRID_SCENARIOS
from agents.evaluation import parse_policy, policy_controller
from fricenv.effects.grid import grid_effect
from fricenv.envs.factory import make_braking
from validation.slip_gains import parse_cell

__all__ = ["main", "measure"]

NOMINAL = "nominal"


def measure(policy: str, cell: str, road: str, v0: float, seed: int) -> dict[str, float]:
    """One episode of ``policy`` on ``road`` at ``v0`` with ``cell`` (``"nominal"`` or ``effect:size``) on.

    :return: ``ratio``, ``slip``, ``slip_hat``, ``slip_ref``, ``torque`` (module docstring).
    """
    spec = parse_policy(policy)
    effects = None if cell == NOMINAL else [grid_effect(*parse_cell(cell), road, v0)]
    env = _SlipEstimates(make_braking(spec.estimator, road=road, v0=v0, change_distance=None,
                                      observation=spec.observation, effects=effects))
    try:
        run = rollout(env, policy_controller(spec, env), seed=seed)
        v_stop = env.unwrapped.config.v_stop
        ref = slip_reference(env.unwrapped.road)[0]
    finally:
        env.close()
    moving = run.v[1:] > v_stop  # the steps' samples, as the estimates
    info = run.info
    distance = info["stopping_distance"] if info["stopped"] else info["distance"]
    return {"ratio": float(distance / info["limit_distance"]), "slip": float(np.mean(run.slip[1:][moving])),
            "slip_hat": float(np.mean(np.asarray(env.slip_hat)[moving])), "slip_ref": float(ref),
            "torque": float(np.mean(run.torque[1:][moving]))}


class _SlipEstimates(gym.Wrapper):
    """Records the slip estimate of each step's info (nan without an estimator)."""

    def reset(self, **kwargs):
        self.slip_hat: list[float] = []
        return super().reset(**kwargs)

    def step(self, action):
        out = super().step(action)
        self.slip_hat.append(float(out[-1].get("estimate", {}).get("slip_hat", np.nan)))
        return out


def main(argv=None) -> int:
    """``python -m validation.policy_slip`` (module docstring)."""
    ap = argparse.ArgumentParser(prog="python -m validation.policy_slip", description=__doc__.splitlines()[0])
    ap.add_argument("--policy", action="append", required=True, help="a fricenv evaluate --policy spec")
    ap.add_argument("--cells", nargs="+", type=str, default=[], metavar="EFFECT:SIZE")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    args = ap.parse_args(argv)
    for cell in args.cells:
        try:
            parse_cell(cell)
        except argparse.ArgumentTypeError as exc:
            ap.error(str(exc))
    for policy in args.policy:
        try:
            parse_policy(policy)
        except ValueError as exc:
            ap.error(f"--policy {policy}: {exc}")
    print(f"{'policy':<24} {'cell':<18} {'road':<5} {'ratio':>6} {'slip':>6} {'slip_hat':>8} {'ref':>6} {'torque':>7}")
    for policy in args.policy:
        for cell in [NOMINAL, *args.cells]:
            for sc in GRID_SCENARIOS:
                rows = [measure(policy, cell, sc.road, sc.v0, s) for s in args.seeds]
                m = {k: float(np.mean([r[k] for r in rows])) for k in rows[0]}
                print(f"{policy[-24:]:<24} {cell:<18} {sc.road:<5} {m['ratio']:>6.3f} {m['slip']:>6.3f} "
                      f"{m['slip_hat']:>8.3f} {m['slip_ref']:>6.3f} {m['torque']:>7.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
