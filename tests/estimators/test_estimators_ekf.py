"""EKF: exact Kalman filter on a linear model, the quarter-car augmented EKF on plant-generated logs, bad input."""

import numpy as np
import pytest

from estimators.base import EstimatorConfigError, Health, run
from estimators.ekf import ExtendedKalmanFilter, QuarterCarEKF, ekf_update
from estimators.scenarios import mhe_case
from fricenv.plants.quarter_car import PAPER_PARAMS
from fricenv.plants.sui_johansen import OMEGA_NOISE_VAR


def _exact_kf(A, Bu, C, Q, R, x0, P0, us, ys):
    """Textbook Kalman filter with explicit inverses (the reference)."""
    x, P, out = x0.copy(), P0.copy(), []
    for u, y in zip(us, ys):
        S = C @ P @ C.T + R
        K = P @ C.T @ np.linalg.inv(S)
        x = x + K @ (y - C @ x)
        P = (np.eye(len(x)) - K @ C) @ P
        out.append((x.copy(), P.copy()))
        x = A @ x + Bu @ u
        P = A @ P @ A.T + Q
    return out


def test_ekf_on_linear_model_equals_exact_kalman_filter():
    rng = np.random.default_rng(1)
    n, m, T = 4, 2, 60
    A = np.eye(n) + 0.1 * rng.normal(size=(n, n))
    Bu = rng.normal(size=(n, 1))
    C = rng.normal(size=(m, n))
    Q = 0.01 * np.eye(n)
    R = np.diag([0.2, 0.5])
    x0, P0 = np.zeros(n), np.eye(n)
    us = rng.normal(size=(T, 1))
    ys = rng.normal(size=(T, m))
    ekf = ExtendedKalmanFilter(lambda x, u: (A @ x + Bu @ np.atleast_1d(u), A), lambda x: (C @ x, C), Q, R)
    ref = _exact_kf(A, Bu, C, Q, R, x0, P0, us, ys)
    x, P = x0, P0
    for k in range(T):
        x, P, _ = ekf.update(x, P, ys[k])
        np.testing.assert_allclose(x, ref[k][0], rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(P, ref[k][1], rtol=1e-8, atol=1e-10)
        assert np.allclose(P, P.T, atol=0)  # symmetrized
        x, P = ekf.predict(x, P, us[k])


def test_joseph_update_keeps_covariance_positive_with_tiny_noise():
    P = np.diag([1e6, 1e-6])
    H = np.array([[1.0, 1.0]])
    _, Pp, _ = ekf_update(np.zeros(2), P, np.array([1.0]), np.array([0.0]), H, np.array([[1e-9]]))
    assert np.all(np.linalg.eigvalsh(Pp) >= -1e-12)


@pytest.mark.parametrize("case", [1, 2])
def test_quarter_car_ekf_recovers_speed_slip_theta(case):
    pc = mhe_case(case, seed=0)
    out = run(QuarterCarEKF(estimated=pc.estimated), pc.log)
    m = pc.log.t >= 0.5
    rms_v = np.sqrt(np.mean((out["v"][m] - pc.v[m]) ** 2))
    rms_s = np.sqrt(np.mean((out["slip"][m] - pc.slip[m]) ** 2))
    assert rms_v < 0.15, rms_v  # measured 0.09 / 0.08
    assert rms_s < 0.012, rms_s  # measured 0.009 / 0.007
    assert abs(out["theta"][-1] - pc.road.theta) < 0.02  # from the prior 0.6
    # ABS cycles excite theta: NOT_EXCITED (the MHE's rule) on at most a few samples, and nothing is an outlier
    assert np.all(np.isin(out["health"], (Health.OK, Health.NOT_EXCITED)))
    assert np.mean(out["health"] == Health.OK) > 0.97


@pytest.mark.parametrize("estimated", [("theta",), ("theta", "B", "C", "E")])
def test_ekf_not_excited_when_free_rolling(estimated):
    """No torque, no slip: the data say nothing about the friction curve (mu(0) = 0 whatever theta), so the EKF
    says NOT_EXCITED like the MHE and the EKF/RLS, and keeps theta at its prior. (With the paper's full wheel-speed
    noise the noise itself makes a slip that the EKF, the MHE and the EKF/RLS all read as partial excitation.)"""
    rng = np.random.default_rng(3)
    n = 150
    omega = 20.0 / PAPER_PARAMS.r + 0.1 * rng.normal(0.0, np.sqrt(OMEGA_NOISE_VAR), n)
    log = {"t": np.arange(n) * 0.01, "omega": omega, "T_b": np.zeros(n)}
    out = run(QuarterCarEKF(estimated=estimated), log)
    assert np.all(out["health"][1:] == Health.NOT_EXCITED)
    assert abs(out["theta"][-1] - 0.6) < 2e-3
    assert abs(out["v"][-1] - 20.0) < 0.05


def test_ekf_bad_samples_flagged_not_raised():
    ekf = QuarterCarEKF()
    before = ekf.update(57.0, 500.0)
    for bad in [(np.nan, 500.0), (57.0, np.inf), ([57.0, 1.0], 500.0), (57.0, [1.0, 2.0])]:
        est = ekf.update(*bad)
        assert est.health == Health.INVALID_INPUT
    assert np.isfinite(ekf.update(57.0, 500.0)["v"])
    assert before.health == Health.NOT_EXCITED  # one sample says little about theta (the MHE rule, delta 0.1)


def test_ekf_config_errors():
    with pytest.raises(EstimatorConfigError, match="dt"):
        QuarterCarEKF(dt=-0.01)
    with pytest.raises(EstimatorConfigError, match="valid"):
        QuarterCarEKF(estimated=("theta", "D"))
    with pytest.raises(EstimatorConfigError, match="Q_std"):
        QuarterCarEKF(Q_std={"zeta": 1.0})
