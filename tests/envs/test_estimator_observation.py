"""EstimatorObservation wrapper, env factories and the estimator + slip-controller pipeline."""

from __future__ import annotations

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from agents.controllers import RuleBasedABS, rollout, slip_reference
from agents.pipeline import EstimatorSlipPipeline, control_spec
from estimators.base import Estimate, Estimator, Health
from fricenv.envs import BRAKING_VARIANTS, ENV_IDS
from fricenv.envs.estimator_observation import (
    ESTIMATOR_NAMES,
    EstimatorObservation,
    PayloadEstimatorObservation,
)
from fricenv.envs.factory import make_braking, make_payload
from fricenv.plants.tire import DRY

WRAPPED = ("ekf", "mhe", "ekf-rls", "oracle")
APPENDED = ("v_hat", "slip_hat", "mu_hat", "theta_hat", "health")
# estimators that also report the friction peak's slip (the EKF/RLS curve-shape fit, the oracle's truth)
WITH_PEAK_SLIP = {"ekf-rls", "oracle"}


def _quiet_check(env):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "the env is wrapped" notice of the gymnasium checker
        gym_check_env(env, skip_render_check=True)
        sb3_check_env(env, warn=False)


@pytest.mark.parametrize("estimator", WRAPPED)
def test_wrapped_env_passes_both_checkers(estimator):
    env = make_braking(estimator)
    assert isinstance(env, EstimatorObservation)
    _quiet_check(env)
    names = env.observation_names
    assert names[:4] == ("wheel_speed", "wheel_decel", "torque", "a_x")
    # every registered estimator gives v, slip, mu and theta; peak_slip_hat only where the estimator reports it
    expected = APPENDED[:4] + (("peak_slip_hat",) if estimator in WITH_PEAK_SLIP else ()) + APPENDED[4:]
    assert names[4:] == expected
    assert env.observation_space.dtype == np.float32
    assert np.all(np.isfinite(env.observation_space.low)) and np.all(np.isfinite(env.observation_space.high))


def test_none_is_the_plain_env_and_unknown_estimator_lists_choices():
    assert not isinstance(make_braking("none"), gym.Wrapper)
    with pytest.raises(ValueError, match="ekf-rls") as err:
        make_braking("kalman")
    for name in ESTIMATOR_NAMES:
        assert name in str(err.value)
    with pytest.raises(ValueError, match="appends nothing"):
        EstimatorObservation(make_braking("none"), "none")
    with pytest.raises(TypeError):
        make_braking("ekf", not_an_option=1)


def test_registered_variants_make_through_gymnasium():
    assert set(BRAKING_VARIANTS) <= set(ENV_IDS)
    env = gym.make("fricenv/BrakingEKFRLS-v0", road="wet")
    obs, info = env.reset(seed=1)
    assert obs.shape == (10,) and env.observation_space.contains(obs)
    assert info["road"] == "wet" and set(info["estimate"]) == {"v_hat", "slip_hat", "mu_hat", "theta_hat",
                                                              "peak_slip_hat", "health"}


def test_factory_as_braking_entry_point_takes_estimator_kwarg():
    """What ``fricenv/Braking-v0`` does once its entry point is ``fricenv.envs.factory:make_braking``."""
    from gymnasium.envs.registration import register, registry

    env_id = "fricenv-h5-test/Braking-v0"
    if env_id not in registry:
        register(id=env_id, entry_point="fricenv.envs.factory:make_braking")
    plain = gym.make(env_id)
    assert plain.observation_space.shape == (4,)
    env = gym.make(env_id, estimator="ekf", road="ice", render_mode="rgb_array")
    assert env.observation_space.shape == (9,)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert env.render().ndim == 3
    with pytest.raises(ValueError, match="oracle"):
        gym.make(env_id, estimator="particle-filter")


