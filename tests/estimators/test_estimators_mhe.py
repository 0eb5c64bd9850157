"""Regularized MHE (Sui & Johansen) and the shared augmented quarter-car model, on plant-generated logs."""

import numpy as np
import pytest

from estimators.base import EstimatorConfigError, Health, run
from estimators.mhe import RegularizedMHE
from estimators.quarter_car_model import AugmentedModel, magic_formula_casadi
from estimators.scenarios import mhe_case
from fricenv.logs import QuarterCarLog
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import DRY, ROADS, magic_formula

P = qc.PAPER_PARAMS


def test_casadi_magic_formula_equals_numpy():
    import casadi as ca

    rng = np.random.default_rng(0)
    lam = ca.SX.sym("lam")
    prm = ca.SX.sym("prm", 4)
    f = ca.Function("mf", [lam, prm], [magic_formula_casadi(lam, prm[0], prm[1], prm[2], prm[3])])
    sets = [r.as_array() for r in ROADS.values()] + [rng.uniform([9, 0, -7.5, 0], [15.5, 3, 2, 1]) for _ in range(20)]
    for B, C, E, theta in sets:
        for s in np.r_[np.linspace(-1, 1, 41), rng.uniform(0, 1, 10)]:
            assert float(f(s, [B, C, E, theta])) == pytest.approx(float(magic_formula(s, B, C, E, theta)),
                                                                   rel=1e-12, abs=1e-14)


@pytest.mark.parametrize("case", [1, 2])
def test_model_one_step_matches_plant(case):
    """The discrete model (ROS2 substeps) against the plant over the ABS operating range."""
    pc = mhe_case(case, seed=0)
    m = AugmentedModel(estimated=("theta", "B", "C", "E"))
    prm = [pc.road.theta, pc.road.B, pc.road.C, pc.road.E]
    err_v, err_s = [], []
    for k in range(len(pc.v) - 1):
        xn = m.f(np.r_[pc.v[k], pc.slip[k], prm], pc.log.T_b[k])
        err_v.append(xn[0] - pc.v[k + 1])
        err_s.append(xn[1] - pc.slip[k + 1])
    assert np.max(np.abs(err_v)) < 1e-3
    assert np.max(np.abs(err_s)) < 2e-3  # 3 substeps: <= 0.05 rad/s in omega, a ninth of the noise std


def test_model_jacobian_matches_finite_differences():
    m = AugmentedModel(estimated=("theta", "B", "C", "E"))
    x = np.array([15.0, 0.08, 0.9, 11.0, 1.5, 0.3])
    _, F = m.f_and_jacobian(x, 900.0)
    eps = 1e-6
    Ffd = np.column_stack([(m.f(x + eps * e, 900.0) - m.f(x - eps * e, 900.0)) / (2 * eps) for e in np.eye(6)])
    np.testing.assert_allclose(F, Ffd, rtol=1e-5, atol=1e-7)


def _rms(a, b, m):
    return float(np.sqrt(np.mean((a[m] - b[m]) ** 2)))


def test_mhe_case1_recovers_v_slip_theta():
    pc = mhe_case(1, seed=0)
    out = run(RegularizedMHE(estimated=pc.estimated), pc.log)
    m = pc.log.t >= 0.5
    assert _rms(out["v"], pc.v, m) < 0.12  # measured 0.091 (EKF 0.090)
    assert _rms(out["slip"], pc.slip, m) < 0.011  # measured 0.0087
    i05 = int(np.argmax(m))
    assert abs(out["theta"][i05] - 1.0) < 0.02  # paper target: theta within 0.02 on dry by 0.5 s
    assert abs(out["theta"][-1] - 1.0) < 0.03


def test_mhe_estimating_bce_helps_on_dry():
    """Paper, Section IV.B: estimating B, C, E too improves v and slip on dry (case 3 against case 1)."""
    errs = {}
    for case in (1, 3):
        pc = mhe_case(case, seed=0)
        out = run(RegularizedMHE(estimated=pc.estimated), pc.log)
        m = pc.log.t >= 0.5
        errs[case] = (_rms(out["v"], pc.v, m), _rms(out["slip"], pc.slip, m))
    assert errs[3][0] < errs[1][0]
    assert errs[3][1] < errs[1][1]


def _constant_torque_log(n=301, seed=0):
    """Constant brake torque from a settled slip: no excitation of the friction curve's shape."""
    rng = np.random.default_rng(seed)
    Tb = 0.5 * P.r * P.Fz
    v, w = np.array([20.0]), np.array([20.0 / P.r * 0.99])
    for _ in range(50):
        v, w = qc.step(v, w, np.array([Tb]), DRY.as_array(), 0.01, P, 10)
    V, W = [], []
    for _ in range(n):
        V.append(v[0])
        W.append(w[0])
        v, w = qc.step(v, w, np.array([Tb]), DRY.as_array(), 0.01, P, 10)
    V, W = np.array(V), np.array(W)
    log = QuarterCarLog(t=np.arange(n) * 0.01, T_b=np.full(n, Tb), omega=W + rng.normal(0, np.sqrt(0.2), n), v=V)
    return log, {"v": V[0], "slip": float(qc.slip(V[0], W[0]))}


