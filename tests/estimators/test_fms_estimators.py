"""FMS calibration estimators (RLS and the paper's adaptive observer) on the payload plant; no RL side."""

import numpy as np
import pytest

from estimators.base import EstimatorConfigError, Health, run
from estimators.fms_observer import FmsObserver
from estimators.fms_rls import FmsRLS
from estimators.scenarios import payload_log
from fricenv.plants import payload as pl

S = pl.PAPER_S


def _E(est):
    return float(pl.calibration_error(est["S"], S))


@pytest.fixture(scope="module")
def clean_100s():
    return pl.simulate(100.0, noise=pl.NO_NOISE)


@pytest.fixture(scope="module")
def noisy_100s():
    return pl.simulate(100.0, rng=np.random.default_rng(0))


# ----------------------------------------------------------------------------------------------- RLS
def test_rls_noise_free_recovers_s(clean_100s):
    tr = clean_100s
    n20 = 20_000
    est = FmsRLS().update_block(tr.pose[:n20], tr.w_hat[:n20])
    assert est.health == Health.OK
    assert _E(est) <= 1e-4
    # a random well-conditioned S with entries in [-3, 3] (the paper's Fig. 3 set-up)
    S_rand = pl.random_calibration(np.random.default_rng(5))
    tr2 = pl.simulate(20.0, noise=pl.NO_NOISE, calibration=pl.constant_calibration(S_rand))
    est2 = FmsRLS(vision_std=(0.0, 0.0)).update_block(tr2.pose, tr2.w_hat)
    assert pl.calibration_error(est2["S"], S_rand) <= 1e-4


def test_rls_stated_noise_reaches_2e3_by_100s(noisy_100s):
    tr = noisy_100s
    rls = FmsRLS()
    for k in range(0, len(tr.t), 1000):
        est = rls.update_block(tr.pose[k:k + 1000], tr.w_hat[k:k + 1000])
    assert est.health == Health.OK
    assert _E(est) <= 2e-3


def test_rls_per_sample_equals_block():
    tr = pl.simulate(1.5, rng=np.random.default_rng(2))
    a, b = FmsRLS(), FmsRLS()
    for k in range(len(tr.t)):
        ea = a.update(tr.pose[k], tr.w_hat[k])
    eb = b.update_block(tr.pose, tr.w_hat)
    np.testing.assert_allclose(ea["S"], eb["S"], rtol=1e-7, atol=1e-9)  # rounding of the two filter paths


def test_rls_tracks_table1_steps():
    sch = pl.table1_schedule()
    tr = pl.simulate(300.0, calibration=sch, rng=np.random.default_rng(1))
    rls = FmsRLS(change_detection=True)
    E = []
    block = 100
    for k in range(0, len(tr.t) - 1, block):
        est = rls.update_block(tr.pose[k:k + block], tr.w_hat[k:k + block])
        E.append(pl.calibration_error(est["S"], tr.S[k + block - 1]))
    E = np.array(E)
    t = (np.arange(len(E)) + 1) * block * 1e-3
    assert len(rls.changes) == 2  # both steps detected, no false alarm
    for tc in (100.0, 200.0):
        assert E[(t > tc + 15.0) & (t < tc + 99.0)].max() < 1e-2
        assert E[(t > tc - 5.0) & (t < tc)].max() < 5e-3


def test_rls_flags_lack_of_excitation_and_near_singular_s():
    n = 3000
    pose = np.zeros((n, 3))
    zero = np.zeros((n, 3))
    est = FmsRLS().update_block(pose, zero)
    assert est.health == Health.NOT_EXCITED
    np.testing.assert_array_equal(est["S"], np.eye(3))  # held at the prior
    # readings that are pure sensor noise while nothing moves: no excitation above the noise, flagged
    noise = np.random.default_rng(0).normal(scale=0.1, size=(20_000, 3))
    est = FmsRLS(wrench_std=(0.1, 0.1, 0.1)).update_block(np.zeros((20_000, 3)), noise)
    assert est.health == Health.NOT_EXCITED
    assert "excitation" in est.info["reason"]
    # a (nearly) singular true calibration gives a near-singular S_hat: flagged, no crash
    S_sing = S.copy()
    S_sing[2] = S_sing[1] + 1e-5
    tr = pl.simulate(5.0, noise=pl.NO_NOISE, calibration=pl.constant_calibration(S_sing))
    est = FmsRLS().update_block(tr.pose, tr.w_hat)
    assert est.health == Health.NOT_EXCITED
    assert "near singular" in est.info["reason"]
    assert np.all(np.isfinite(est["S"]))


def test_rls_invalid_samples_are_skipped(clean_100s):
    tr = clean_100s
    rls = FmsRLS()
    rls.update_block(tr.pose[:5000], tr.w_hat[:5000])
    assert rls.update([np.nan, 0, 0], tr.w_hat[5000]).health == Health.INVALID_INPUT
    assert rls.update([0, 0], [0, 0, 0]).health == Health.INVALID_INPUT
    pose = tr.pose[5001:20_000].copy()
    pose[100] = np.nan
    est = rls.update_block(pose, tr.w_hat[5001:20_000])
    assert est.health == Health.INVALID_INPUT
    est = rls.update_block(tr.pose[20_000:21_000], tr.w_hat[20_000:21_000])
    assert est.health == Health.OK and _E(est) < 1e-4


