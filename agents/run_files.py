"""The files of a training run: the names of the model, its normalisation statistics and its metadata, the files
beside the model that rl-zoo3 users expect, and the steps a run really trains.

``config.yml``: env id, algorithm, policy class, trained steps, normalisation, frame stack and hyperparameters.
``env_kwargs.yml``: the keyword arguments of ``gymnasium.make(env_id, **env_kwargs)`` that build the env the policy
acts on (the estimator and, for the braking env, the action map). :func:`rounded_steps`: PPO trains whole rollouts
(``n_envs x n_steps``), SAC whole rounds of its envs (``n_envs x train_freq``).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import yaml

from fricenv.utils import atomic_write

__all__ = ["CONFIG_FILE", "ENV_IDS", "ENV_KWARGS_FILE", "META_FILE", "MODEL_FILE", "VECNORM_FILE", "rounded_steps",
           "write_zoo_files", "zoo_files"]

ENV_IDS = {"braking": "fricenv/Braking-v0", "payload": "fricenv/PayloadExcitation-v0"}
CONFIG_FILE = "config.yml"
MODEL_FILE = "model.zip"  # the final policy (SB3 format)
VECNORM_FILE = "vecnormalize.pkl"  # its VecNormalize statistics
META_FILE = "train.json"  # what the run was: env, estimator, algorithm, seed, steps, hyperparameters, times
ENV_KWARGS_FILE = "env_kwargs.yml"


def rounded_steps(algo: str, cfg: Any, steps: int) -> int:
    """The env steps a run of ``steps`` trains: PPO whole rollouts of ``n_envs x n_steps``, SAC whole rounds of
    ``n_envs x train_freq``."""
    unit = cfg.n_envs * (cfg.train_freq if algo == "sac" else cfg.n_steps)
    return -(-int(steps) // unit) * unit


def zoo_files(env: str, estimator: str, algo: str, cfg: Any, steps: int,
              env_kwargs: dict | None, frame_stack: int) -> tuple[dict, dict]:
    """(config, env_kwargs) as ``config.yml`` and ``env_kwargs.yml`` hold them (module docstring)."""
    kwargs: dict[str, Any] = {"estimator": estimator, **json.loads(json.dumps(env_kwargs or {}))}
    if env == "braking":
        kwargs["action_map"] = cfg.action_map
    policy = "MlpLstmPolicy" if algo == "recurrent-ppo" else "MlpPolicy"
    normalize = {"norm_obs": cfg.norm_obs, "norm_reward": cfg.norm_reward} if cfg.norm_obs or cfg.norm_reward \
        else False
    hyper = json.loads(json.dumps(dataclasses.asdict(cfg)))
    config = {"env_id": ENV_IDS[env], "algo": algo, "policy": policy, "n_timesteps": int(steps),
              "normalize": normalize, "frame_stack": int(frame_stack), "hyperparams": hyper}
    return config, kwargs


def write_zoo_files(out: Path, config: dict, kwargs: dict) -> None:
    """Write ``config.yml`` and ``env_kwargs.yml`` into the run directory ``out``."""
    for name, content in ((CONFIG_FILE, config), (ENV_KWARGS_FILE, kwargs)):
        with atomic_write(out / name) as fh:
            yaml.safe_dump(content, fh, sort_keys=False)
