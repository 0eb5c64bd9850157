"""Stable-Baselines3 training of ABS policies (``Braking-v0``) and excitation policies (``PayloadExcitation-v0``).

:func:`train` builds vectorised envs (each with its own seed) over randomised scenarios, trains PPO or SAC with the
tuned defaults below, and writes to ``out``:

================================  ========================================================================
file                              content
================================  ========================================================================
``model.zip``                     the final policy (SB3 format)
``vecnormalize.pkl``              observation/reward normalisation statistics (VecNormalize)
``checkpoints/``                  periodic checkpoints (model and VecNormalize statistics)
``tb/``                           TensorBoard logs (``tensorboard`` is a dependency; without it, a warning)
``train.json``                    env, estimator, algorithm, seed, steps, hyperparameters, wall time, steps/s,
                                  the run it started from (``init``, :mod:`agents.warm_start`)
``config.yml``                    what rl-zoo3 keeps: env id, algorithm, policy, steps, normalisation, frame
                                  stack and the hyperparameters
``env_kwargs.yml``                the keyword arguments of ``gymnasium.make(env_id, **env_kwargs)`` that
                                  build the env the policy acts on (the estimator, the action map)
================================  ========================================================================

The policy loads the standard way: ``PPO.load("model.zip")`` and ``VecNormalize.load("vecnormalize.pkl", venv)``
on ``venv = DummyVecEnv([lambda: gymnasium.make(env_id, **env_kwargs)])`` (``VecNormalize.training = False``)
give the same env commands as :func:`load_policy` (the action map is inside that env).

Steps: PPO trains whole rollouts (``n_envs x n_steps`` env steps) and SAC whole rounds of its ``n_envs`` envs, so
the trained steps are ``steps`` rounded up to that unit (:func:`agents.run_files.rounded_steps`); ``train.json``
has both.

Braking scenarios (:class:`ScenarioMix`): each episode draws either a preset road (dry, wet, snow, ice;
probability ``1 - change_probability``) or a friction change between two different presets at a distance drawn
on 5..30 m, with roads weighted so that each gets about the same share of env steps, and an initial speed uniform
on :data:`V0_RANGE`. Payload: a random calibration S per episode.

Training signal of the ABS task beyond the env (fields of :class:`PPOConfig`, committed in
``agents/hyperparams/braking.json``): ``action_map`` maps the network's action to the env's torque command
(:mod:`agents.action_map`; ``log`` gives ice's 110 N m peak torque the same relative resolution as dry's 1100), and
``lock_onset_penalty`` charges the wheel-lock condition from its first step (:mod:`agents.lock_shaping`). Both act
in the training vector env only; the saved policy applies its map in :class:`TrainedPolicy`, so the env and the
evaluation are unchanged. ``train.json`` records wall and CPU time (one torch thread: the CPU time is the wall time
the run takes on a core of its own).

Torch runs one thread per process (``torch.set_num_threads(1)``): on a small machine the env, not the network, is
the bottleneck, and several threads per process only fight over the cores.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agents.hyperparams import BRAKING_FILE, load_hyperparams
from agents.run_files import META_FILE, MODEL_FILE, VECNORM_FILE
from agents.scenario_mix import CHANGE_PROBABILITY, CHANGE_RANGE, V0_RANGE, ScenarioMix, ScenarioSampler  # noqa: F401
from agents.warm_start import check_warm_start, warm_start
from fricenv.utils import write_json

__all__ = [
    "ALGOS",
    "DEFAULT_CONFIGS",
    "ENVS",
    "PPOConfig",
    "RecurrentPPOConfig",
    "SACConfig",
    "ScenarioMix",
    "TrainResult",
    "TrainedPolicy",
    "load_policy",
    "make_env_fn",
    "train",
]

ALGOS = ("ppo", "sac", "recurrent-ppo")  # recurrent-ppo: sb3-contrib's RecurrentPPO (LSTM), PPO hyperparameters
ENVS = ("braking", "payload")
CHECKPOINT_EVERY = 50_000  # env steps between checkpoints
SEED_STRIDE = 1000  # env i of a run with seed s is seeded s * SEED_STRIDE + i
VEC_KINDS = ("auto", "native", "dummy", "subproc")


@dataclass(frozen=True)
class PPOConfig:
    """PPO hyperparameters (the ABS task's are in ``agents/hyperparams/braking.json``; these field defaults are the
    ones first tuned on Braking-v0 with randomised roads, 8 envs).

    The reward is dense (braking efficiency per step) and the slip dynamics are fast (tens of ms), so a short
    horizon (gamma 0.95, i.e. ~0.2 s) is enough and learns faster than the usual 0.99; rewards are normalised by
    VecNormalize (their raw scale is 1e-4 per step).
    """

    n_envs: int = 8  # parallel envs
    n_steps: int = 256  # rollout length per env (2048 transitions per update)
    batch_size: int = 256  # minibatch [transitions]
    n_epochs: int = 10  # passes over each rollout
    learning_rate: float = 3e-4  # Adam step size
    gamma: float = 0.95  # discount per 10 ms step
    gae_lambda: float = 0.9  # GAE lambda
    clip_range: float = 0.2  # PPO ratio clip
    ent_coef: float = 0.0  # entropy bonus
    vf_coef: float = 0.5  # value loss weight
    max_grad_norm: float = 0.5  # gradient clip
    log_std_init: float = -1.5  # initial action noise std exp(-1.5) = 0.22 of the [-1, 1] range (280 N m)
    net_arch: tuple[int, ...] = (64, 64)  # policy and value MLP
    norm_obs: bool = True  # VecNormalize observations
    norm_reward: bool = True  # VecNormalize rewards
    action_map: str = "linear"  # network output -> env torque command (agents.action_map.ACTION_MAPS)
    lock_onset_penalty: float = 0.0  # training reward per step of lock condition before it counts as a lock
    # (agents.lock_shaping); 0: the env's reward alone


@dataclass(frozen=True)
class RecurrentPPOConfig(PPOConfig):
    """RecurrentPPO (sb3-contrib, ``MlpLstmPolicy``): PPO's fields plus the LSTM's. sb3-contrib's default (256
    units, separate actor and critic LSTMs) costs about 24 min per 300k steps on a loaded 2-core machine; the
    committed file uses a small actor-only LSTM (the critic is an MLP on the observation)."""

    lstm_hidden_size: int = 256  # LSTM units
    n_lstm_layers: int = 1  # stacked LSTM layers
    shared_lstm: bool = False  # one LSTM for actor and critic
    enable_critic_lstm: bool = True  # a separate LSTM for the critic (False with shared_lstm False: MLP critic)


@dataclass(frozen=True)
class SACConfig:
    """SAC defaults for the ABS task (off-policy; fewer env steps, more compute per step)."""

    n_envs: int = 4  # parallel envs
    learning_rate: float = 3e-4  # Adam step size
    buffer_size: int = 300_000  # replay buffer [transitions]
    batch_size: int = 256  # minibatch [transitions]
    learning_starts: int = 5_000  # random-action warm-up [transitions]
    tau: float = 0.005  # target smoothing
    gamma: float = 0.95  # discount per 10 ms step
    train_freq: int = 1  # env steps (per env) between updates
    gradient_steps: int = 1  # gradient steps per update
    ent_coef: str = "auto"  # learned entropy temperature
    net_arch: tuple[int, ...] = (256, 256)  # actor and critic MLPs
    norm_obs: bool = True  # VecNormalize observations
    norm_reward: bool = True  # VecNormalize rewards
    action_map: str = "linear"  # network output -> env torque command (agents.action_map.ACTION_MAPS)
    lock_onset_penalty: float = 0.0  # training reward per step of lock condition before it counts as a lock


# Payload excitation: longer horizon (the calibration reward comes from accumulated information).
PAYLOAD_PPO = PPOConfig(n_envs=4, n_steps=512, gamma=0.99, gae_lambda=0.95, log_std_init=-0.5, ent_coef=0.0)
CONFIG_CLASSES: dict[str, type] = {"ppo": PPOConfig, "sac": SACConfig, "recurrent-ppo": RecurrentPPOConfig}
BRAKING_CONFIGS = load_hyperparams(BRAKING_FILE, CONFIG_CLASSES)  # the committed file
DEFAULT_CONFIGS: dict[tuple[str, str], PPOConfig | SACConfig] = {
    ("braking", "ppo"): BRAKING_CONFIGS["ppo"],
    ("braking", "sac"): BRAKING_CONFIGS["sac"],
    ("braking", "recurrent-ppo"): BRAKING_CONFIGS.get("recurrent-ppo", BRAKING_CONFIGS["ppo"]),  # PPO's by default
    ("payload", "ppo"): PAYLOAD_PPO,
    ("payload", "sac"): SACConfig(gamma=0.99),
}


def native_vec_available(env: str, estimator: str) -> bool:
    """Whether ``vec="native"`` can run this env and estimator (braking, with none or a batched estimator)."""
    from estimators.batched import BATCHED

    return env == "braking" and (estimator == "none" or estimator in BATCHED)


def _check_choice(value: str, valid: tuple[str, ...], what: str) -> str:
    if value not in valid:
        raise ValueError(f"unknown {what} {value!r}; valid: {', '.join(valid)}")
    return value


def make_env_fn(env: str, estimator: str, rank: int = 0, training: bool = True,
                env_kwargs: dict | None = None) -> Callable[[], gym.Env]:
    """A picklable env constructor for SB3 vector envs.

    :param env: ``braking`` or ``payload``.
    :param estimator: estimator choice (braking: none/ekf/mhe/ekf-rls/oracle/...; payload: none/rls/oracle).
    :param rank: index of the env in the vector env (unused but kept for SubprocVecEnv symmetry).
    :param training: braking: draw scenarios with :class:`ScenarioMix`; payload: random calibrations.
    :param env_kwargs: extra env arguments.
    """
    _check_choice(env, ENVS, "env")
    kwargs = dict(env_kwargs or {})

    def _make() -> gym.Env:
        from stable_baselines3.common.monitor import Monitor

        if env == "braking":
            from fricenv.envs.factory import make_braking

            e = make_braking(estimator, **kwargs)
            if training:
                e = ScenarioMix(e)
        else:
            from fricenv.envs.factory import make_payload

            if training:
                kwargs.setdefault("calibration", "random")
            e = make_payload(estimator, **kwargs)
        return Monitor(e)

    return _make


@dataclass
class TrainResult:
    """What a training run produced."""

    out: Path  # run directory
    model_path: Path
    vecnormalize_path: Path
    steps: int  # env steps trained
    wall_time: float  # [s]
    steps_per_second: float
    meta: dict = field(default_factory=dict)


def _tensorboard_dir(out: Path) -> str | None:
    if importlib.util.find_spec("tensorboard") is None:
        warnings.warn("tensorboard is not installed: training runs without TensorBoard logs "
                      "(pip install tensorboard to get them)", RuntimeWarning, stacklevel=3)
        return None
    return str(out / "tb")


def check_train_args(env: str, estimator: str, algo: str, steps: int, vec: str,
                     config: PPOConfig | SACConfig | None) -> PPOConfig | SACConfig:
    """Validate the arguments of :func:`train` (ValueError or TypeError naming the bad one); the hyperparameters
    to use."""
    _check_choice(env, ENVS, "env")
    _check_choice(algo, ALGOS, "algo")
    _check_choice(vec, VEC_KINDS, "vec")
    if vec == "native" and not native_vec_available(env, estimator):
        raise ValueError(f"vec 'native' runs the braking env with estimator none or one with a batched form "
                         f"(estimators.batched.BATCHED), got env {env!r}, estimator {estimator!r}; use vec 'dummy'")
    if env == "braking":
        from fricenv.envs.estimator_observation import check_estimator_name

        check_estimator_name(estimator)
    else:
        from fricenv.envs.factory import PAYLOAD_ESTIMATOR_NAMES

        _check_choice(estimator, PAYLOAD_ESTIMATOR_NAMES, "payload estimator")
    if not isinstance(steps, int) or steps < 1:
        raise ValueError(f"steps must be a positive int, got {steps!r}")
    cfg = config if config is not None else DEFAULT_CONFIGS[(env, algo)]
    if algo == "recurrent-ppo" and type(cfg) is PPOConfig:
        cfg = RecurrentPPOConfig(**dataclasses.asdict(cfg))  # PPO's fields, sb3-contrib's LSTM defaults
    expected = CONFIG_CLASSES[algo]
    if not isinstance(cfg, expected):
        raise TypeError(f"config for {algo} must be a {expected.__name__}, got {type(cfg).__name__}")
    from agents.action_map import check_action_map

    check_action_map(cfg.action_map)
    if env != "braking" and (cfg.action_map != "linear" or cfg.lock_onset_penalty):
        raise ValueError(f"action_map and lock_onset_penalty are of the braking env: env {env!r} takes "
                         f"action_map 'linear' and lock_onset_penalty 0")
    return cfg


def _make_model(algo: str, cfg: PPOConfig | SACConfig, venv, tb: str | None, seed: int, verbose: int):
    """The SB3 model (PPO, RecurrentPPO or SAC, CPU) with the hyperparameters ``cfg`` on ``venv``."""
    from stable_baselines3 import PPO, SAC

    policy_kwargs: dict[str, Any] = {"net_arch": list(cfg.net_arch)}
    if algo != "sac":
        policy_kwargs["log_std_init"] = cfg.log_std_init
        policy = "MlpPolicy"
        if algo == "recurrent-ppo":
            from sb3_contrib import RecurrentPPO as PPO

            policy = "MlpLstmPolicy"
            policy_kwargs.update(lstm_hidden_size=cfg.lstm_hidden_size, n_lstm_layers=cfg.n_lstm_layers,
                                 shared_lstm=cfg.shared_lstm, enable_critic_lstm=cfg.enable_critic_lstm)
        return PPO(policy, venv, n_steps=cfg.n_steps, batch_size=cfg.batch_size, n_epochs=cfg.n_epochs,
                   learning_rate=cfg.learning_rate, gamma=cfg.gamma, gae_lambda=cfg.gae_lambda,
                   clip_range=cfg.clip_range, ent_coef=cfg.ent_coef, vf_coef=cfg.vf_coef,
                   max_grad_norm=cfg.max_grad_norm, policy_kwargs=policy_kwargs, tensorboard_log=tb,
                   seed=seed, verbose=verbose, device="cpu")
    return SAC("MlpPolicy", venv, learning_rate=cfg.learning_rate, buffer_size=cfg.buffer_size,
               batch_size=cfg.batch_size, learning_starts=cfg.learning_starts, tau=cfg.tau, gamma=cfg.gamma,
               train_freq=cfg.train_freq, gradient_steps=cfg.gradient_steps, ent_coef=cfg.ent_coef,
               policy_kwargs=policy_kwargs, tensorboard_log=tb, seed=seed, verbose=verbose, device="cpu")


def make_training_model(env: str, estimator: str, algo: str, cfg: PPOConfig | SACConfig, seed: int,
                        vec: str = "native", env_kwargs: dict | None = None, frame_stack: int = 0,
                        tb: str | None = None, verbose: int = 0):
    """The SB3 model of a training run on its normalised vector env (the training curriculum): what
    :func:`train` learns with, and what ``fricenv tune`` scores.

    :param env: ``braking`` or ``payload``.
    :param estimator: estimator appended to the observation.
    :param algo: ``ppo`` or ``sac``.
    :param cfg: hyperparameters.
    :param seed: seed of the run; env ``i`` is seeded ``seed * SEED_STRIDE + i``.
    :param vec: ``native``, ``dummy`` or ``subproc`` (see :func:`train`).
    :param env_kwargs: extra env arguments.
    :param frame_stack: k > 0: the last k observations (``VecFrameStack``); 0: none.
    :param tb: TensorBoard directory or None.
    :param verbose: SB3 verbosity.
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize

    if not isinstance(frame_stack, int) or frame_stack < 0:
        raise ValueError(f"frame_stack must be an int >= 0 (0: none), got {frame_stack!r}")
    if vec == "native":
        from fricenv.envs.sb3_vec import make_sb3_vec_env

        venv = make_sb3_vec_env(cfg.n_envs, seed=seed * SEED_STRIDE, estimator=estimator,
                                scenarios=ScenarioSampler(), **(env_kwargs or {}))
    else:
        fns = [make_env_fn(env, estimator, rank=i, training=True, env_kwargs=env_kwargs)
               for i in range(cfg.n_envs)]
        venv = SubprocVecEnv(fns) if vec == "subproc" else DummyVecEnv(fns)
        venv.seed(seed * SEED_STRIDE)
    if cfg.action_map != "linear":
        from agents.action_map import ActionMapVecEnv

        venv = ActionMapVecEnv(venv, cfg.action_map)
    if cfg.lock_onset_penalty:
        from agents.lock_shaping import LockOnsetPenaltyVecEnv

        venv = LockOnsetPenaltyVecEnv(venv, cfg.lock_onset_penalty)
    if frame_stack:
        from stable_baselines3.common.vec_env import VecFrameStack

        venv = VecFrameStack(venv, frame_stack)
    venv = VecNormalize(venv, norm_obs=cfg.norm_obs, norm_reward=cfg.norm_reward, gamma=cfg.gamma)
    return _make_model(algo, cfg, venv, tb, seed, verbose)


