"""Excitation policies for ``fricenv/PayloadExcitation-v0`` and their evaluation.

Every policy has ``reset(seed=None)`` and ``act(obs) -> action`` (normalised wrench in [-1, 1]^3). The excitation
policies add a workspace-keeping PD term on the vision pose (the multi-sine of eq. (13) alone drifts: its forces
have a non-zero-mean velocity response, about 0.4 m/s, so the payload would leave the 0.5 m workspace within
about 2 s); the PD forces are themselves measured by the sensor and add to the excitation.

- ``multisine``: the paper's wrench of eq. (13) (in N m and N, scaled by the actuator limits) plus the PD term;
- ``prbs``: a pseudo-random binary wrench per axis (random hold times of 0.1-0.5 s) at half the limits, plus PD;
- ``zero``: no wrench at all (no excitation; the calibrator cannot learn anything and says so).

:func:`evaluate` runs policies through the env and reports the time until E stays below 1e-2, E at the end and
the effort (mean squared normalised action).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fricenv.plants.payload import PAPER_PARAMS, paper_wrench

__all__ = [
    "E_THRESHOLD",
    "POLICIES",
    "EpisodeResult",
    "ExcitationPolicy",
    "MultiSinePolicy",
    "PRBSPolicy",
    "ZeroPolicy",
    "evaluate",
    "make_policy",
    "run_episode",
]

E_THRESHOLD = 1e-2  # calibration error counted as "calibrated"
PD_OMEGA = 2.0  # natural frequency of the workspace-keeping PD [rad/s]
PD_ZETA = 1.0  # its damping ratio [-]
PRBS_AMPLITUDE = 0.5  # PRBS level as a fraction of the actuator limits [-]
PRBS_HOLD_STEPS = (5, 25)  # PRBS hold time range in control steps (0.1-0.5 s at 50 Hz)


class ExcitationPolicy:
    """Common interface: ``reset(seed)`` at the start of an episode, then ``act(obs)`` every control step.

    :param env: the (unwrapped) PayloadExcitation env, used for its observation layout, step and limits.
    """

    name = "base"

    def __init__(self, env):
        self.env = env
        self.dt = float(env.dt)
        self.limits = np.asarray(env.limits, dtype=float)
        names = [f.name for f in env.observation_fields]
        self._idx = {k: names.index(k) for k in ("theta", "X", "Y", "X_rate", "Y_rate")}
        self._scale = {k: env.observation_fields[i].scale for k, i in self._idx.items()}
        m = PAPER_PARAMS.m if not hasattr(env, "params") else env.params.m
        self.kp = m * PD_OMEGA**2  # [N/m]
        self.kd = 2.0 * PD_ZETA * m * PD_OMEGA  # [N s/m]
        self.k = 0

    def reset(self, seed: int | None = None) -> None:
        """Start a new episode."""
        self.k = 0

    def act(self, obs) -> np.ndarray:
        """The normalised wrench for this control step."""
        w = self.wrench(self.k * self.dt, obs)
        self.k += 1
        return np.clip(w / self.limits, -1.0, 1.0).astype(np.float32)

    def wrench(self, t: float, obs) -> np.ndarray:
        """Body-frame wrench (M [N m], f_x [N], f_y [N]) at time ``t`` [s]."""
        raise NotImplementedError

    def _keep_in_workspace(self, obs) -> np.ndarray:
        """PD force towards the origin from the vision pose, rotated into the body frame: (0, f_x, f_y)."""
        obs = np.asarray(obs, dtype=float)
        v = {k: obs[i] * self._scale[k] for k, i in self._idx.items()}
        f_world = -self.kp * np.array([v["X"], v["Y"]]) - self.kd * np.array([v["X_rate"], v["Y_rate"]])
        c, s = np.cos(v["theta"]), np.sin(v["theta"])
        return np.array([0.0, c * f_world[0] + s * f_world[1], -s * f_world[0] + c * f_world[1]])


class MultiSinePolicy(ExcitationPolicy):
    """The paper's multi-sine wrench, eq. (13), plus the workspace-keeping PD."""

    name = "multisine"

    def wrench(self, t: float, obs) -> np.ndarray:
        return paper_wrench(t) + self._keep_in_workspace(obs)


class PRBSPolicy(ExcitationPolicy):
    """Pseudo-random binary wrench per axis (random hold times), plus the workspace-keeping PD.

    :param env: the env.
    :param amplitude: level as a fraction of the actuator limits.
    :param seed: seed of the switching sequence (``reset(seed)`` re-seeds).
    """

    name = "prbs"

    def __init__(self, env, amplitude: float = PRBS_AMPLITUDE, seed: int | None = None):
        super().__init__(env)
        if not 0 < amplitude <= 1:
            raise ValueError(f"amplitude must be in (0, 1], got {amplitude!r}")
        self.amplitude = float(amplitude)
        self._seed = seed
        self.reset(seed)

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.rng = np.random.default_rng(self._seed if seed is None else seed)
        self.level = self.rng.choice([-1.0, 1.0], size=3)
        self.next_switch = self.rng.integers(*PRBS_HOLD_STEPS, size=3, endpoint=True)

    def wrench(self, t: float, obs) -> np.ndarray:
        switch = self.k >= self.next_switch
        if switch.any():
            self.level[switch] *= -1.0
            self.next_switch[switch] = self.k + self.rng.integers(*PRBS_HOLD_STEPS, size=int(switch.sum()),
                                                                  endpoint=True)
        return self.amplitude * self.level * self.limits + self._keep_in_workspace(obs)