def test_no_excitation_thresholding_keeps_bce_near_prior():
    log, start = _constant_torque_log()
    est = ("theta", "B", "C", "E")
    out = run(RegularizedMHE(estimated=est, arrival="paper", model_error=None), log, reset_kwargs=start)
    # the paper's MHE, scaled reading: held near the prior (B = 12, C = 1.3, E = 0) and flagged
    assert np.max(np.abs(out["B"] - 12.0)) < 0.6
    assert np.max(np.abs(out["C"] - 1.3)) < 0.25
    assert np.max(np.abs(out["E"])) < 0.8
    assert np.mean(out["health"] == Health.NOT_EXCITED) > 0.9
    # literal reading: with thresholding (delta = 0.8) B, C, E stay put; without it (delta = 0) they drift to
    # the bounds and the speed estimate is lost
    thr = run(RegularizedMHE(estimated=est, weighting="literal"), log, reset_kwargs=start)
    raw = run(RegularizedMHE(estimated=est, weighting="literal", delta=0.0), log, reset_kwargs=start)
    drift = lambda o: max(np.max(np.abs(o["B"] - 12)) / 6.5, np.max(np.abs(o["E"])) / 9.5)
    assert drift(thr) < 0.1
    assert drift(raw) > 0.4
    assert _rms(thr["v"], log.v, slice(None)) < 0.1 * _rms(raw["v"], log.v, slice(None))


def test_forced_solver_failure_falls_back_to_prior_and_flags():
    pc = mhe_case(1, seed=0)
    est = RegularizedMHE(estimated=pc.estimated, arrival="paper", model_error=None)  # the paper's MHE
    est.reset()
    for k in range(30):
        est.update(pc.log.omega[k], pc.log.T_b[k])
    good = est._fun

    def broken(*args):
        raise RuntimeError("forced failure")

    est._fun = broken
    # the prior start of the next window: the last solution's first state pushed one sample (eq. (11))
    prior0 = np.clip(est._f_est0, est.lower, est.upper)
    e = est.update(pc.log.omega[30], pc.log.T_b[30])
    assert e.health == Health.SOLVER_FAILED
    assert "forced failure" in e.info["reason"]
    np.testing.assert_allclose(est.x_prior0, prior0)
    # fallback value: the a priori trajectory's end, i.e. the prior propagated by the model over the window
    x = prior0
    for u in est._u[:est.N]:
        x = est.model.f(x, u)
    assert e["v"] == pytest.approx(x[0], rel=1e-9)
    assert e["theta"] == pytest.approx(x[2], rel=1e-9)
    est._fun = good
    _assert_recovers(est, pc, range(31, 60))


def _assert_recovers(est, pc, samples) -> None:
    """After a forced failure the estimator is back to OK / NOT_EXCITED and within 0.5 m/s of the true speed."""
    for k in samples:
        e = est.update(pc.log.omega[k], pc.log.T_b[k])
        assert e.health in (Health.OK, Health.NOT_EXCITED)
        assert abs(e["v"] - pc.v[k]) < 0.5


def test_mhe_bad_samples_flagged_not_raised():
    pc = mhe_case(2, seed=0)
    est = RegularizedMHE(estimated=pc.estimated)
    est.reset()
    for k in range(40):
        y = np.nan if k == 20 else pc.log.omega[k]
        u = [1.0, 2.0] if k == 25 else pc.log.T_b[k]
        e = est.update(y, u)
        assert (e.health == Health.INVALID_INPUT) == (k in (20, 25))  # exactly the bad samples
        assert np.isfinite(e["v"])


def test_mhe_config_errors():
    with pytest.raises(EstimatorConfigError, match="dt"):
        RegularizedMHE(dt=-0.01)
    with pytest.raises(EstimatorConfigError, match="weighting"):
        RegularizedMHE(weighting="exact")
    with pytest.raises(EstimatorConfigError, match="arrival"):
        RegularizedMHE(arrival="kalman")
    with pytest.raises(EstimatorConfigError, match="horizon"):
        RegularizedMHE(horizon=0)
    with pytest.raises(EstimatorConfigError, match="valid"):
        RegularizedMHE(estimated=("mu",))
    with pytest.raises(EstimatorConfigError, match="alpha"):
        RegularizedMHE(alpha=0.0)
    with pytest.raises(EstimatorConfigError, match="model_error"):
        RegularizedMHE(model_error="ekf")
    with pytest.raises(EstimatorConfigError, match="model_error"):
        RegularizedMHE(model_error=(0.01, -1.0))
    with pytest.raises(EstimatorConfigError, match="gate"):
        RegularizedMHE(gate=0.0)


