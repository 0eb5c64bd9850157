"""Benchmark targets of ``fricenv bench`` beyond the single env: reference env, vector env, estimators, PPO slice,
gap diagnosis.

Each target is a function ``(args) -> dict`` of figures, merged into the ``--json`` output by
:mod:`fricenv.commands.bench`; ``args`` carries ``repeats``, ``steps`` and ``seed``. Every figure is the median
over ``args.repeats`` repeats in this process (the ``*_all`` keys keep every repeat); :func:`ratios` divides by
Gymnasium's ``Pendulum-v1`` measured in the same run, which is what to compare across machines. Nothing here asserts
a speed: benchmarks measure, tests check correctness.
"""

from __future__ import annotations

import argparse
import importlib
import statistics
import time
from collections.abc import Callable
from typing import Any

__all__ = [
    "BRAKING_ENV",
    "REFERENCE_ENV",
    "VECTOR_SIZES",
    "bench_estimators",
    "bench_gap",
    "bench_pendulum",
    "bench_ppo",
    "bench_training",
    "bench_vector",
    "env_steps_per_s",
    "ratios",
]

REFERENCE_ENV = "Pendulum-v1"
BRAKING_ENV = "fricenv/Braking-v0"
VECTOR_SIZES = (1, 64, 1024)
# Batched steps per repeat of the vector benchmark: steps // num_envs, at least this many.
MIN_VECTOR_STEPS = 100
# The PPO slice: sub-envs, rollout length per sub-env, minibatch, epochs, rollouts per repeat.
PPO_ENVS = 16
PPO_N_STEPS = 128
PPO_BATCH = 512
PPO_EPOCHS = 4
PPO_ROLLOUTS = 2
ESTIMATOR_MODULE = "estimators.bench"
COARSE_PHYSICS_DT = 0.005  # [s] 2 substeps per 10 ms control step (an option, not the default 2 ms)
# The gap benchmark's log: one 5 s wet-road ABS stop with a brake lag (the example), diagnosed on 2 cores.
GAP_EFFECT = ("brake_lag", {"tau": 0.04})
GAP_ROAD = "wet"
GAP_JOBS = 2
# The training target: env steps of one `fricenv train` run per estimator (all on the native vector env).
TRAINING_STEPS = {"none": 40_960, "ekf-rls": 40_960, "mhe": 40_960}
SPEED_CALLS = 20  # speed reconstructions per repeat (one parameter set, as in a least-squares residual call)


def _median_and_all(values: list[float]) -> tuple[float, list[float]]:
    return statistics.median(values), list(values)


def env_steps_per_s(env_id: str, steps: int, seed: int, **kwargs) -> float:
    """Steps per second of ``gymnasium.make(env_id)`` under a fixed zero action, resetting at episode end.

    :param env_id: registered env id.
    :param steps: steps to time.
    :param seed: reset seed.
    :param kwargs: env keyword arguments.
    :return: steps per second (wall clock).
    """
    import gymnasium as gym
    import numpy as np

    env = gym.make(env_id, **kwargs)
    action = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
    env.reset(seed=seed)
    env.step(action)  # first call outside the timing (lazy loads: the compiled substeps come from numba's cache)
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    elapsed = time.perf_counter() - start
    env.close()
    return steps / elapsed


def bench_pendulum(args: argparse.Namespace) -> dict[str, Any]:
    """Gymnasium's ``Pendulum-v1`` steps per second (the reference every ratio divides by)."""
    runs = [env_steps_per_s(REFERENCE_ENV, args.steps, seed=args.seed + k) for k in range(args.repeats)]
    median, every = _median_and_all(runs)
    print(f"pendulum: {REFERENCE_ENV} {median:,.0f} steps/s (median of {args.repeats} x {args.steps} steps)")
    return {"pendulum_steps_per_s": median, "pendulum_steps_per_s_all": every}