def test_oracle_appends_the_truth():
    env = make_braking("oracle", road="dry->ice", change_distance=5.0)
    ctl = RuleBasedABS(control_spec(env))
    obs, info = env.reset(seed=0)
    ctl.reset()
    for _ in range(150):
        obs, _, term, trunc, info = env.step(ctl.act(obs))
        d = env.decode_observation(obs)
        assert d["v_hat"] == pytest.approx(info["v"], rel=1e-6)
        assert d["slip_hat"] == pytest.approx(info["slip"], abs=1e-6)
        assert d["mu_hat"] == pytest.approx(info["mu"], abs=1e-6)
        assert d["health"] == 0.0
        if term or trunc:
            break
    assert d["theta_hat"] == pytest.approx(0.1, abs=1e-7)  # on ice after the change at 5 m


def test_ekf_rls_speed_estimate_is_accurate_under_abs():
    """The EKF/RLS speed filter, advanced by the measured a_x, tracks the true speed on dry asphalt: the error is
    the offset of its start from one noisy wheel-speed sample (std sqrt(0.2) r = 0.15 m/s), nearly constant."""
    env = make_braking("ekf-rls", road="dry")
    ctl = RuleBasedABS(control_spec(env))
    obs, info = env.reset(seed=3)
    ctl.reset()
    err = []
    while True:
        obs, _, term, trunc, info = env.step(ctl.act(obs))
        err.append(env.decode_observation(obs)["v_hat"] - info["v"])
        if term or trunc:
            break
    assert info["stopped"]
    err = np.array(err[50:])
    assert abs(err.mean()) < 3 * np.sqrt(0.2) * 0.345
    assert err.std() < 0.05


def test_same_seed_same_augmented_trajectory_and_pickle_round_trip():
    def trace(env, seed, n=80):
        ctl = RuleBasedABS(control_spec(env))
        obs, _ = env.reset(seed=seed)
        ctl.reset()
        out = [obs]
        for _ in range(n):
            obs, *_ = env.step(ctl.act(obs))
            out.append(obs)
        return np.array(out)

    env = make_braking("ekf", road="wet")
    a, b = trace(env, 7), trace(env, 7)
    np.testing.assert_array_equal(a, b)
    clone = pickle.loads(pickle.dumps(env))
    np.testing.assert_array_equal(trace(clone, 7), a)
    assert not np.array_equal(trace(env, 8), a)


class _Exploding(Estimator):
    measurement_columns = ("omega",)
    input_columns = ("T_b",)
    names = ("v", "slip", "mu", "theta")

    def __init__(self, fail_after: int):
        self.fail_after = fail_after

    def reset(self, v: float = 20.0, slip: float = 0.0) -> Estimate:
        self.k = 0
        return Estimate({"v": v, "slip": slip, "mu": 0.0, "theta": 0.5})

    def update(self, measurement, u) -> Estimate:
        self.k += 1
        if self.k > self.fail_after:
            raise np.linalg.LinAlgError("singular matrix")
        if self.k == self.fail_after:
            return Estimate({"v": np.nan, "slip": 0.0, "mu": 0.0, "theta": 0.5})
        return Estimate({"v": 19.0, "slip": 0.1, "mu": 0.5, "theta": 0.5}, Health.NOT_EXCITED)


def test_failing_estimator_never_raises_and_flags_health():
    env = EstimatorObservation(make_braking("none"), "exploding", estimator_factory=lambda dt, p: _Exploding(3))
    obs, _ = env.reset(seed=0)
    obs, *_ = env.step(np.array([-1.0], dtype=np.float32))
    d = env.decode_observation(obs)
    assert d["health"] == Health.NOT_EXCITED and d["slip_hat"] == pytest.approx(0.1)
    obs, *_ = env.step(np.array([-1.0], dtype=np.float32))
    with pytest.warns(RuntimeWarning, match="holding its last values"):
        obs, *_ = env.step(np.array([-1.0], dtype=np.float32))  # NaN estimate
    d = env.decode_observation(obs)
    assert d["health"] == Health.SOLVER_FAILED and d["slip_hat"] == pytest.approx(0.1)
    obs, _, _, _, info = env.step(np.array([-1.0], dtype=np.float32))  # raises inside: no new warning, held
    assert info["estimate"]["health"] == Health.SOLVER_FAILED
    assert env.observation_space.contains(obs)


