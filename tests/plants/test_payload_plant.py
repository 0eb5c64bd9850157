"""Planar payload plant (Liu, Leung, Tang & Jia, eq. (1)) against solve_ivp, closed forms and the paper's data."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from estimators.scenarios import payload_log
from fricenv.logs import read_log, write_log
from fricenv.plants import payload as pl

P = pl.PAPER_PARAMS


def _reference(x0, wrench, t_eval):
    sol = solve_ivp(lambda t, y: pl.derivatives(y, wrench(t), P), (t_eval[0], t_eval[-1]), x0, method="DOP853",
                    rtol=1e-12, atol=1e-12, t_eval=t_eval)
    assert sol.success
    return sol.y.T


def test_multisine_matches_solve_ivp():
    traj = pl.simulate(10.0, dt=1e-3, noise=pl.NO_NOISE)
    ref = _reference(np.zeros(6), pl.paper_wrench, traj.t)
    assert np.max(np.abs(traj.state - ref)) < 1e-9


def test_integrator_is_fourth_order():
    x0 = np.array([0.3, 0.1, -0.2, 0.5, 0.2, -0.1])
    ref = _reference(x0, pl.paper_wrench, np.array([0.0, 5.0]))[-1]
    errs = [np.max(np.abs(pl.simulate(5.0, dt=h, noise=pl.NO_NOISE, state0=x0).state[-1] - ref))
            for h in (2e-2, 1e-2)]
    assert 12.0 < errs[0] / errs[1] < 20.0, errs  # 2^4 = 16


def test_zoh_step_matches_solve_ivp_batched():
    rng = np.random.default_rng(3)
    x0 = rng.normal(size=(4, 6))
    w = rng.uniform(-3, 3, size=(4, 3))
    states = pl.step(x0, w, 0.02, 20, P)
    assert states.shape == (4, 21, 6)
    for i in range(4):
        ref = _reference(x0[i], lambda t, wi=w[i]: wi, np.linspace(0.0, 0.02, 21))
        np.testing.assert_allclose(states[i], ref, atol=1e-13)


def test_closed_forms():
    # A pure moment spins the payload: theta = M t^2 / (2 I_G), the centre of mass stays put.
    states = pl.step(np.zeros(6), np.array([1.5, 0.0, 0.0]), 2.0, 200, P)
    t = np.linspace(0.0, 2.0, 201)
    np.testing.assert_allclose(states[:, 0], 1.5 * t**2 / (2 * P.I_G), rtol=1e-12)
    np.testing.assert_allclose(states[:, 1:3], 0.0, atol=1e-15)
    # No wrench: straight line at constant speed.
    x0 = np.array([0.2, 1.0, -1.0, 0.3, 0.4, -0.5])
    states = pl.step(x0, np.zeros(3), 1.0, 10, P)
    np.testing.assert_allclose(states[-1], [0.5, 1.4, -1.5, 0.3, 0.4, -0.5], rtol=1e-13)
    # Force through G is impossible here (rho != 0); a force whose moment is cancelled by M: no rotation,
    # X'' = f_x / m at theta = 0.
    w = np.array([P.rho_y * 2.0, 2.0, 0.0])
    states = pl.step(np.zeros(6), w, 1.0, 10, P)
    np.testing.assert_allclose(states[-1, [0, 3]], 0.0, atol=1e-14)
    np.testing.assert_allclose(states[-1, 1], 2.0 / P.m / 2, rtol=1e-12)


def test_accelerations_frame_reading():
    # Body-frame force rotated into the inertial frame: at theta = 90 deg a body-x force pushes along +Y.
    acc = pl.accelerations(np.pi / 2, np.array([0.0, 1.0, 0.0]), P)
    np.testing.assert_allclose(acc, [-P.rho_y / P.I_G, 0.0, 1.0 / P.m], atol=1e-15)


def test_sensor_and_calibration_error():
    w = pl.paper_wrench(np.linspace(0, 3, 7))
    w_hat = pl.sensor_reading(w, np.linalg.inv(pl.PAPER_S), pl.NO_NOISE, None)
    np.testing.assert_allclose(w_hat @ pl.PAPER_S.T, w, atol=1e-14)  # w = S w_hat, eq. (3)
    assert pl.calibration_error(pl.PAPER_S, pl.PAPER_S) == pytest.approx(0.0, abs=1e-15)
    assert pl.calibration_error(np.zeros((3, 3)), pl.PAPER_S) == pytest.approx(1.0)
    # The paper's S_hat at 100 s gives the order of its reported E = 9.1106e-4 (4-digit rounding of S_hat).
    S_hat = np.array([[0.6105, -0.0366, -0.1445], [-0.3358, 1.0017, -0.1443], [-0.1148, 0.1676, 0.9597]])
    assert 5e-4 < pl.calibration_error(S_hat, pl.PAPER_S) < 2e-3


def test_noise_levels_are_the_stated_ones():
    rng = np.random.default_rng(0)
    traj = pl.simulate(20.0, rng=rng)
    err = traj.pose - traj.state[:, :3]
    np.testing.assert_allclose(err.std(axis=0), [np.deg2rad(0.1), 1e-4, 1e-4], rtol=0.03)
    w_err = traj.w_hat - traj.w @ np.linalg.inv(pl.PAPER_S).T
    np.testing.assert_allclose(w_err.std(axis=0), 0.05 * pl.PAPER_WRENCH_AMPLITUDE, rtol=0.03)
    np.testing.assert_allclose(pl.PAPER_WRENCH_AMPLITUDE, [1.5, 1.5, 2.6])


def test_table1_schedule_and_random_s():
    sch = pl.table1_schedule()
    S = sch.at(np.array([50.0, 150.0, 250.0]))
    np.testing.assert_allclose(np.diagonal(S, axis1=1, axis2=2), pl.TABLE1_DIAGONALS)
    off = ~np.eye(3, dtype=bool)
    for k in range(3):
        np.testing.assert_allclose(S[k][off], pl.PAPER_S[off])
    assert sch.change_times == (100.0, 200.0)
    S1 = pl.random_calibration(np.random.default_rng(7))
    S2 = pl.random_calibration(np.random.default_rng(7))
    np.testing.assert_array_equal(S1, S2)
    assert np.all(np.abs(S1) <= 3.0) and np.linalg.cond(S1) <= 10.0


def test_log_round_trip(tmp_path):
    traj = pl.simulate(0.5, rng=np.random.default_rng(1))
    path = tmp_path / "payload.csv"
    write_log(path, payload_log(traj))
    log = read_log(path, plant="payload")
    np.testing.assert_allclose(log.X, traj.pose[:, 1], rtol=1e-9, atol=1e-12)


def test_bad_inputs_are_rejected():
    with pytest.raises(ValueError, match="m must be"):
        pl.PayloadParams(m=0.0)
    with pytest.raises(ValueError, match="integrator must be one of rk4, euler"):
        pl.simulate(1.0, noise=pl.NO_NOISE, integrator="rk45")
    with pytest.raises(ValueError, match="rng is required"):
        pl.simulate(1.0)
    with pytest.raises(ValueError, match="must start at 0"):
        pl.CalibrationSchedule((1.0,), (pl.PAPER_S,))
    with pytest.raises(ValueError, match="singular"):
        pl.constant_calibration(np.ones((3, 3)))
    with pytest.raises(ValueError, match="4N\\+1"):
        pl.integrate(np.zeros(6), np.zeros((6, 3)), 1e-3)
    with pytest.raises(ValueError, match="substeps"):
        pl.step(np.zeros(6), np.zeros(3), 0.02, 0)
    with pytest.raises(ValueError, match="wrench_rel"):
        pl.NoiseParams(wrench_rel=-1.0)
