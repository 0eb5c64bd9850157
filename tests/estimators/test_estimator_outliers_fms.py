"""The force-reading gate of the FMS observer and the FMS RLS calibrator (estimators.outliers.SignalGate)."""

import numpy as np
import pytest

from estimators.base import EstimatorConfigError, Health
from estimators.fms_observer import FmsObserver
from estimators.fms_rls import FmsRLS
from estimators.outliers import FMS_GATE, GateParams, SignalGate, Verdict, wrench_gate
from fricenv.plants import payload as pl

BLOCK = 50  # samples per update_block call, as `fricenv paper fms` does
SPIKES = np.array([3000, 7777, 12345, 15000])


@pytest.fixture(scope="module")
def run20():
    return pl.simulate(20.0, rng=np.random.default_rng(2))


def _feed(est, tr, W):
    health = []
    for i in range(0, len(tr.t), BLOCK):
        e = est.update_block(tr.pose[i:i + BLOCK], W[i:i + BLOCK])
        health.append(e.health)
    return float(pl.calibration_error(e["S"], pl.PAPER_S)), np.array(health)


def _alpha_beta_predictions(gate_: SignalGate, Z: np.ndarray) -> np.ndarray:
    """The tracker written out: x = z0, v = 0; pred = x + v; x = pred + alpha e; v = v + beta e."""
    alpha = 1.0 - gate_.a[2]
    beta = gate_.a[1] + 2.0 - alpha
    x, v = Z[0].copy(), np.zeros(Z.shape[1])
    preds = [Z[0].copy()]
    for z in Z[1:]:
        pred = x + v
        preds.append(pred)
        e = z - pred
        x, v = pred + alpha * e, v + beta * e
    return np.array(preds)


def test_rejected_reading_is_replaced_by_the_trackers_prediction(run20):
    W = run20.w_hat[:4000].copy()
    W[2500] *= 50.0
    g = wrench_gate(1e-3, pl.PAPER_NOISE.wrench_std)
    used, verdicts = g(W)
    assert list(np.flatnonzero(verdicts)) == [2500] and verdicts[2500] == Verdict.REJECT
    pred = _alpha_beta_predictions(g, run20.w_hat[:2501])[2500]
    np.testing.assert_allclose(used[2500], pred, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(np.delete(used, 2500, axis=0), np.delete(W, 2500, axis=0))


def test_blocks_and_one_call_give_the_same_verdicts(run20):
    W = run20.w_hat.copy()
    W[SPIKES] *= 20.0
    one, v_one = wrench_gate(1e-3, pl.PAPER_NOISE.wrench_std)(W)
    g = wrench_gate(1e-3, pl.PAPER_NOISE.wrench_std)
    parts = [g(W[i:i + BLOCK]) for i in range(0, len(W), BLOCK)]
    np.testing.assert_array_equal(np.concatenate([p[1] for p in parts]), v_one)
    np.testing.assert_allclose(np.concatenate([p[0] for p in parts]), one, rtol=0, atol=1e-9)
    assert list(np.flatnonzero(v_one)) == list(SPIKES)


def test_a_step_of_the_reading_is_kept(run20):
    """A real step (a PRBS wrench, a calibration change) is confirmed by the next sample and restarts the tracker:
    nothing is marked in a block; sample by sample, only the step's first sample is held back."""
    W = run20.w_hat[:6000].copy()
    W[4500:] *= 2.0  # at t = 4.5 s the reading is large (M 1.7 N m): the step is far outside the gate
    used, verdicts = wrench_gate(1e-3, pl.PAPER_NOISE.wrench_std)(W)
    # (later, the doubled sensor noise exceeds the stated one now and then: only the first 0.2 s are checked)
    assert not verdicts[:4700].any()
    np.testing.assert_array_equal(used[:4700], W[:4700])
    g = wrench_gate(1e-3, pl.PAPER_NOISE.wrench_std)
    one_by_one = np.concatenate([g(W[k:k + 1])[1] for k in range(4700)])
    assert list(np.flatnonzero(one_by_one)) == [4500]


def test_a_burst_of_wild_readings_reinitialises_after_max_rejections(run20):
    W = run20.w_hat[:6000].copy()
    W[4500:4530] = np.random.default_rng(3).normal(scale=50.0, size=(30, 3))  # garbage, no two alike
    _, verdicts = wrench_gate(1e-3, pl.PAPER_NOISE.wrench_std)(W)
    k = FMS_GATE.max_rejections
    assert np.all(verdicts[4500:4500 + k] == Verdict.REJECT) and verdicts[4500 + k] == Verdict.REINIT
    assert not verdicts[:4500].any()


@pytest.mark.parametrize("make, factor", [(lambda g: FmsObserver(seed=1, outlier_gate=g), 1000.0),
                                          (lambda g: FmsRLS(outlier_gate=g), 100.0)], ids=["observer", "rls"])
def test_force_spikes_no_longer_wreck_s(run20, make, factor):
    W = run20.w_hat.copy()
    W[SPIKES] *= factor
    E_clean, h_clean = _feed(make(FMS_GATE), run20, run20.w_hat)
    E_plain, _ = _feed(make(None), run20, W)
    E_gated, h = _feed(make(FMS_GATE), run20, W)
    assert E_plain > 10 * E_clean  # the ungated estimator's failure (measured 31 / 0.23 and 0.040 / 0.0024)
    assert E_gated < 1.1 * E_clean
    assert list(np.flatnonzero(h == Health.OUTLIER)) == list(SPIKES // BLOCK)
    assert not np.any(h_clean == Health.OUTLIER)


def test_signal_gate_config_errors():
    with pytest.raises(EstimatorConfigError, match="dof = channels"):
        SignalGate(1e-3, [0.1, 0.1], [1.0, 1.0], GateParams(dof=3))
    with pytest.raises(EstimatorConfigError, match="outlier_gate"):
        FmsObserver(outlier_gate=25.0)
    with pytest.raises(EstimatorConfigError, match="outlier_gate"):
        FmsRLS(outlier_gate="on")
