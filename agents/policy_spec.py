"""One parser for the policy specs every closed-loop command takes (``fricenv evaluate``, ``fricenv gap policy``).

=========================  ==========  ============================================================================
spec                       kind        policy
=========================  ==========  ============================================================================
``rule-abs``, ``locked``   controller  :data:`agents.controllers.CONTROLLERS` on measured signals
``oracle-slip``,           controller  the same on the true state and road (they need ``observation="oracle"``)
``slip-pi``
``pipeline:EST``           pipeline    estimator EST (an observation estimator of
                                       :data:`fricenv.envs.estimator_observation.ESTIMATOR_NAMES` but ``none``)
                                       + slip controller (:class:`agents.pipeline.EstimatorSlipPipeline`)
``DIR``                    trained     a braking training run directory (``train.json``, ``model.zip``, ...)
=========================  ==========  ============================================================================

:func:`parse_policy_spec` only parses (it reads a run's ``train.json``, it loads no model); an invalid spec raises
:class:`PolicySpecError` (a ValueError) listing the valid forms.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from agents.controllers import CONTROLLERS
from agents.pipeline import PIPELINE_NAME
from agents.training import META_FILE
from fricenv.envs.estimator_observation import ESTIMATOR_NAMES, NO_ESTIMATOR
from fricenv.errors import InvalidInputError

__all__ = [
    "ORACLE_CONTROLLERS",
    "PIPELINE_PREFIX",
    "PolicyKind",
    "PolicySpec",
    "PolicySpecError",
    "parse_policy_spec",
    "valid_forms",
]

PIPELINE_PREFIX = "pipeline:"
ORACLE_CONTROLLERS = ("oracle-slip", "slip-pi")  # controllers that read the true state (observation="oracle")
TRAINED_ENV = "braking"  # the env a policy spec drives
PIPELINE_ESTIMATORS = tuple(n for n in ESTIMATOR_NAMES if n != NO_ESTIMATOR)
PolicyKind = Literal["controller", "pipeline", "trained"]


class PolicySpecError(InvalidInputError):
    """A policy spec that is neither a controller, an estimator pipeline nor a braking training run directory."""


def valid_forms() -> str:
    """The valid spec forms, for error messages."""
    return (f"valid: {', '.join(CONTROLLERS)}, {PIPELINE_PREFIX}<estimator> (estimator one of "
            f"{', '.join(PIPELINE_ESTIMATORS)}), or a training run directory (with {META_FILE})")


@dataclass(frozen=True)
class PolicySpec:
    """A parsed policy spec.

    :param label: row label in tables (``rule-abs``, ``est+slip-pi[ekf]``, ``ppo[ekf-rls]``, ...).
    :param kind: ``controller``, ``pipeline`` or ``trained``.
    :param source: the spec string (a controller name, ``pipeline:EST`` or the run directory).
    :param estimator: estimator whose outputs the policy sees (``none`` for plain controllers).
    :param observation: the ``Braking-v0`` observation mode the policy needs (``oracle`` or ``default``).
    :param algo: SB3 algorithm of a trained run (None otherwise).
    :param env_kwargs: env arguments a trained run was trained with (empty otherwise).
    """

    label: str
    kind: PolicyKind
    source: str
    estimator: str = NO_ESTIMATOR
    observation: str = "default"
    algo: str | None = None
    env_kwargs: Mapping[str, Any] = field(default_factory=dict, hash=False)


def _trained(spec: str, meta_path: Path) -> PolicySpec:
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise PolicySpecError(f"{meta_path}: unreadable training metadata ({exc}); re-run fricenv train") from None
    env = meta.get("env", TRAINED_ENV)
    if env != TRAINED_ENV:
        raise PolicySpecError(f"{spec} is a {env} policy; only {TRAINED_ENV} policies run here")
    algo, estimator = meta.get("algo", "ppo"), meta.get("estimator", NO_ESTIMATOR)
    kwargs = dict(meta.get("env_kwargs") or {})
    stack = int(meta.get("frame_stack", 0) or 0)
    name = f"{algo}-stack{stack}" if stack else algo
    return PolicySpec(f"{name}[{estimator}]", "trained", spec, estimator=estimator,
                      observation=str(kwargs.get("observation", "default")), algo=algo, env_kwargs=kwargs)


def parse_policy_spec(spec: str) -> PolicySpec:
    """Parse a policy spec (module docstring).

    :param spec: a controller name, ``pipeline:<estimator>`` or a training run directory.
    :raises PolicySpecError: anything else, with the valid forms.
    """
    if not isinstance(spec, (str, Path)):
        raise PolicySpecError(f"a policy spec is a string, got {type(spec).__name__}; {valid_forms()}")
    spec = str(spec)
    if spec in CONTROLLERS:
        observation = "oracle" if spec in ORACLE_CONTROLLERS else "default"
        return PolicySpec(spec, "controller", spec, observation=observation)
    if spec.startswith(PIPELINE_PREFIX):
        est = spec[len(PIPELINE_PREFIX):]
        if est not in PIPELINE_ESTIMATORS:
            raise PolicySpecError(f"unknown pipeline estimator {est!r}; valid: {', '.join(PIPELINE_ESTIMATORS)}")
        return PolicySpec(f"{PIPELINE_NAME}[{est}]", "pipeline", spec, estimator=est)
    meta_path = Path(spec) / META_FILE
    if meta_path.is_file():
        return _trained(spec, meta_path)
    raise PolicySpecError(f"unknown policy {spec!r}; {valid_forms()}")
