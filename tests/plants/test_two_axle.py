"""Two-axle Dugoff plant (Li, Du & Li, eqs. (1)-(2)) against closed forms and scipy's Radau."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fricenv.plants import two_axle as ta

P = ta.TABLE_I


def test_axle_loads_sum_to_weight_and_follow_lever_arms():
    Fzf, Fzr = ta.axle_loads(P)
    assert Fzf + Fzr == pytest.approx(P.m * P.g)
    assert Fzf * P.L_f == pytest.approx(Fzr * P.L_r)


def test_dugoff_closed_forms():
    Fz, u = 7500.0, 15.0
    # linear region (lambda_D >= 1): F = C_s S / (1 - |S|), independent of mu
    for S in (0.005, -0.01, 0.02):
        for mu in (0.5, 0.9):
            assert ta.dugoff_force(S, Fz, u, mu, P) == pytest.approx(P.C_s * S / (1 - abs(S)))
    S = np.linspace(-0.9, 0.9, 181)
    F = ta.dugoff_force(S, Fz, u, 0.9, P)
    np.testing.assert_allclose(F, -ta.dugoff_force(-S, Fz, u, 0.9, P))  # odd
    # saturated region: F = mu Fz (1 - eps u |S|) (1 - lambda_D / 2) sign(S) <= mu Fz (1 - eps u |S|)
    assert np.all(np.abs(F) <= 0.9 * Fz * (1 - P.eps_r * u * np.abs(S)) + 1e-9)
    a = 0.3
    lam = 0.9 * Fz * (1 - P.eps_r * u * a) * (1 - a) / (2 * P.C_s * a)
    assert lam < 1
    assert ta.dugoff_force(a, Fz, u, 0.9, P) == pytest.approx(0.9 * Fz * (1 - P.eps_r * u * a) * (1 - lam / 2))


def test_free_rolling_keeps_speed():
    v, wf, wr = np.array([5.0, 20.0]), np.array([5.0, 20.0]) / P.R_w, np.array([5.0, 20.0]) / P.R_w
    for _ in range(100):
        v, wf, wr = ta.step(v, wf, wr, 0.0, 0.0, 0.01, P)
    np.testing.assert_allclose(v, [5.0, 20.0], rtol=1e-12)


def test_step_matches_radau_traction_then_braking():
    def torques(t):
        if t < 1.0:
            return 300.0, 0.0
        return -900.0, -600.0

    x = (np.array([10.0]), np.array([10.0 / P.R_w]), np.array([10.0 / P.R_w]))
    dt = 0.01
    n = 200
    for k in range(n):
        x = ta.step(*x, *torques(k * dt), dt, P, substeps=10)
    y = np.array([10.0, 10.0 / P.R_w, 10.0 / P.R_w])
    for k in range(n):  # same zero-order hold, one Radau solve per sample
        Tf, Tr = torques(k * dt)
        sol = solve_ivp(lambda t, s, Tf=Tf, Tr=Tr: ta.derivatives(s[0], s[1], s[2], Tf, Tr, P), (0, dt), y,
                        method="Radau",
                        rtol=1e-10, atol=1e-10)
        y = sol.y[:, -1]
    np.testing.assert_allclose([x[0][0], x[1][0], x[2][0]], y, rtol=1e-6)


def test_batched_equals_single():
    v = np.array([8.0, 12.0, 20.0])
    wf = v / P.R_w * np.array([1.02, 0.97, 1.0])
    wr = v / P.R_w
    Tf, Tr = np.array([300.0, -800.0, 0.0]), np.array([0.0, -500.0, 0.0])
    out = ta.step(v, wf, wr, Tf, Tr, 0.01, P)
    for i in range(3):
        single = ta.step(v[i:i + 1], wf[i:i + 1], wr[i:i + 1], Tf[i], Tr[i], 0.01, P)
        for a, b in zip(out, single):
            assert a[i] == pytest.approx(b[0], rel=1e-14)


def test_bad_parameters_raise():
    with pytest.raises(ValueError, match="m"):
        ta.TwoAxleParams(m=-1.0)
    with pytest.raises(ValueError, match="substeps"):
        ta.step(np.array([1.0]), np.array([1.0]), np.array([1.0]), 0.0, 0.0, 0.01, P, substeps=0)
    with pytest.raises(ValueError, match="dt"):
        ta.step(np.array([1.0]), np.array([1.0]), np.array([1.0]), 0.0, 0.0, -0.01, P)
