"""The wheel-speed gate's friction-jump rule (:mod:`estimators.jump`): a wheel that locks after dry -> ice restarts
the gate after two samples, where the gate without the rule discarded ten (the cause of
the dry->ice locks of PPO + EKF/RLS policies).

Logs: the quarter-car plant (1 ms substeps) braked at a torque held at ``SHARE`` of dry's peak torque (ramped in
over 0.1 s), the road turning from dry to ice at ``JUMP_AT``, measured as the braking env measures (wheel speed
noise of variance 0.2 (rad/s)^2, a_x the speed difference over the sample plus N(0, 0.1^2)); noise seeds 1-3.
"""

from __future__ import annotations

import numpy as np
import pytest

from estimators.base import Health
from estimators.batched import make_batched
from estimators.ekf_rls import QuarterCarEkfRls
from estimators.jump import JUMP_MU_MAX, jump_test
from estimators.registry import get_estimator
from fricenv.plants import quarter_car as qc
from fricenv.plants import sui_johansen as sj
from fricenv.plants.tire import DRY, ICE

P = qc.PAPER_PARAMS
DT = 0.01
V0 = 20.0  # [m/s]
SHARE = 0.95  # brake torque / dry's peak torque r F_z mu_max [-]
JUMP_AT = 0.5  # [s]
T_END = 0.8  # [s]
K_JUMP = round(JUMP_AT / DT)  # the first sample measured on ice (its speed change is the first on ice)
BAD = (int(Health.OUTLIER), int(Health.REINITIALISED))


def dry_to_ice_log(seed: int) -> np.ndarray:
    """Rows (omega, a_x, T_b) of the log of the module docstring."""
    rng = np.random.default_rng(seed)
    v, w, v_prev = np.array([V0]), np.array([V0 / P.r]), V0
    torque = SHARE * P.r * P.Fz * DRY.mu_max
    rows = []
    for k in range(round(T_END / DT)):
        road = DRY if k * DT < JUMP_AT else ICE
        a_x = (v[0] - v_prev) / DT + rng.normal(0.0, 0.1)
        rows.append((w[0] + rng.normal(0.0, sj.OMEGA_NOISE_STD), a_x, torque * min(k * DT / 0.1, 1.0)))
        v_prev = v[0]
        v, w = qc.step(v, w, np.array([rows[-1][2]]), road.as_array(), DT, P, 10)
    return np.array(rows)


def _run(log: np.ndarray, rule: bool) -> tuple[np.ndarray, np.ndarray]:
    """Health and slip estimate per sample; ``rule=False``: no implied tire term is physical (the gate before)."""
    health, values = _estimates(log, rule)
    return health, values["slip"]


