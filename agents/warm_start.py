"""Warm start of a training run from another: its policy's weights and its normalisation statistics (fine-tuning).

A run started from a source run (``fricenv train --init RUN``) trains the source's policy on its own envs, for
example a policy trained on the nominal plant trained on further over the effect grid's distribution. Its network
starts at the source's weights (the optimiser starts afresh), and its ``VecNormalize`` at the source's observation
and return statistics, which go on adapting to the new envs. The two runs must act on the same observation and
action: same env, estimator, algorithm, frame stack and network (:func:`check_warm_start`, before any training).
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path
from typing import Any

from agents.run_files import META_FILE, MODEL_FILE, VECNORM_FILE

__all__ = ["check_warm_start", "warm_start"]

MATCHED = ("env", "estimator", "algo", "frame_stack")  # train.json fields the two runs share


def check_warm_start(run_dir: str | Path, env: str, estimator: str, algo: str, frame_stack: int,
                     net_arch: Any) -> dict:
    """The source run's ``train.json``, after checking that a run of these settings can start from it.

    :param run_dir: the source run (the ``out`` of :func:`agents.training.train`).
    :param env: the new run's env; :param estimator: its estimator; :param algo: its algorithm.
    :param frame_stack: its frame stack (0: none); :param net_arch: its network (``config.net_arch``).
    :raises ValueError: naming the missing file or the setting that differs, and the source's value.
    """
    run_dir = Path(run_dir)
    for name in (META_FILE, MODEL_FILE, VECNORM_FILE):
        if not (run_dir / name).is_file():
            raise ValueError(f"init run {run_dir}: {name} is missing (give the out directory of a finished "
                             f"fricenv train)")
    meta = json.loads((run_dir / META_FILE).read_text())
    ours = {"env": env, "estimator": estimator, "algo": algo, "frame_stack": frame_stack}
    for key in MATCHED:
        theirs = meta.get(key, 0 if key == "frame_stack" else None)
        if theirs != ours[key]:
            raise ValueError(f"init run {run_dir} has {key} {theirs!r}, this run {ours[key]!r}: a warm start "
                             f"needs the same {', '.join(MATCHED)}")
    theirs = meta.get("config", {}).get("net_arch")
    if theirs is not None and json.loads(json.dumps(net_arch)) != theirs:
        raise ValueError(f"init run {run_dir} has net_arch {theirs!r}, this run {net_arch!r}: a warm start "
                         f"needs the same network")
    return meta


def warm_start(model, run_dir: str | Path) -> None:
    """Load the source run's policy weights into ``model`` and its normalisation statistics into ``model``'s
    ``VecNormalize``. The caller checks the source with :func:`check_warm_start` before building ``model``.

    :param model: the new run's SB3 model, on its ``VecNormalize`` env.
    :param run_dir: the source run.
    :raises ValueError: when the source's observation statistics do not fit the new env's observation.
    """
    run_dir = Path(run_dir)
    venv = model.get_env()
    with open(run_dir / VECNORM_FILE, "rb") as fh:
        stats = pickle.load(fh)
    if stats.obs_rms.mean.shape != venv.obs_rms.mean.shape:  # before the weights, whose load would fail unclearly
        raise ValueError(f"init run {run_dir}: observation statistics of shape {stats.obs_rms.mean.shape}, this "
                         f"run's observation has shape {venv.obs_rms.mean.shape}")
    source = type(model).load(str(run_dir / MODEL_FILE), device="cpu")
    model.policy.load_state_dict(source.policy.state_dict())
    venv.obs_rms, venv.ret_rms = stats.obs_rms, stats.ret_rms
