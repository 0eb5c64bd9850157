"""The compiled nuisance fit (fricenv.gap.quarter_car.windows_kernel) against the numpy Gauss-Newton loop of
fricenv.gap.quarter_car.windows around the same compiled simulator: the same replicas, steps, clips, bounds, summation order
and LAPACK solve, so the residuals are equal bit for bit (a last-bit difference can grow through a least-squares run
into a different optimum, so nothing less would keep the diagnosis' results); and the sums, the solve and the move
rule on their own."""

from dataclasses import replace

import numpy as np
import pytest

from fricenv.effects.quarter_car import make_effect
from fricenv.gap.quarter_car import windows, windows_kernel
from fricenv.gap.quarter_car.config import DiagnoseConfig
from fricenv.gap.quarter_car.simulate import simulate_log
from fricenv.gap.quarter_car.windows import prepare, window_residuals
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import DRY, WET

P = qc.PAPER_PARAMS

# (effects, parameter names, two parameter sets): the states fitted differ (lam_t for a relaxation model), and the
# effects switch on every part of the simulator's substep
CASES = [
    ([], ("B", "C", "E", "theta"), [[*WET.as_array()], [*DRY.as_array()[:3], 0.6]]),
    (["brake_lag", "brake_delay"], ("B", "C", "E", "theta", "tau", "delay"),
     [[*WET.as_array(), 0.03, 0.02], [*WET.as_array()[:3], 0.7, 0.0, 0.04]]),
    (["relaxation_length"], ("B", "C", "E", "theta", "sigma"), [[*WET.as_array(), 0.3], [*DRY.as_array(), 0.0]]),
    (["brake_fade", "load_transfer", "drag"], ("B", "C", "E", "theta", "fade", "load", "c0", "c2"),
     [[*WET.as_array(), 1e-5, 0.3, 40.0, 0.3], [*WET.as_array(), 0.0, -0.2, 0.0, 0.0]]),
    (["sliding_speed_friction", "mu_change"], ("B", "C", "E", "theta", "slide", "t_change", "theta_after"),
     [[*WET.as_array(), 0.05, 1.0, 0.5], [*DRY.as_array(), 0.0, np.inf, 1.0]]),
]


def _data(write_v: bool, seed: int, missing: bool = False):
    log, _ = simulate_log([make_effect("brake_lag", tau=0.04)], WET, "abs", seed=seed, duration=2.0, write_v=write_v)
    if missing:  # held and missing samples: no residual there
        omega = np.array(log.omega, dtype=float)
        omega[5::7] = np.nan
        log = replace(log, omega=omega)
    return prepare(log, P, DiagnoseConfig(jobs=1))


@pytest.mark.parametrize("write_v", [True, False])
@pytest.mark.parametrize("case", range(len(CASES)))
def test_compiled_nuisance_fit_equals_the_numpy_loop(monkeypatch, write_v, case):
    effects, names, x = CASES[case]
    d = _data(write_v, seed=3 + case, missing=case == 1)
    fused = window_residuals(effects, names, np.array(x), d)
    monkeypatch.setattr(windows, "FUSED_NUISANCE_FIT", False)
    loop, per_channel = window_residuals(effects, names, np.array(x), d, per_channel=True)
    assert fused.shape == loop.shape and np.all(np.isfinite(fused))
    np.testing.assert_array_equal(fused, loop)
    monkeypatch.setattr(windows, "FUSED_NUISANCE_FIT", True)
    _, fused_channels = window_residuals(effects, names, np.array(x), d, per_channel=True)
    for c in d.channels:  # NaN exactly where a sample is missing
        np.testing.assert_array_equal(np.isnan(fused_channels[c]), np.isnan(per_channel[c]))


def test_the_numpy_path_does_not_use_the_compiled_fit(monkeypatch):
    d = _data(True, seed=4)
    effects, names, x = CASES[1]
    numpy_path = window_residuals(effects, names, np.array(x), replace(d, compiled=False))
    monkeypatch.setattr(windows_kernel, "fit_windows", None)  # would fail if called
    assert np.array_equal(window_residuals(effects, names, np.array(x), replace(d, compiled=False)), numpy_path)


def test_the_small_solve_is_numpys_and_a_singular_matrix_gives_no_move():
    rng = np.random.default_rng(5)
    for q in (1, 2, 3):
        for _ in range(50):
            J = rng.normal(size=(12, q)) * rng.uniform(0.01, 100.0, q)
            A = J.T @ J + 1e-9 * np.eye(q)
            g = rng.normal(size=q)
            assert np.array_equal(windows_kernel._solve(A, g), np.linalg.solve(A, g[:, None])[:, 0])
    assert np.array_equal(windows_kernel._solve(np.zeros((2, 2)), np.array([1.0, 2.0])), np.zeros(2))


@pytest.mark.parametrize("M", [3, 8, 10, 17, 20, 30])
def test_the_one_state_sums_are_einsums(M):
    """The order of numpy's einsum over a contiguous reduction (what the numpy loop computes for one state)."""
    rng = np.random.default_rng(M)
    J, r = rng.normal(size=(4, 3, M, 1)) * 7.0, rng.normal(size=(4, 3, 2, M))
    A = np.einsum("kwmi,kwmj->kwij", J, J)
    g = np.einsum("kwmi,kwm->kwi", J, r[:, :, 0])
    for k in range(4):
        for w in range(3):
            assert windows_kernel._dot_simd(J[k, w, :, 0], J[k, w, :, 0]) == A[k, w, 0, 0]
            assert windows_kernel._dot_simd(J[k, w, :, 0], r[k, w, 0]) == g[k, w, 0]


def test_the_move_is_nan_to_num_then_clipped_to_its_step_and_bounds():
    s = np.array([10.0, 50.0, 0.95])
    free = np.array([1, 0, 2], dtype=np.int64)
    max_move, lower, upper = np.array([0.5, 0.3, 0.1]), np.array([0.0, 0.0, -1.0]), np.array([np.inf, np.inf, 1.0])
    windows_kernel._move(s, np.array([np.nan, -np.inf, np.inf]), free, max_move, lower, upper)
    # omega: NaN -> no move; v: -inf -> -max_move; lam_t: +inf -> +0.1, then the bound 1
    np.testing.assert_array_equal(s, [9.5, 50.0, 1.0])
    windows_kernel._move(s, np.array([-0.2, -100.0, -0.05]), free, max_move, lower, upper)
    np.testing.assert_allclose(s, [9.0, 49.8, 0.95], rtol=0, atol=1e-15)


def _residuals(effects, names, x, d):
    return window_residuals(effects, names, x, d)


def test_threads_and_worker_processes_do_not_change_the_residuals():
    """Kernel threads in the main process and in forked pool workers (Data.threads = jobs): the pairs are
    independent, so the residuals equal the single-threaded ones bit for bit."""
    from fricenv.gap.core.pool import map_tasks, shared_pool

    effects, names, x = CASES[2]
    d = _data(True, seed=6)
    one = window_residuals(effects, names, np.array(x), replace(d, threads=1))
    two = window_residuals(effects, names, np.array(x), replace(d, threads=2))
    with shared_pool(2):
        in_workers = map_tasks(_residuals, [(effects, names, np.array(x), replace(d, threads=2))] * 2, 2, "residuals")
    assert np.array_equal(one, two) and all(np.array_equal(one, w) for w in in_workers)