class ZeroPolicy(ExcitationPolicy):
    """No wrench: the payload drifts with its initial (zero) velocity; nothing to learn from."""

    name = "zero"

    def wrench(self, t: float, obs) -> np.ndarray:
        return np.zeros(3)


POLICIES = {cls.name: cls for cls in (MultiSinePolicy, PRBSPolicy, ZeroPolicy)}


def make_policy(name: str, env, seed: int | None = None) -> ExcitationPolicy:
    """A policy by name (``multisine``, ``prbs``, ``zero``) for the given (unwrapped) env."""
    try:
        cls = POLICIES[name]
    except KeyError:
        raise ValueError(f"unknown policy {name!r}; valid: {', '.join(POLICIES)}") from None
    return cls(env, seed=seed) if cls is PRBSPolicy else cls(env)


@dataclass(frozen=True)
class EpisodeResult:
    """One evaluated episode."""

    policy: str
    t: np.ndarray  # time after each step [s]
    E: np.ndarray  # calibration error after each step [-]
    t_below: float | None  # time after which E stays below E_THRESHOLD [s]; None if it never does
    E_end: float  # E at the end of the episode [-]
    effort: float  # mean squared normalised action [-]
    ret: float  # episode return
    left_workspace: bool  # terminated by leaving the workspace


def run_episode(env, policy: ExcitationPolicy, seed: int | None = None) -> EpisodeResult:
    """Run one episode of ``policy`` in ``env`` (a Gymnasium env, wrapped or not)."""
    obs, info = env.reset(seed=seed)
    policy.reset(seed)
    ts, Es, efforts, ret = [], [], [], 0.0
    while True:
        action = policy.act(obs)
        obs, reward, terminated, truncated, info = env.step(action)
        ts.append(info["time"])
        Es.append(info["E"])
        efforts.append(info["effort"])
        ret += reward
        if terminated or truncated:
            break
    t, E = np.array(ts), np.array(Es)
    above = np.flatnonzero(E >= E_THRESHOLD)
    if E[-1] >= E_THRESHOLD:
        t_below = None
    else:
        t_below = float(t[above[-1] + 1]) if above.size else float(t[0])
    return EpisodeResult(policy.name, t, E, t_below, float(E[-1]), float(np.mean(efforts)), float(ret),
                         bool(info["out_of_workspace"]))


def evaluate(policies=tuple(POLICIES), episodes: int = 3, seed: int = 0, env_kwargs: dict | None = None,
             progress_bar: bool = False) -> list[dict]:
    """Evaluate excitation policies in ``fricenv/PayloadExcitation-v0``.

    :param policies: policy names.
    :param episodes: episodes per policy (seeds ``seed, seed+1, ...``, the same for every policy).
    :param seed: first episode seed.
    :param env_kwargs: passed to the env.
    :param progress_bar: show a progress bar.
    :return: one dict per policy: ``policy``, ``t_below_1e-2`` (median over episodes; None if most never get
        there), ``E_end`` (median), ``effort`` (mean), ``return`` (mean), ``left_workspace`` (count), ``episodes``
        (per-episode figures).
    """
    from fricenv.envs.payload import PayloadExcitationEnv
    from fricenv.utils import progress

    env = PayloadExcitationEnv(**(env_kwargs or {}))
    rows = []
    jobs = [(name, k) for name in policies for k in range(episodes)]
    results: dict[str, list[EpisodeResult]] = {name: [] for name in policies}
    for name, k in progress(jobs, total=len(jobs), desc="excitation", disable=None if progress_bar else True):
        policy = make_policy(name, env, seed=seed + k)
        results[name].append(run_episode(env, policy, seed=seed + k))
    for name in policies:
        eps = results[name]
        tb = [np.inf if r.t_below is None else r.t_below for r in eps]
        med = float(np.median(tb))
        rows.append({
            "policy": name,
            "t_below_1e-2": med if np.isfinite(med) else None,
            "E_end": float(np.median([r.E_end for r in eps])),
            "effort": float(np.mean([r.effort for r in eps])),
            "return": float(np.mean([r.ret for r in eps])),
            "left_workspace": int(sum(r.left_workspace for r in eps)),
            "episodes": [{"seed": seed + k, "t_below_1e-2": r.t_below, "E_end": r.E_end, "effort": r.effort,
                          "return": r.ret, "left_workspace": r.left_workspace, "duration": float(r.t[-1])}
                         for k, r in enumerate(eps)],
        })
    return rows
