"""Training signal of the ABS task: the wheel-lock penalty from the first step of the lock condition.

``Braking-v0`` subtracts ``lock_penalty`` (0.01) per step only once the lock condition ``omega r < 0.05 v`` has
held for more than ``lock_time`` (0.1 s, 10 steps): that is the lock *event* the evaluation counts. Trained
policies held ice at slips 0.95-1.0 (flat curve: locked friction is 96 % of the peak) and near the end of the stop
the condition came and went for a second before it counted, unpenalised until then (measured on a
PPO + EKF policy on ice at 20 m/s: 55 locked steps, all below 3 m/s). :class:`LockOnsetPenaltyVecEnv` adds
``onset_penalty`` per step while the condition holds but has not yet counted as a lock, so with
``onset_penalty = lock_penalty`` every step of the condition costs the same and a lock never pays. The env's own
reward, its lock counter and the evaluation metric are unchanged: only the reward the learner sees differs.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecEnvWrapper

__all__ = ["LockOnsetPenaltyVecEnv", "lock_counter"]


def lock_counter(venv: VecEnv) -> tuple[Callable[[], np.ndarray], int]:
    """A function returning the lock-condition step counts of every sub-env of an SB3 braking vector env (the
    native one or a ``DummyVecEnv`` of ``Braking-v0``, possibly wrapped), and the steps after which they count as
    a lock.

    :raises TypeError: a vector env whose sub-envs live in other processes.
    """
    from fricenv.envs.sb3_vec import BrakingSB3VecEnv

    base = venv
    while not isinstance(base, (BrakingSB3VecEnv, DummyVecEnv)):
        if not isinstance(base, VecEnvWrapper):
            raise TypeError(f"the lock-onset penalty reads the sims of a native or dummy braking vector env, "
                             f"got {type(base).__name__}; train with vec 'native' or 'dummy'")
        base = base.venv
    if isinstance(base, BrakingSB3VecEnv):
        sim = base.venv.unwrapped.sim
        return (lambda: sim.lock_count), sim.config.lock_steps
    sims = [e.unwrapped.sim for e in base.envs]
    return (lambda: np.array([s.lock_count[0] for s in sims])), sims[0].config.lock_steps


class LockOnsetPenaltyVecEnv(VecEnvWrapper):
    """Subtract ``onset_penalty`` from the reward of every sub-env whose wheel is in the lock condition but not yet
    counted as locked (module docstring).

    :param venv: a native or dummy braking vector env (possibly wrapped).
    :param onset_penalty: per step [-] (>= 0).
    """

    def __init__(self, venv: VecEnv, onset_penalty: float):
        if not np.isfinite(onset_penalty) or onset_penalty < 0:
            raise ValueError(f"onset_penalty must be a finite number >= 0, got {onset_penalty!r}")
        self.onset_penalty = float(onset_penalty)
        self._counts, self._lock_steps = lock_counter(venv)
        super().__init__(venv)

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        count = np.asarray(self._counts())  # sub-envs reset at their episode end read 0: no onset there
        onset = (count > 0) & (count <= self._lock_steps)
        return obs, rewards - self.onset_penalty * onset, dones, infos

    def reset(self):
        return self.venv.reset()