def _estimates(log: np.ndarray, rule: bool = True) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Health and every value of the estimator per sample (``rule`` as in :func:`_run`)."""
    est = QuarterCarEkfRls(dt=DT, p=P)
    est.reset(v0=float(log[0, 0]) * P.r)
    if not rule:
        est.core.wheel_gate.b_bound[:] = 0.0
    out = [est.update((w, a), (T,)) for w, a, T in log]
    return np.array([int(e.health) for e in out]), {k: np.array([e[k] for e in out]) for k in est.names}


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_friction_drop_restarts_the_gate_after_two_samples(seed):
    log = dry_to_ice_log(seed)
    health, slip = _run(log, rule=True)
    assert not np.isin(health[:K_JUMP], BAD).any()  # no false marks on dry
    assert list(health[K_JUMP:K_JUMP + 3]) == [int(Health.OK), int(Health.OUTLIER), int(Health.REINITIALISED)]
    assert slip[K_JUMP + 3] > 0.5  # the locking wheel is seen 30 ms after the jump (true slip about 0.9)
    old_health, old_slip = _run(log, rule=False)  # before: ten samples discarded while the wheel locked
    assert list(old_health[K_JUMP + 1:K_JUMP + 11]) == [int(Health.OUTLIER)] * 10
    assert np.all(old_slip[K_JUMP + 1:K_JUMP + 11] < 0.2)


def test_jump_test_implied_term_and_rule():
    dt, I_w, bound = 0.01, 1.0, 1000.0
    # (J2): from 30 rad/s with -900 N m held, a wheel read at 22 rad/s implied b = (30 - 9 - 22) / 0.01 = -100
    jump, chain, b = jump_test(1, True, -1.0, 30.0, 22.0, -900.0, -5.0, dt, I_w, bound)
    assert b == pytest.approx(-100.0, abs=1e-9) and chain and jump
    assert not jump_test(0, True, -1.0, 30.0, 22.0, -900.0, -5.0, dt, I_w, bound)[0]  # the first of a run
    assert not jump_test(1, False, -1.0, 30.0, 22.0, -900.0, -5.0, dt, I_w, bound)[0]  # the run had a spike
    assert not jump_test(1, True, 1.0, 30.0, 22.0, -900.0, -5.0, dt, I_w, bound)[0]  # innovations of both signs
    jump, chain, b = jump_test(1, True, -1.0, 30.0, 0.0, -900.0, -5.0, dt, I_w, bound)  # a drop to 0 at speed
    assert b == pytest.approx(2100.0, abs=1e-9) and not chain and not jump
    assert JUMP_MU_MAX * P.Fz * P.r / P.J == pytest.approx(1.5 * 1099.86, rel=1e-4)  # this car's bound


def test_batched_gate_takes_the_same_jumps():
    logs = [dry_to_ice_log(seed) for seed in (1, 2, 3)]
    omega, a_x, T_b = (np.stack([log[:, j] for log in logs], axis=1) for j in range(3))
    batched = make_batched("ekf-rls", 3, P, DT)
    batched.reset(v0=omega[0] * P.r)
    singles = [get_estimator("ekf-rls").make(P, DT) for _ in logs]
    for i, est in enumerate(singles):
        est.reset(v0=float(omega[0, i]) * P.r)
    jumps = np.zeros(3, dtype=int)
    for k in range(omega.shape[0]):
        values, health = batched.update(omega[k], a_x[k], T_b[k])
        jumps += (health == int(Health.REINITIALISED)) & (K_JUMP <= k <= K_JUMP + 2)
        for i, est in enumerate(singles):
            ref = est.update((omega[k, i], a_x[k, i]), (T_b[k, i],))
            assert health[i] == int(ref.health), (k, i)
            for key in est.names:
                np.testing.assert_allclose(values[key][i], ref.values[key], rtol=1e-9, atol=1e-9)
    assert list(jumps) == [1, 1, 1]  # every sub-env took the jump, at the sample the single estimator did


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_restart_drops_the_old_roads_peak_friction_at_once(seed):
    """At the jump's restart the RLS covariance and the shape fit's memory restart: the peak friction estimate is
    within 0.05 of ice's 0.1 from the sample after the restart on (it held dry's for about 0.4 s before)."""
    health, values = _estimates(dry_to_ice_log(seed))
    restart = K_JUMP + 2
    assert health[restart] == int(Health.REINITIALISED) and values["mu"][restart - 1] > 0.8  # still dry's
    assert np.all(np.abs(values["mu"][restart + 1:] - ICE.mu_max) <= 0.05), values["mu"][restart + 1:]


def test_jump_test_a_braked_wheel_held_at_rest():
    """(J3): at rest the brake applies only what the tire pulls; a command above the bound implies no tire
    term."""
    dt, I_w, bound, band = 0.01, 1.0, 1650.0, 1.34
    # 0.02 -> -0.66 rad/s under 1735.6 N m commanded: (J2) gives b = -1667, beyond the bound
    assert not jump_test(1, True, -1.0, 0.02, -0.66, -1735.6, -6.0, dt, I_w, bound)[1]  # the rule off
    jump, chain, b = jump_test(1, True, -1.0, 0.02, -0.66, -1735.6, -6.0, dt, I_w, bound, band)
    assert chain and jump and b == -bound
    # a drop to 0 at speed stays a spike; a wheel at rest without a brake is not held by one
    assert not jump_test(1, True, -1.0, 30.0, 0.0, -900.0, -5.0, dt, I_w, bound, band)[1]
    assert not jump_test(1, True, -1.0, 0.02, -0.66, 1735.6, -6.0, dt, I_w, bound, band)[1]
