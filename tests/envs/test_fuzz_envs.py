"""Fuzz the env action checks through gymnasium.make: any action of any shape, dtype or value gives a step result
(observation in the observation space, finite reward) or a one-line ValueError/TypeError about the action; after a
rejected action the env still steps."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import fricenv  # noqa: F401  (registers the envs)

ENV_IDS = ("fricenv/Braking-v0", "fricenv/PayloadExcitation-v0")
FUZZ = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
_ENVS: dict = {}

NUMERIC_DTYPES = [np.float16, np.float32, np.float64, np.longdouble, np.int8, np.int16, np.int32, np.int64,
                  np.uint8, np.uint16, np.uint32, np.uint64]
OTHER_DTYPES = [np.bool_, np.complex64, np.complex128]


def _env(env_id: str):
    """One env per id for the whole module (reset when needed)."""
    if env_id not in _ENVS:
        env = gym.make(env_id)
        env.reset(seed=0)
        _ENVS[env_id] = env
    return _ENVS[env_id]


def _arrays(shape_strategy, dtypes):
    return st.sampled_from(dtypes).flatmap(lambda dt: hnp.arrays(np.dtype(dt), shape_strategy))


# every kind of action a user or a wrapper might pass
ACTIONS = st.one_of(
    _arrays(hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=4), NUMERIC_DTYPES + OTHER_DTYPES),
    _arrays(st.sampled_from([(1,), (3,)]), NUMERIC_DTYPES),  # the right shapes, any value (NaN, inf, huge)
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-10**30, 10**30),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=4),
    st.lists(st.one_of(st.floats(), st.text(max_size=3), st.none()), min_size=1, max_size=3),
    st.none(),
    st.text(max_size=5),
    st.dictionaries(st.text(max_size=2), st.floats(), max_size=2),
)


def _check_step(env, action) -> None:
    """Step with ``action``: a valid result, or a clear error naming the action and a usable env after it."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # passive checker notes (e.g. dtype of a rejected action) are fine
            obs, reward, terminated, truncated, info = env.step(action)
    except (ValueError, TypeError) as exc:
        msg = str(exc)
        assert "action" in msg and "\n" not in msg, f"unclear error for {action!r}: {type(exc).__name__}: {msg}"
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())  # still usable
    assert env.observation_space.contains(obs), f"observation out of its space after {action!r}: {obs!r}"
    assert isinstance(reward, float) and np.isfinite(reward)
    assert isinstance(terminated, bool) and isinstance(truncated, bool) and isinstance(info, dict)
    if terminated or truncated:
        env.reset()


@pytest.mark.parametrize("env_id", ENV_IDS)
@FUZZ
@given(action=ACTIONS)
def test_any_action_gives_a_result_or_a_clear_error(env_id, action):
    env = _env(env_id)
    env.action_space.seed(0)
    _check_step(env, action)


@pytest.mark.parametrize("env_id", ENV_IDS)
@FUZZ
@given(data=st.data())
def test_in_shape_finite_actions_of_any_numeric_dtype_are_clipped_not_rejected(env_id, data):
    env = _env(env_id)
    shape = env.action_space.shape
    dtype = data.draw(st.sampled_from(NUMERIC_DTYPES), label="dtype")
    action = data.draw(hnp.arrays(np.dtype(dtype), shape, elements=hnp.from_dtype(
        np.dtype(dtype), allow_nan=False, allow_infinity=False)), label="action")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        obs, reward, terminated, truncated, _ = env.step(action)
    assert env.observation_space.contains(obs) and np.isfinite(reward)
    if terminated or truncated:
        env.reset()


@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("action", [pytest.param([[0.1], [0.2, 0.3]], id="ragged"),
                                    pytest.param([0.1, [0.2]], id="nested-mixed"),
                                    pytest.param(np.array([1.0], dtype=object), id="object-array")])
def test_ragged_and_object_actions_are_rejected_with_a_message_about_the_action(env_id, action):
    env = _env(env_id)
    with pytest.raises((ValueError, TypeError), match="action"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env.step(action)