def _vector_env_steps_per_s(num_envs: int, batched_steps: int, seed: int, **env_kwargs) -> tuple[float, float]:
    """Env-steps per second of the native vector env (make_vec, vector_entry_point) under a fixed zero action:
    (per wall-clock second, per second of this process's CPU time)."""
    import gymnasium as gym
    import numpy as np

    import fricenv  # noqa: F401  (registers the envs)

    envs = gym.make_vec(BRAKING_ENV, num_envs=num_envs, vectorization_mode="vector_entry_point", **env_kwargs)
    actions = np.zeros(envs.action_space.shape, dtype=envs.action_space.dtype)
    envs.reset(seed=seed)
    envs.step(actions)  # first call outside the timing (lazy allocations)
    start, cpu = time.perf_counter(), time.process_time()
    for _ in range(batched_steps):
        envs.step(actions)  # autoreset (next step) happens inside
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
    envs.close()
    return num_envs * batched_steps / elapsed, num_envs * batched_steps / max(cpu, 1e-9)


def bench_vector(args: argparse.Namespace) -> dict[str, Any]:
    """Native vector env env-steps per second at 1, 64 and 1024 sub-envs (one process, one core)."""
    medians: dict[str, float] = {}
    every: dict[str, list[float]] = {}
    cpu_medians: dict[str, float] = {}
    for n in VECTOR_SIZES:
        batched = max(MIN_VECTOR_STEPS, args.steps // n)
        runs = [_vector_env_steps_per_s(n, batched, seed=args.seed + k) for k in range(args.repeats)]
        medians[str(n)], every[str(n)] = _median_and_all([wall for wall, _ in runs])
        cpu_medians[str(n)] = statistics.median([cpu for _, cpu in runs])
        print(f"vector: {n:5d} envs {medians[str(n)]:,.0f} env-steps/s "
              f"({cpu_medians[str(n)]:,.0f} per CPU second; median of {args.repeats} x {batched} batched steps)")
    # Not the default: 2 physics substeps per control step (physics_dt = 5 ms), within 0.1 % of the Radau
    # stopping distances (tests/envs/test_braking_vector.py, slow), for users who trade accuracy margin for speed.
    n = VECTOR_SIZES[-1]
    batched = max(MIN_VECTOR_STEPS, args.steps // n)
    coarse = [_vector_env_steps_per_s(n, batched, seed=args.seed + k, physics_dt=COARSE_PHYSICS_DT)
              for k in range(args.repeats)]
    coarse_median = statistics.median([wall for wall, _ in coarse])
    print(f"vector: {n:5d} envs {coarse_median:,.0f} env-steps/s with physics_dt={COARSE_PHYSICS_DT} "
          f"(2 substeps, not the default)")
    return {"vector_steps_per_s": medians, "vector_steps_per_s_all": every, "vector_steps_per_cpu_s": cpu_medians,
            "vector_steps_per_s_physics_dt_5ms": {str(n): coarse_median}}


def bench_estimators(args: argparse.Namespace) -> dict[str, Any]:
    """Mean update time [us] per estimator, from ``estimators.bench.bench_estimators(repeats, seed)`` if present."""
    try:
        module = importlib.import_module(ESTIMATOR_MODULE)
    except ModuleNotFoundError as exc:
        if exc.name != ESTIMATOR_MODULE:
            raise
        print(f"estimators: {ESTIMATOR_MODULE} is not installed; skipped")
        return {"estimator_update_us": {}}
    raw = module.bench_estimators(repeats=args.repeats, seed=args.seed)
    means = {name: _mean_us(value) for name, value in raw.items()}
    cpu = {name: float(value["cpu_mean_us"]) for name, value in raw.items()
           if isinstance(value, dict) and "cpu_mean_us" in value}
    for name, us in means.items():
        extra = f", {cpu[name]:10.1f} us CPU" if name in cpu else ""
        print(f"estimators: {name:24s} {us:10.1f} us per update (mean{extra}); sample time 10 ms")
    return {"estimator_update_us": means, "estimator_update_cpu_us": cpu, "estimator_bench_raw": raw}


def _mean_us(value: Any) -> float:
    """The mean update time [us] of one estimator entry: a number, or a dict with a mean-like key."""
    if isinstance(value, (int, float)):
        return float(value)
    if isinstance(value, dict):
        for key in ("mean_us", "mean", "update_us", "mean_update_us"):
            if key in value:
                return float(value[key])
    raise ValueError(f"estimators.bench.bench_estimators returned an entry of unknown shape: {value!r}; expected "
                     f"a number [us] or a dict with 'mean_us'")


def _ppo_slice(seed: int) -> tuple[float, float]:
    """One PPO training slice on the native vector env: (env-steps per second, fraction of time in the env)."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecEnvWrapper, VecMonitor

    from fricenv.envs.sb3_vec import BrakingSB3VecEnv

    torch.set_num_threads(1)

    class Timed(VecEnvWrapper):
        """Adds up the wall time spent in the wrapped env."""

        def __init__(self, venv):
            super().__init__(venv)
            self.elapsed = 0.0

        def reset(self):
            t = time.perf_counter()
            obs = self.venv.reset()
            self.elapsed += time.perf_counter() - t
            return obs

        def step_async(self, actions):
            t = time.perf_counter()
            self.venv.step_async(actions)
            self.elapsed += time.perf_counter() - t

        def step_wait(self):
            t = time.perf_counter()
            out = self.venv.step_wait()
            self.elapsed += time.perf_counter() - t
            return out

    env = Timed(VecMonitor(BrakingSB3VecEnv(PPO_ENVS)))
    model = PPO("MlpPolicy", env, n_steps=PPO_N_STEPS, batch_size=PPO_BATCH, n_epochs=PPO_EPOCHS, seed=seed,
                device="cpu", verbose=0)
    total = PPO_ENVS * PPO_N_STEPS * PPO_ROLLOUTS
    start = time.perf_counter()
    model.learn(total_timesteps=total, progress_bar=False)
    wall = time.perf_counter() - start
    steps = model.num_timesteps
    env.close()
    return steps / wall, env.elapsed / wall


def bench_ppo(args: argparse.Namespace) -> dict[str, Any]:
    """A fixed PPO slice (SB3, MlpPolicy, CPU, 1 thread) on the native vector env: steps/s and env time share."""
    rates, shares = [], []
    for k in range(args.repeats):
        rate, share = _ppo_slice(args.seed + k)
        rates.append(rate)
        shares.append(share)
    out = {
        "ppo_steps_per_s": statistics.median(rates),
        "ppo_env_time_fraction": statistics.median(shares),
        "ppo_steps_per_s_all": rates,
        "ppo_env_time_fraction_all": shares,
        "ppo_slice": {"num_envs": PPO_ENVS, "n_steps": PPO_N_STEPS, "batch_size": PPO_BATCH,
                      "n_epochs": PPO_EPOCHS, "timesteps": PPO_ENVS * PPO_N_STEPS * PPO_ROLLOUTS},
    }
    print(f"ppo: {out['ppo_steps_per_s']:,.0f} steps/s on {PPO_ENVS} vector sub-envs, env share of the time "
          f"{out['ppo_env_time_fraction']:.1%} (median of {args.repeats} slices of "
          f"{out['ppo_slice']['timesteps']} steps)")
    return out


def _training_rate(estimator: str, steps: int, seed: int) -> tuple[float, str]:
    """env-steps/s of ``fricenv train`` (PPO, the committed hyperparameters, no checkpoints) and the vec env used."""
    import tempfile

    from agents.training import train

    with tempfile.TemporaryDirectory() as out:
        res = train(out, estimator=estimator, algo="ppo", steps=steps, seed=seed, progress_bar=False,
                    checkpoint_every=0)
    return res.steps_per_second, res.meta["vec"]


def bench_training(args: argparse.Namespace) -> dict[str, Any]:
    """PPO training speed as ``fricenv train`` runs it, without estimates, with the EKF/RLS and with the MHE, in
    the same run, and the ratios to the run without estimates (the targets: EKF/RLS >= 10,000 env-steps/s and
    >= 0.8x, MHE >= 2,000)."""
    rates: dict[str, list[float]] = {name: [] for name in TRAINING_STEPS}
    vec: dict[str, str] = {}
    for k in range(args.repeats):
        for name, steps in TRAINING_STEPS.items():
            rate, vec[name] = _training_rate(name, steps, args.seed + k)
            rates[name].append(rate)
    med = {name: statistics.median(r) for name, r in rates.items()}
    out = {"training_steps_per_s": med, "training_steps_per_s_all": rates, "training_vec": vec,
           "training_steps": dict(TRAINING_STEPS),
           "training_ratio_to_none": {name: r / med["none"] for name, r in med.items() if name != "none"}}
    print("training (PPO, fricenv train): " + ", ".join(
        f"{name} {med[name]:,.0f} env-steps/s ({vec[name]} vec, {TRAINING_STEPS[name]} steps"
        + (f", {out['training_ratio_to_none'][name]:.2f}x none)" if name != "none" else ")") for name in med)
        + f" (median of {args.repeats})")
    return out


def ratios(figures: dict[str, Any]) -> dict[str, Any]:
    """Every steps-per-second figure divided by ``pendulum_steps_per_s`` of the same run (empty without it)."""
    ref = figures.get("pendulum_steps_per_s")
    if not ref:
        return {}
    out: dict[str, Any] = {}
    if "single_steps_per_s" in figures:
        out["single"] = figures["single_steps_per_s"] / ref
    if "vector_steps_per_s" in figures:
        out["vector"] = {n: v / ref for n, v in figures["vector_steps_per_s"].items()}
    if "ppo_steps_per_s" in figures:
        out["ppo"] = figures["ppo_steps_per_s"] / ref
    return {"ratio_to_pendulum": out}


def _gap_log(seed: int, all_channels: bool):
    from fricenv.effects.quarter_car import make_effect
    from fricenv.gap.quarter_car.simulate import simulate_log
    from fricenv.plants.tire import get_road

    log, _ = simulate_log([make_effect(GAP_EFFECT[0], **GAP_EFFECT[1])], get_road(GAP_ROAD), "abs", seed=seed,
                          write_v=all_channels, write_ax=all_channels)
    return log


def _speed_reconstruction_ms(log) -> tuple[float, float]:
    """ms per call of the whole-trajectory speed reconstruction and of its sample-by-sample reference."""
    from fricenv.effects.quarter_car import ModelBatch
    from fricenv.gap.signals.speed import reconstruct_speed, reconstruct_speed_sequential
    from fricenv.plants import quarter_car as qc
    from fricenv.plants.tire import get_road

    args = (ModelBatch.nominal(get_road(GAP_ROAD), 1), log.omega, float(log.t[0]), float(log.t[1] - log.t[0]), 20,
            qc.PAPER_PARAMS)
    out = []
    for fn in (reconstruct_speed, reconstruct_speed_sequential):
        t = time.perf_counter()
        for _ in range(SPEED_CALLS):
            fn(*args)
        out.append((time.perf_counter() - t) / SPEED_CALLS * 1e3)
    return out[0], out[1]


GAP_PATHS = {"compiled": True, "numpy": False}  # window simulators timed in the same run (DiagnoseConfig.compiled)


def _diagnose_seconds(log, compiled: bool) -> tuple[float, float]:
    """Wall seconds and CPU seconds of one diagnosis (its worker processes end with it, so their CPU is counted)."""
    import warnings

    from fricenv.gap.quarter_car.diagnose import DiagnoseConfig, diagnose

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        cpu, t = _cpu_seconds(), time.perf_counter()
        diagnose(log, cfg=DiagnoseConfig(jobs=GAP_JOBS, compiled=compiled))
        return time.perf_counter() - t, _cpu_seconds() - cpu


def _cpu_seconds() -> float:
    """User + system CPU seconds of this process and of its ended child processes (NaN where not measurable)."""
    try:
        import resource
    except ImportError:  # pragma: no cover - not on Linux / macOS
        return float("nan")
    return sum(u.ru_utime + u.ru_stime for u in (resource.getrusage(resource.RUSAGE_SELF),
                                                 resource.getrusage(resource.RUSAGE_CHILDREN)))


def _medians(times: dict[str, dict[str, list[float]]]) -> dict[str, dict[str, float]]:
    """The median of each list of a ``{path: {channels: [seconds, ...]}}`` table."""
    return {path: {key: statistics.median(v) for key, v in by.items()} for path, by in times.items()}


def bench_gap(args: argparse.Namespace) -> dict[str, Any]:
    """Wall seconds to diagnose one 5 s log on 2 cores (all channels, and t, T_b, omega only) with the compiled
    window simulator and with the numpy one (its simulator and forward-difference Jacobian are the path before
    the compiled one; the least-squares stop and the forward-selection screen are shared) in the same run, interleaved,
    and their ratio, and the CPU seconds of each diagnosis with its worker processes (on a loaded machine the wall
    time varies with the other load, the CPU time much less); ms per speed reconstruction (the no-``v`` logs' inner
    loop) against its sample-by-sample reference."""
    channels = ("all_channels", "required_only")
    seconds = {path: {key: [] for key in channels} for path in GAP_PATHS}
    cpu = {path: {key: [] for key in channels} for path in GAP_PATHS}
    newton, sequential = [], []
    for k in range(args.repeats):
        for key in channels:
            log = _gap_log(args.seed + k, key == "all_channels")
            for path, compiled in GAP_PATHS.items():
                wall, used = _diagnose_seconds(log, compiled)
                seconds[path][key].append(wall)
                cpu[path][key].append(used)
        a, b = _speed_reconstruction_ms(_gap_log(args.seed + k, False))
        newton.append(a)
        sequential.append(b)
    med, med_cpu = _medians(seconds), _medians(cpu)
    out = {"gap_diagnose_seconds": med["compiled"], "gap_diagnose_seconds_numpy": med["numpy"],
           "gap_speedup": {key: med["numpy"][key] / med["compiled"][key] for key in channels},
           "gap_diagnose_seconds_all": seconds["compiled"], "gap_diagnose_seconds_numpy_all": seconds["numpy"],
           # CPU seconds of the diagnosis and its worker processes: what a loaded machine changes least
           "gap_diagnose_cpu_seconds": med_cpu["compiled"], "gap_diagnose_cpu_seconds_numpy": med_cpu["numpy"],
           "speed_reconstruction_ms": {"newton": statistics.median(newton),
                                       "sequential": statistics.median(sequential)}}
    out["speed_reconstruction_ms"]["ratio"] = out["speed_reconstruction_ms"]["sequential"] / \
        out["speed_reconstruction_ms"]["newton"]
    s, o, x, r = med["compiled"], med["numpy"], out["gap_speedup"], out["speed_reconstruction_ms"]
    print(f"gap: one 5 s log diagnosed in {s['all_channels']:.1f} s with all channels (numpy path "
          f"{o['all_channels']:.1f} s, {x['all_channels']:.1f}x), {s['required_only']:.1f} s with t, T_b, omega only "
          f"(numpy path {o['required_only']:.1f} s, {x['required_only']:.1f}x) ({GAP_JOBS} processes, median of "
          f"{args.repeats}; CPU {med_cpu['compiled']['all_channels']:.1f} / {med_cpu['compiled']['required_only']:.1f} "
          f"s); speed reconstruction {r['newton']:.2f} ms per call, sample-by-sample {r['sequential']:.2f} ms "
          f"({r['ratio']:.1f}x)")
    return out


# Targets added to `fricenv bench` (name -> function(args) -> figures).
TARGETS: dict[str, Callable[[argparse.Namespace], dict]] = {
    "pendulum": bench_pendulum,
    "vector": bench_vector,
    "estimators": bench_estimators,
    "ppo": bench_ppo,
    "gap": bench_gap,
    "training": bench_training,
}
# Targets left out of ``fricenv bench all``: minutes per repeat.
SLOW_TARGETS = ("gap", "training")
