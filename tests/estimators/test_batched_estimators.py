"""The batched EKF/RLS (compiled) equals N single estimators (to 1e-9) across per-env resets, outliers and invalid
samples, friction jumps and a wheel past the car's speed, with and without the wheel-speed gate."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.base import Health
from estimators.batched import BatchedEkfRls, make_batched
from estimators.registry import make_estimator
from fricenv.plants.quarter_car import PAPER_PARAMS

N, STEPS, DT = 6, 400, 0.01


def _signals(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Braking-like wheel speed, a_x and torque per sub-env, with spikes (outliers), a dropout run and a wheel that
    locks (a friction jump, :mod:`estimators.jump`)."""
    t = np.arange(STEPS) * DT
    v = 25.0 - 6.0 * t[:, None] * rng.uniform(0.5, 1.5, N)
    slip = 0.05 + 0.04 * np.sin(7.0 * t[:, None] + rng.uniform(0, 6, N))
    omega = v * (1.0 - slip) / PAPER_PARAMS.r + rng.normal(0, 0.05, (STEPS, N))
    a_x = -6.0 + rng.normal(0, 0.05, (STEPS, N))
    a_x[STEPS // 2:, 3:5] /= 6.0  # a friction jump (6x less force): the curve-shape fit restarts its memory
    T_b = 800.0 + 300.0 * np.sin(11.0 * t[:, None] + rng.uniform(0, 6, N))
    spikes = rng.random((STEPS, N)) < 0.02
    omega[spikes] += rng.choice([-30.0, 30.0], spikes.sum())
    omega[200:215, 1] = 0.0  # a dropout longer than max_rejections: rejections then a re-initialisation
    lock = np.arange(1, STEPS - 300 + 1)  # a wheel that locks at 800 rad/s^2 (a friction drop): the gate's jump rule
    omega[300:, 5] = np.maximum(omega[299, 5] - 8.0 * lock, 0.0) + rng.normal(0, 0.05, lock.size)
    omega[50, 2] = np.nan  # an invalid sample
    omega[120:126, 0] = v[120:126, 0] * 1.06 / PAPER_PARAMS.r  # a wheel past the car: the braking rules (B1)-(B3)
    return omega, a_x, T_b


@pytest.mark.parametrize(("name", "options"), [("ekf-rls", {}), ("ekf-rls-paper-loop", {}),
                                               ("ekf-rls-paper-map", {}), ("ekf-rls", {"outlier_gate": None})])
def test_batched_ekf_rls_equals_single_estimators(name, options):
    rng = np.random.default_rng(3)
    omega, a_x, T_b = _signals(rng)
    resets = {k: rng.random(N) < 0.01 for k in range(1, STEPS)}  # per-env resets, as autoresets do
    batched = make_batched(name, N, PAPER_PARAMS, DT, **options)
    singles = [make_estimator(name, PAPER_PARAMS, DT, **options) for _ in range(N)]
    v0 = omega[0] * PAPER_PARAMS.r
    batched.reset(v0=v0)
    for i, est in enumerate(singles):
        est.reset(v0=float(v0[i]))
    seen, peaks = set(), set()
    for k in range(STEPS):
        mask = resets.get(k)
        if mask is not None and mask.any():
            batched.reset(mask, np.full(N, np.nan))  # restart from the next wheel speed
            for i in np.flatnonzero(mask):
                singles[i].reset()
        values, health = batched.update(omega[k], a_x[k], T_b[k])
        for i, est in enumerate(singles):
            ref = est.update((omega[k, i], a_x[k, i]), (T_b[k, i],))
            assert health[i] == int(ref.health), (k, i)
            seen.add(int(ref.health))
            peaks.add(ref.values.get("peak_slip"))
            for key in est.names:
                np.testing.assert_allclose(values[key][i], ref.values[key], rtol=1e-9, atol=1e-9,
                                           err_msg=f"{name} {key} step {k} env {i}")
    gated = {int(Health.OUTLIER), int(Health.REINITIALISED)}
    assert {int(Health.INVALID_INPUT), int(Health.OK)} <= seen
    assert gated <= seen if "outlier_gate" not in options else not gated & seen
    if name != "ekf-rls-paper-map":  # the curve-shape fit ran and left its prior (the paper's map has no fit)
        assert len(peaks) >= 2, peaks


def test_make_batched_answers_none_without_a_batched_form():
    assert make_batched("mhe-paper", 2, PAPER_PARAMS, DT) is None
    assert isinstance(make_batched("ekf-rls", 2, PAPER_PARAMS, DT), BatchedEkfRls)


def test_batched_rejects_a_map_without_batch_form():
    with pytest.raises(TypeError, match="batch"):
        BatchedEkfRls(2, DT, PAPER_PARAMS, mu_map=lambda k_s, s_bar: 0.1 * k_s)


def test_batched_ekf_rls_equals_single_estimators_on_a_stop_with_a_free_roll_and_releases():
    """The gap tool's open-loop stop (dry, seed 18): a free roll, then torque released from past the road's peak,
    where rules (B5) and (B6) of :mod:`estimators.speed_reference` act."""
    from fricenv.gap.quarter_car.simulate import simulate_log
    from fricenv.plants.tire import DRY

    log, _ = simulate_log([], DRY, "open-loop", seed=18)
    batched, single = make_batched("ekf-rls", 1, PAPER_PARAMS, DT), make_estimator("ekf-rls", PAPER_PARAMS, DT)
    batched.reset(v0=np.full(1, np.nan))
    single.reset()
    for k in range(log.t.size):
        values, health = batched.update(log.omega[k:k + 1], log.a_x[k:k + 1], log.T_b[k:k + 1])
        ref = single.update((log.omega[k], log.a_x[k]), (log.T_b[k],))
        assert health[0] == int(ref.health), k
        for key in single.names:
            np.testing.assert_allclose(values[key][0], ref.values[key], rtol=1e-9, atol=1e-9, err_msg=f"{key} step {k}")