def train(out: str | Path, env: str = "braking", estimator: str = "none", algo: str = "ppo", steps: int = 200_000,
          seed: int = 0, config: PPOConfig | SACConfig | None = None, vec: str = "auto",
          progress_bar: bool = True, checkpoint_every: int = CHECKPOINT_EVERY,
          env_kwargs: dict | None = None, verbose: int = 0, frame_stack: int = 0,
          init: str | Path | None = None) -> TrainResult:
    """Train a policy and save model, normalisation statistics, checkpoints and metadata in ``out``.

    :param out: run directory (created).
    :param env: ``braking`` or ``payload``.
    :param estimator: estimator whose outputs are appended to the observation.
    :param algo: ``ppo`` or ``sac``.
    :param steps: env steps to train.
    :param seed: seed of the run (networks, envs).
    :param config: hyperparameters; default :data:`DEFAULT_CONFIGS` for (env, algo).
    :param vec: ``auto`` (``native`` where available, else ``dummy``), ``native`` (the braking vector env, all cars
        and a batched estimator in one numpy call: :mod:`fricenv.envs.sb3_vec`), ``dummy`` (single envs in this
        process) or ``subproc`` (one process per env). ``native`` and ``dummy`` draw the same scenarios.
    :param progress_bar: show a progress bar (tqdm + rich).
    :param checkpoint_every: env steps between checkpoints (0: none).
    :param env_kwargs: extra env arguments.
    :param verbose: SB3 verbosity.
    :param frame_stack: k > 0: the policy sees the last k observations (SB3's ``VecFrameStack``), the memory
        baseline; 0: the observation alone.
    :param init: a training run to start from (:mod:`agents.warm_start`: its policy's weights and normalisation
        statistics; same env, estimator, algorithm, frame stack and network); ``train.json`` names it.
    """
    import torch
    from stable_baselines3.common.callbacks import CheckpointCallback

    cfg = check_train_args(env, estimator, algo, steps, vec, config)
    source = None
    if init is not None:
        source = check_warm_start(init, env, estimator, algo, frame_stack, list(cfg.net_arch))
    torch.set_num_threads(1)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)

    if vec == "auto":
        vec = "native" if native_vec_available(env, estimator) else "dummy"
    tb = _tensorboard_dir(out)
    model = make_training_model(env, estimator, algo, cfg, seed, vec, env_kwargs, frame_stack, tb, verbose)
    if init is not None:
        warm_start(model, init)
    venv = model.get_env()
    callbacks = []
    if checkpoint_every > 0:
        callbacks.append(CheckpointCallback(save_freq=max(checkpoint_every // cfg.n_envs, 1),
                                            save_path=str(out / "checkpoints"), name_prefix=algo,
                                            save_vecnormalize=True))
    t0, cpu0 = time.perf_counter(), time.process_time()
    model.learn(total_timesteps=steps, callback=callbacks or None, progress_bar=progress_bar,
                tb_log_name=f"{algo}-{estimator}")
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    model_path, vn_path = out / MODEL_FILE, out / VECNORM_FILE
    model.save(str(model_path))
    venv.save(str(vn_path))
    venv.close()
    trained = int(model.num_timesteps)
    meta = {"env": env, "estimator": estimator, "algo": algo, "seed": seed, "steps": trained,
            "steps_requested": int(steps),
            "wall_time_s": wall, "steps_per_second": trained / wall, "cpu_time_s": cpu,
            "config": dataclasses.asdict(cfg),
            "vec": vec, "env_kwargs": env_kwargs or {}, "tensorboard": tb is not None,
            "torch_threads": torch.get_num_threads(), "frame_stack": frame_stack,
            "init": None if source is None else {"run": str(init), "steps": source.get("steps"),
                                                  "env_kwargs": source.get("env_kwargs", {})}}
    write_json(out / META_FILE, meta)
    from agents.run_files import write_zoo_files, zoo_files

    write_zoo_files(out, *zoo_files(env, estimator, algo, cfg, trained, env_kwargs, frame_stack))
    return TrainResult(out=out, model_path=model_path, vecnormalize_path=vn_path, steps=trained, wall_time=wall,
                       steps_per_second=trained / wall, meta=meta)


class TrainedPolicy:
    """A saved policy with its normalisation statistics, as a controller: ``reset()``, ``act(obs) -> action``.

    :param model: the SB3 model.
    :param obs_rms: VecNormalize statistics (or None).
    :param meta: the run's ``train.json`` content.
    """

    def __init__(self, model, vecnormalize, meta: dict):
        self.model = model
        self.vecnormalize = vecnormalize
        self.meta = meta
        self.estimator = meta.get("estimator", "none")
        self.algo = meta.get("algo", "ppo")
        self.frame_stack = int(meta.get("frame_stack", 0))
        from agents.action_map import check_action_map

        self.action_map = check_action_map(meta.get("config", {}).get("action_map", "linear"))
        self.name = f"{self.algo}[{self.estimator}]"
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        """Start of an episode: empty frame stack, fresh LSTM state (``seed`` is accepted for the excitation
        interface)."""
        self._stack: np.ndarray | None = None
        self._state = None
        self._episode_start = True

    def act(self, obs) -> np.ndarray:
        """Deterministic action for one observation (shape (act_dim,)); a frame-stack policy sees the last
        ``frame_stack`` observations (zeros before the first, as SB3's VecFrameStack), a recurrent one its state."""
        obs = np.asarray(obs, dtype=np.float32).ravel()
        if self.frame_stack:
            if self._stack is None:
                self._stack = np.zeros(self.frame_stack * obs.size, dtype=np.float32)
            self._stack = np.concatenate([self._stack[obs.size:], obs])
            obs = self._stack
        if self.vecnormalize is not None:
            obs = self.vecnormalize.normalize_obs(obs)
        if self.algo == "recurrent-ppo":
            action, self._state = self.model.predict(obs, state=self._state, deterministic=True,
                                                     episode_start=np.array([self._episode_start]))
            self._episode_start = False
        else:
            action, _ = self.model.predict(obs, deterministic=True)
        if self.meta.get("env", "braking") == "braking":
            action = self.action_map(np.asarray(action, dtype=float))
        return np.asarray(action, dtype=np.float32)


def load_policy(run_dir: str | Path, model_file: str | None = None,
                vecnormalize_file: str | None = None) -> TrainedPolicy:
    """Load ``model.zip`` (or ``model_file``), ``vecnormalize.pkl`` and ``train.json`` from a run directory.

    :param run_dir: the ``out`` of :func:`train`.
    :param model_file: another model in the run (e.g. a checkpoint), relative to ``run_dir``.
    :param vecnormalize_file: its normalisation statistics, relative to ``run_dir``.
    """
    import pickle

    import torch
    from stable_baselines3 import PPO, SAC

    torch.set_num_threads(1)
    run_dir = Path(run_dir)
    meta_path = run_dir / META_FILE
    if not meta_path.is_file():
        raise ValueError(f"{run_dir} is not a training run: {META_FILE} is missing")
    meta = json.loads(meta_path.read_text())
    algo = meta.get("algo")
    _check_choice(algo, ALGOS, f"algo in {meta_path}")
    path = run_dir / (model_file or MODEL_FILE)
    if not path.is_file():
        raise ValueError(f"model file {path} does not exist")
    if algo == "recurrent-ppo":
        from sb3_contrib import RecurrentPPO as PPO
    model = (SAC if algo == "sac" else PPO).load(str(path), device="cpu")
    vn = None
    vn_path = run_dir / (vecnormalize_file or VECNORM_FILE)
    if vn_path.is_file():
        with open(vn_path, "rb") as fh:
            vn = pickle.load(fh)  # a VecNormalize without its venv: only normalize_obs is used
        vn.training = False
    return TrainedPolicy(model, vn, meta)