def test_rls_config_errors():
    with pytest.raises(EstimatorConfigError, match="dt"):
        FmsRLS(dt=0.0)
    with pytest.raises(EstimatorConfigError, match="filter_order"):
        FmsRLS(filter_order=2)
    with pytest.raises(EstimatorConfigError, match="point, zoh"):
        FmsRLS(wrench_hold="linear")
    with pytest.raises(EstimatorConfigError, match="cutoff_hz"):
        FmsRLS(cutoff_hz=600.0)
    with pytest.raises(EstimatorConfigError, match="forgetting_time"):
        FmsRLS(forgetting_time=-1.0)
    with pytest.raises(EstimatorConfigError, match="S0"):
        FmsRLS().reset(S0=np.eye(2))
    with pytest.raises(TypeError):
        FmsRLS(bogus=1)


def test_run_over_a_payload_log():
    tr = pl.simulate(2.0, noise=pl.NO_NOISE)
    out = run(FmsRLS(), payload_log(tr))
    assert out["S"].shape == (len(tr.t), 3, 3)
    assert pl.calibration_error(out["S"][-1], S) < 1e-2


# ------------------------------------------------------------------------------------------ observer
def test_observer_noise_free_converges_below_1e2(clean_100s):
    tr = clean_100s
    for reading in ("paper", "corrected"):
        obs = FmsObserver(seed=0, reading=reading)
        E = [_E(obs.update_block(tr.pose[k:k + 1000], tr.w_hat[k:k + 1000])) for k in range(0, 100_000, 1000)]
        assert E[0] > 0.5  # it starts far off (initial S_hat drawn in [0, 3])
        # below 1e-2 over the last 40 s, fluctuating about its floor (see test_observer_floor_is_its_euler_step)
        assert np.median(E[60:]) < 1e-2 and max(E[60:]) < 2e-2, reading


def test_observer_floor_is_its_euler_step():
    # Against an Euler-integrated plant (the observer's own discretisation) the paper reading converges to ~1e-11;
    # against the accurate plant it stalls at an O(dt) floor (about 5e-3 at 1 ms, 1.4e-3 at 0.25 ms).
    euler = pl.simulate(100.0, noise=pl.NO_NOISE, integrator="euler")
    assert _E(FmsObserver(seed=0).update_block(euler.pose, euler.w_hat)) < 1e-8
    floors = []
    for dt in (1e-3, 5e-4):
        tr = pl.simulate(100.0, dt=dt, noise=pl.NO_NOISE)
        floors.append(_E(FmsObserver(dt=dt, seed=0).update_block(tr.pose, tr.w_hat)))
    assert 1e-3 < floors[0] < 1e-2
    assert 1.6 < floors[0] / floors[1] < 2.5  # first order in dt


def test_observer_stalls_at_stated_noise(noisy_100s):
    # The known trap: the backward differences of eq. (15) amplify the vision noise; E stays far above 1e-2.
    tr = noisy_100s
    assert _E(FmsObserver(seed=0).update_block(tr.pose, tr.w_hat)) > 0.05


def test_observer_per_sample_equals_block():
    tr = pl.simulate(0.5, noise=pl.NO_NOISE)
    a, b = FmsObserver(seed=1), FmsObserver(seed=1)
    for k in range(len(tr.t)):
        ea = a.update(tr.pose[k], tr.w_hat[k])
    np.testing.assert_allclose(ea["S"], b.update_block(tr.pose, tr.w_hat)["S"], rtol=1e-12)


def test_observer_initial_guess_and_flags():
    obs = FmsObserver(seed=3)
    S0 = obs.S
    assert np.all((S0 >= 0) & (S0 <= 3))
    singular = FmsObserver(seed=0)
    singular.reset(S0=np.zeros((3, 3)))
    est = singular.update_block(np.zeros((10, 3)), np.zeros((10, 3)))
    assert est.health == Health.NOT_EXCITED and "near singular" in est.info["reason"]
    assert obs.update([np.nan, 0, 0], [0, 0, 0]).health == Health.INVALID_INPUT
    # a divergent gain does not crash: the observer restarts and says so
    wild = FmsObserver(seed=0, delta=1e9)
    tr = pl.simulate(2.0, noise=pl.NO_NOISE)
    est = wild.update_block(tr.pose, tr.w_hat)
    assert est.health == Health.SOLVER_FAILED
    assert np.all(np.isfinite(est["S"]))


def test_observer_config_errors():
    with pytest.raises(EstimatorConfigError, match="paper, corrected"):
        FmsObserver(reading="literal")
    with pytest.raises(EstimatorConfigError, match="K2"):
        FmsObserver(K2=np.zeros((2, 4)))
    with pytest.raises(EstimatorConfigError, match="delta"):
        FmsObserver(delta=-1.0)


@pytest.mark.slow
def test_rls_stated_noise_median_over_seeds_meets_targets():
    # the paper's targets: median over seeds E <= 5e-3 at 20 s and <= 1e-3 at 100 s (measured: 2.3e-3 and 8.6e-4)
    e20, e100 = [], []
    for seed in range(5):
        tr = pl.simulate(100.0, rng=np.random.default_rng(seed))
        rls = FmsRLS()
        e20.append(_E(rls.update_block(tr.pose[:20_000], tr.w_hat[:20_000])))
        e100.append(_E(rls.update_block(tr.pose[20_000:100_000], tr.w_hat[20_000:100_000])))
    assert np.median(e20) <= 5e-3
    assert np.median(e100) <= 1e-3
