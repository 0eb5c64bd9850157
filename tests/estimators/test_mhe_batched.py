"""The batched MHE equals N single regularized MHEs, on plant-generated logs."""

import numpy as np
import pytest

from estimators.base import EstimatorConfigError, Health
from estimators.casadi_compiled import compiled
from estimators.mhe_batched import BATCHED_MHE, BatchedMHE
from estimators.registry import get_estimator
from estimators.scenarios import mhe_case
from fricenv.plants import quarter_car as qc

P = qc.PAPER_PARAMS
DT = 0.01
TOL = 1e-9  # the batched MHE runs the single's operations (measured: equal to the last bit); 1e-9 is the brief's
CORRUPT_AT = 60  # sample at which sub-env 1's EKF theta variance is made negative: the next solves fail


def _signals(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Wheel speeds and torques (T, n) of the paper's cases 1-4, with NaN samples, single outliers, a burst of
    outliers long enough to re-initialise (sub-env 0)."""
    cases = [mhe_case(1 + i % 4, seed=seed + i) for i in range(n)]
    T = min(len(c.log.t) for c in cases)
    omega = np.array([c.log.omega[:T] for c in cases]).T.copy()
    torque = np.array([c.log.T_b[:T] for c in cases]).T.copy()
    rng = np.random.default_rng(seed)
    omega[rng.uniform(size=omega.shape) < 0.03] = np.nan
    torque[rng.uniform(size=torque.shape) < 0.01] = np.nan
    omega[rng.uniform(size=omega.shape) < 0.03] += 30.0
    omega[40:53, 0] += 40.0  # 13 rejections in a row: the 11th re-initialises
    return omega, torque


def _run_both(name: str, n: int, seed: int, batched: BatchedMHE | None = None, reset_at: int = 70):
    """Feed N single MHEs and one batched MHE the same samples and per-env resets; returns the largest value
    difference and the health flags seen (T, n)."""
    singles = [get_estimator(name).make(P, DT) for _ in range(n)]
    batched = batched or BatchedMHE(get_estimator(name).make(P, DT), n)
    omega, torque = _signals(n, seed)
    v0 = np.nan_to_num(omega[0], nan=60.0) * P.r
    for est, v in zip(singles, v0):
        est.reset(v=v, slip=0.0)
    batched.reset(None, v0)
    worst, healths = 0.0, []
    for k in range(len(omega)):
        if k == reset_at:  # autoreset of every other sub-env
            mask = np.arange(n) % 2 == 0
            for i in np.flatnonzero(mask):
                singles[i].reset(v=15.0 + i, slip=0.0)
            batched.reset(mask, 15.0 + np.arange(n))
        if k == CORRUPT_AT:  # the arrival covariance's Cholesky factor will fail: SOLVER_FAILED, then recovery
            singles[1].arrival_filter.P = singles[1].arrival_filter.P.copy()
            singles[1].arrival_filter.P[2, 2] *= -1.0
            batched.ekf_P[1, 2, 2] *= -1.0
        ests = [s.update([omega[k, i]], [torque[k, i]]) for i, s in enumerate(singles)]
        values, health = batched.update(omega[k], np.zeros(n), torque[k])
        np.testing.assert_array_equal(health, [int(e.health) for e in ests])
        for key in batched.names:
            ref = np.array([e.values[key] for e in ests])
            np.testing.assert_allclose(values[key], ref, rtol=TOL, atol=TOL, err_msg=f"{key} at sample {k}")
            worst = max(worst, float(np.max(np.abs(values[key] - ref))))
        healths.append(health)
    return worst, np.array(healths)


@pytest.mark.parametrize("name", ["mhe", "mhe-full"])
def test_batched_mhe_equals_single_mhes_across_resets_outliers_nan_and_failures(name):
    worst, health = _run_both(name, 4, seed=3)
    assert worst < TOL
    flags = [Health.NOT_EXCITED, Health.INVALID_INPUT, Health.OUTLIER, Health.REINITIALISED]
    if name == "mhe":  # with four parameters: never OK (delta 0.8) and the failures hide behind OUTLIER flags
        flags += [Health.OK, Health.SOLVER_FAILED]
    for flag in flags:  # every path was exercised
        assert (health == int(flag)).any(), f"{flag.name} never occurred"


@pytest.mark.slow
def test_thread_map_and_virtual_machine_equal_the_compiled_serial_map():
    template = get_estimator("mhe").make(P, DT)
    for variant in (BatchedMHE(template, 3, parallel="thread", threads=2), BatchedMHE(template, 3, compile_c=False)):
        worst, _ = _run_both("mhe", 3, seed=11, batched=variant)
        assert worst < TOL


def test_compiled_window_function_equals_casadi_virtual_machine(tmp_path):
    template = get_estimator("mhe").make(P, DT)
    fast = compiled(template._fun, tmp_path)
    if fast is None:
        pytest.skip("no C compiler")
    assert len(list(tmp_path.glob("*.so"))) == 1
    rng = np.random.default_rng(0)
    for _ in range(20):
        z = np.r_[rng.uniform(5, 30), rng.uniform(0, 0.3), rng.uniform(0.1, 1), rng.normal(0, 0.01, template._nz - 3)]
        U = rng.uniform(0, 1500, template.N)
        for a, b in zip(template._fun(z, U), fast(z, U)):
            np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-13, atol=1e-13)
    assert compiled(template._fun, tmp_path) is not None  # loaded from the cache, not rebuilt
    assert len(list(tmp_path.glob("*.so"))) == 1


def test_batched_mhe_refuses_the_paper_variants_and_bad_options():
    with pytest.raises(EstimatorConfigError, match="EKF arrival cost with the scaled weighting"):
        BatchedMHE(get_estimator("mhe-paper").make(P, DT), 2)
    template = get_estimator("mhe").make(P, DT)
    with pytest.raises(EstimatorConfigError, match="threads must be"):
        BatchedMHE(template, 2, parallel="thread", threads=4)
    with pytest.raises(EstimatorConfigError, match="parallel must be one of"):
        BatchedMHE(template, 2, parallel="process")
    with pytest.raises(TypeError, match="RegularizedMHE"):
        BatchedMHE(object(), 2)


def test_registry_builders_build_the_entries_estimator():
    from estimators.registry import ESTIMATORS

    full = BATCHED_MHE["mhe-full"](2, DT, P, {})
    assert full.t.model.estimated == ("theta", "B", "C", "E")
    assert BATCHED_MHE["mhe"](2, DT, P, {}).t.model.estimated == ("theta",)
    for name in BATCHED_MHE:  # the options estimators.batched.make_batched passes once "mhe" is in BATCHED
        entry = ESTIMATORS[name]
        built = BATCHED_MHE[name](2, DT, P, {**entry.options, "shape": object()}).t
        assert built.model.fixed == entry.make(P, DT).model.fixed