def test_estimator_needing_unmeasured_columns_is_rejected():
    class NeedsVision(_Exploding):
        measurement_columns = ("omega", "X")

    with pytest.raises(ValueError, match="X"):
        EstimatorObservation(make_braking("none"), "vision", estimator_factory=lambda dt, p: NeedsVision(5))


@pytest.mark.parametrize("estimator", ("none", "rls", "oracle"))
def test_payload_factory_passes_both_checkers(estimator):
    env = make_payload(estimator)
    _quiet_check(env)
    n = {"none": 12, "rls": 22, "oracle": 21}[estimator]
    assert env.observation_space.shape == (n,)
    if estimator == "oracle":
        assert isinstance(env, PayloadEstimatorObservation)
        obs, _ = env.reset(seed=2, options={"calibration": "random"})
        np.testing.assert_allclose(obs[12:], env.unwrapped.S.reshape(9), rtol=1e-6)
    with pytest.raises(ValueError, match="rls"):
        make_payload("ekf")


def test_pipeline_with_oracle_tracks_the_true_peak():
    env = make_braking("oracle", road="dry")
    ctl = EstimatorSlipPipeline(env)
    ro = rollout(env, ctl, seed=0)
    assert ctl.source.lambda_ref == pytest.approx(slip_reference(DRY)[0], abs=2e-4)  # shape rounded to 1e-3
    assert not ro.info["lock_seen"]
    assert ro.info["ratio"] < 1.03


def test_pipeline_reference_comes_from_the_estimated_curve():
    """A theta-only EKF keeps eq. (18)'s shape: its peak, 0.2197, is the reference whatever theta it estimates."""
    env = make_braking("ekf", road="dry")
    ctl = EstimatorSlipPipeline(env)
    ro = rollout(env, ctl, seed=0)
    assert ctl.source.lambda_ref == pytest.approx(0.2197, abs=5e-4)
    assert ro.info["stopped"] and not ro.info["lock_seen"]
    # 1.078 measured: the env EKF's brake-gain state (robust to brake lag and gain) leaves the slip less pinned by
    # the torque than the paper's model did (1.05 or less)
    assert ro.info["ratio"] < 1.10
    with pytest.raises(ValueError, match="make_braking"):
        EstimatorSlipPipeline(make_braking("none"))


def test_ekf_ax_is_fed_the_torque_and_the_acceleration_measured_over_the_step():
    """``ekf-ax`` integrates the acceleration measured over each step (the a_x of the observation after it) with the
    torque held over it, started from one free-rolling wheel sample and its spread: the appended speed equals the
    estimator run on those columns, and it tracks the car under a 60 ms brake delay (dry, rule ABS, seed 0) to 0.2
    m/s rms after the first half second (0.13 measured; the speed keeps its start's error, 0.02 m/s here)."""
    from estimators.registry import make_estimator

    env = make_braking("ekf-ax", road="dry", effects=[{"effect": "brake_delay", "params": {"delay": 0.06}}])
    assert env.estimator.input_columns == ("T_b", "a_x")
    ctl = RuleBasedABS(control_spec(env))
    obs, info = env.reset(seed=0)
    ctl.reset()
    ref = make_estimator("ekf-ax", env.unwrapped.config.params, env.unwrapped.config.dt)
    cfg = env.unwrapped.config
    ref.reset(v=env.decode_observation(obs)["wheel_speed"] * cfg.params.r, slip=0.0,
              v_std=np.sqrt(cfg.omega_noise_var) * cfg.params.r)  # the env's start: one free-rolling wheel sample
    dt, got, want, err = env.unwrapped.config.dt, [], [], []
    while True:
        before = env.decode_observation(obs)
        obs, _, term, trunc, info = env.step(ctl.act(obs))
        after = env.decode_observation(obs)
        est = ref.update([before["wheel_speed"]], [info["torque"], after["a_x"]])
        want.append(est["v"] + dt * after["a_x"])
        got.append(info["estimate"]["v_hat"])
        err.append(got[-1] - info["v"])
        if term or trunc:
            break
    assert info["stopped"]
    np.testing.assert_allclose(got, want, rtol=1e-12)
    assert np.sqrt(np.mean(np.square(err[50:]))) < 0.2