def test_forced_solver_failure_default_mhe_flags_and_recovers():
    pc = mhe_case(1, seed=0)
    est = RegularizedMHE(estimated=pc.estimated)
    est.reset()
    for k in range(30):
        est.update(pc.log.omega[k], pc.log.T_b[k])
    good = est._fun
    est._fun = lambda *a: (_ for _ in ()).throw(RuntimeError("forced failure"))
    e = est.update(pc.log.omega[30], pc.log.T_b[30])
    assert e.health == Health.SOLVER_FAILED and "forced failure" in e.info["reason"]
    assert abs(e["v"] - pc.v[30]) < 0.5  # the a priori trajectory from the EKF arrival prior
    est._fun = good
    _assert_recovers(est, pc, range(31, 60))


def test_mhe_defaults_and_paper_option():
    """Default: EKF arrival cost and process noise with the EKF's Q (beyond the paper); the paper's MHE stays."""
    from estimators.ekf import DEFAULT_EKF_TUNING

    q = DEFAULT_EKF_TUNING["Q_std"]
    for est in (("theta",), ("theta", "B", "C", "E")):
        mhe = RegularizedMHE(estimated=est)
        assert mhe.arrival == "ekf"
        np.testing.assert_allclose(mhe.model_error, [q["v"], q["slip"]])
        paper = RegularizedMHE(estimated=est, arrival="paper", model_error=None)
        assert paper.model_error is None and paper._nz == paper.model.nx  # hard dynamics (12b)
    assert RegularizedMHE(weighting="literal").arrival == "paper"


def test_mhe_alongside_ekf_is_the_ekf():
    """With a gate of ~0 every solution is replaced by the alongside EKF's x(t|t) (as is the warm-up output): it
    must be QuarterCarEKF's."""
    from estimators.ekf import QuarterCarEKF

    pc = mhe_case(2, seed=1, duration=0.5)
    gated = run(RegularizedMHE(estimated=pc.estimated, gate=1e-12), pc.log)
    ekf = run(QuarterCarEKF(estimated=pc.estimated), pc.log)
    for key in ("v", "slip", "theta"):
        np.testing.assert_allclose(gated[key], ekf[key], rtol=1e-9, atol=1e-12)


def test_mhe_process_noise_case1_within_ekf():
    """Case 1 (B, C, E fixed at wrong nominal values), seed 0: the default MHE (process noise in the window, EKF
    arrival cost) is as accurate as the EKF; the paper's hard-dynamics MHE is not."""
    from estimators.ekf import QuarterCarEKF

    pc = mhe_case(1, seed=0)
    m = pc.log.t >= 0.5
    mhe = run(RegularizedMHE(estimated=pc.estimated), pc.log)
    ekf = run(QuarterCarEKF(estimated=pc.estimated), pc.log)
    paper = run(RegularizedMHE(estimated=pc.estimated, arrival="paper", model_error=None), pc.log)
    assert _rms(mhe["v"], pc.v, m) < 1.03 * _rms(ekf["v"], pc.v, m)  # measured 0.0914 vs 0.0898
    assert _rms(mhe["slip"], pc.slip, m) < _rms(ekf["slip"], pc.slip, m)  # measured 0.00873 vs 0.00889
    assert _rms(paper["v"], pc.v, m) > 1.3 * _rms(ekf["v"], pc.v, m)  # measured 0.151


def test_mhe_ekf_arrival_and_model_error_options_run():
    pc = mhe_case(1, seed=0, duration=0.6)
    for kw in ({"arrival": "ekf", "model_error": None, "gate": None}, {"model_error": (0.02, 0.005)}):
        out = run(RegularizedMHE(estimated=pc.estimated, **kw), pc.log)
        m = pc.log.t >= 0.3
        assert _rms(out["v"], pc.v, m) < 0.3
        assert abs(out["theta"][-1] - 1.0) < 0.05
    with pytest.raises(EstimatorConfigError, match="arrival='ekf'"):
        RegularizedMHE(arrival="paper", model_error=(0.01, 0.01))


@pytest.mark.slow
@pytest.mark.parametrize("case", [1, 2, 3, 4])
def test_mhe_paper_cases_no_worse_than_ekf(case):
    from estimators.ekf import QuarterCarEKF

    pc = mhe_case(case, seed=0)
    m = pc.log.t >= 0.5
    mhe = run(RegularizedMHE(estimated=pc.estimated), pc.log)
    ekf = run(QuarterCarEKF(estimated=pc.estimated), pc.log)
    assert _rms(mhe["slip"], pc.slip, m) < _rms(ekf["slip"], pc.slip, m)
    assert _rms(mhe["v"], pc.v, m) < 1.03 * _rms(ekf["v"], pc.v, m)
