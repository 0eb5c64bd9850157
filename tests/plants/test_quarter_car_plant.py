"""Quarter-car plant against closed forms and an independent Radau reference."""

import numpy as np
import pytest

from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import DRY, ICE, ROADS, SNOW, WET, get_road, magic_formula, magic_formula_dslip
from tests.reference import stopping_distance_radau

P = qc.PAPER_PARAMS
DT = 0.01


def _zoh(torque_fn):
    """The env holds the torque over each 10 ms control step; the reference must see the same input."""
    return lambda t: torque_fn(np.floor(t / DT + 1e-9) * DT)


def _stop_distance_ros2(road, torque_fn, substeps, v0=20.0, v_stop=2.0):
    v, w, x, t = np.array([v0]), np.array([v0 / P.r]), 0.0, 0.0
    while True:
        v_prev = v.copy()
        v, w = qc.step(v, w, torque_fn(t), road.as_array(), DT, P, substeps)
        if v[0] <= v_stop:  # the speed is linear within a step to second order: interpolate the crossing
            frac = (v_prev[0] - v_stop) / (v_prev[0] - v[0])
            return x + frac * DT * (v_prev[0] + v_stop) / 2
        x += DT * (v_prev[0] + v[0]) / 2
        t += DT


CASES = [(road, profile) for road in (DRY, WET, SNOW, ICE) for profile in ("below_peak", "lock_up")]
# The modulated torque changes every control step, so its Radau reference restarts ~100 times per second of
# braking; it is kept on the two short stops, where it adds coverage of the peak region.
CASES += [(DRY, "modulated"), (WET, "modulated")]


# The longest references (a lock-up on ice, the modulated wet and dry stops) run with the slow tests.
SLOW_CASES = {("ice", "lock_up"), ("wet", "modulated"), ("dry", "modulated")}


@pytest.mark.parametrize("road, profile", [pytest.param(r, prof, marks=pytest.mark.slow)
                                           if (r.name, prof) in SLOW_CASES else (r, prof) for r, prof in CASES],
                         ids=lambda x: getattr(x, "name", x))
def test_stopping_distance_matches_radau(road, profile):
    t_safe = 0.8 * road.mu_max * P.Fz * P.r
    torque = {
        "below_peak": lambda t: t_safe,
        "lock_up": lambda t: 3000.0 * min(t / 0.2, 1.0),  # ramps through the peak and locks the wheel
        "modulated": lambda t: t_safe * (1 + 0.3 * np.sin(2 * np.pi * 3 * t)),
    }[profile]
    ref, _ = stopping_distance_radau(road, _zoh(torque))
    ours = _stop_distance_ros2(road, torque, substeps=5)
    assert abs(ours - ref) / ref < 1e-3, (ours, ref)


def test_free_rolling_keeps_speed_and_zero_slip():
    n = 4
    v = np.array([5.0, 10.0, 20.0, 30.0])
    w = v / P.r
    road = qc.road_array(DRY, n)
    for _ in range(300):
        v, w = qc.step(v, w, np.zeros(n), road, DT, P, substeps=5)
    np.testing.assert_allclose(v, [5.0, 10.0, 20.0, 30.0], rtol=1e-12)
    np.testing.assert_allclose(w * P.r, v, rtol=1e-12)


@pytest.mark.parametrize("road", [DRY, WET, SNOW, ICE], ids=lambda r: r.name)
def test_locked_wheel_decelerates_at_g_mu_of_full_slip(road):
    v, w = np.array([20.0]), np.array([0.0])  # locked from the start, brake far above the tire torque
    v_next, w_next = qc.step(v, w, 5000.0, road.as_array(), 0.5, P, substeps=50)
    assert w_next[0] == 0.0
    decel = (v[0] - v_next[0]) / 0.5
    assert decel == pytest.approx(P.Fz * road.mu(1.0) / P.m, rel=1e-9)
    assert decel == pytest.approx(P.g * road.mu_locked, rel=1e-3)  # F_z = m g to 1e-4 in Table I


def test_lock_releases_when_brake_drops_below_tire_torque():
    v, w = np.array([20.0]), np.array([0.0])
    v, w = qc.step(v, w, 0.0, DRY.as_array(), 0.2, P, substeps=20)
    assert w[0] * P.r == pytest.approx(v[0], rel=1e-3)  # spun back up to free rolling


def test_traction_accelerates_with_negative_slip():
    v, w = np.array([10.0]), np.array([10.0 / P.r])
    for _ in range(100):
        v, w = qc.step(v, w, -500.0, WET.as_array(), DT, P, substeps=5)
    assert v[0] > 10.5
    lam = qc.slip(v, w, P)
    assert -0.2 < lam[0] < 0.0
    # traction slip is Li et al.'s (omega r - v)/(omega r), reported negative
    assert lam[0] == pytest.approx(-(w[0] * P.r - v[0]) / (w[0] * P.r))


def test_slip_form_matches_speed_form():
    rng = np.random.default_rng(0)
    v = rng.uniform(3, 30, 50)
    lam = rng.uniform(0.0, 0.9, 50)
    w = v * (1 - lam) / P.r
    tb = rng.uniform(0, 2000, 50)
    R = DRY.as_array()
    vdot, wdot = qc.derivatives(v, w, tb, R, P)
    vdot2, lamdot = qc.slip_form_derivatives(v, lam, tb, R, P)
    np.testing.assert_allclose(vdot, vdot2, rtol=1e-12)
    # lambda = 1 - omega r / v  =>  lambda' = -(r/v) omega' + (omega r / v^2) v'
    np.testing.assert_allclose(lamdot, -(P.r / v) * wdot + w * P.r / v**2 * vdot, rtol=1e-9, atol=1e-9)


def test_jacobian_matches_finite_differences():
    rng = np.random.default_rng(1)
    R = WET.as_array()
    for v, w in [(20.0, 50.0), (10.0, 35.0), (5.0, 5.0), (15.0, 20.0 / P.r)]:
        a = np.array(qc.jacobian(v, w, R, P)).reshape(2, 2)
        eps = 1e-6
        num = np.zeros((2, 2))
        for j, (dv, dw) in enumerate([(eps, 0), (0, eps)]):
            fp = np.array(qc.derivatives(v + dv, w + dw, 0.0, R, P))
            fm = np.array(qc.derivatives(v - dv, w - dw, 0.0, R, P))
            num[:, j] = (fp - fm) / (2 * eps)
        np.testing.assert_allclose(a, num, rtol=1e-5, atol=1e-6)
    del rng


def test_magic_formula_derivative_and_oddness():
    s = np.linspace(-1, 1, 401)
    for road in ROADS.values():
        args = (road.B, road.C, road.E, road.theta)
        np.testing.assert_allclose(magic_formula(-s, *args), -magic_formula(s, *args), atol=1e-15)
        num = (magic_formula(s + 1e-7, *args) - magic_formula(s - 1e-7, *args)) / 2e-7
        np.testing.assert_allclose(magic_formula_dslip(s, *args), num, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("name, limit_m", [("dry", 20.2), ("snow", 68.2), ("ice", 201.9), ("wet", 24.6)])
def test_peak_and_physical_limit(name, limit_m):
    road = get_road(name)
    grid = np.linspace(1e-4, 1, 200001)
    assert road.mu_max == pytest.approx(road.mu(grid).max(), abs=1e-9)
    assert road.mu_max >= road.mu(grid).max() - 1e-12
    assert qc.physical_limit_distance(20.0, 2.0, road.mu_max, P) == pytest.approx(limit_m, abs=0.1)


def test_snow_has_no_interior_peak():
    assert SNOW.peak_slip == 1.0  # C < 1: mu rises all the way to lock (documented in tire.py)
    assert np.all(np.diff(SNOW.mu(np.linspace(0.01, 1, 100))) > 0)


def test_unknown_road_lists_valid_names():
    with pytest.raises(ValueError, match="valid roads: dry, wet, snow, ice"):
        get_road("gravel")


def test_bad_params_rejected():
    with pytest.raises(ValueError, match="QuarterCarParams.m"):
        qc.QuarterCarParams(m=-1.0)


RELEASE_PAST_PEAK = [(WET, 0.136, v0) for v0 in (1.0, 2.0, 4.0)] + [(DRY, 0.3, v0) for v0 in (1.0, 2.0, 4.0)]


@pytest.mark.parametrize("road, lam, v0", RELEASE_PAST_PEAK, ids=lambda x: getattr(x, "name", x))
def test_brake_release_past_peak_at_low_speed_is_physical(road, lam, v0):
    """Releasing the brake past the peak at low speed: the slip dynamics are much faster than a 2 ms step, and a
    linearised step once overshot to traction slip and pushed the car forward (v 2.000 -> 2.032 m/s on wet)."""
    v, w = np.array([v0]), np.array([v0 * (1 - lam) / P.r])
    v1, w1 = qc.step(v, w, np.zeros(1), road.as_array(), 0.002, P, substeps=1)
    assert v1[0] <= v0 and w1[0] * P.r <= v1[0] * (1 + 1e-9)  # no energy from nowhere, even in one substep
    # over a control step at the env's 2 ms substeps, against a 25 us reference
    v10, w10 = qc.step(v, w, np.zeros(1), road.as_array(), DT, P, substeps=5)
    v_fine, w_fine = qc.step(v, w, np.zeros(1), road.as_array(), DT, P, substeps=400)
    assert v10[0] == pytest.approx(v_fine[0], rel=1e-4)
    assert w10[0] == pytest.approx(w_fine[0], rel=1e-3)


@pytest.mark.parametrize("road, lam, v0", RELEASE_PAST_PEAK, ids=lambda x: getattr(x, "name", x))
def test_env_kernels_equal_the_plant_on_refined_steps(road, lam, v0):
    from fricenv.plants import compiled
    from fricenv.plants.braking_plant import BatchPlant

    w0 = v0 * (1 - lam) / P.r
    ref = qc.step(np.array([v0]), np.array([w0]), np.zeros(1), road.as_array(), 0.002, P, substeps=1)
    scalar = compiled.substep_refined(v0, w0, 0.0, *road.as_array(), road.mu_locked, 0.002, P.r, P.m, P.J, P.Fz)
    batch = BatchPlant(1, 0.002, P)
    batch.set_road(slice(None), road.as_array())
    batch.set_torque(np.zeros(1))
    batch.reset(slice(None), v0, w0)
    vb, wb = batch.substep()
    np.testing.assert_allclose([scalar[0], vb[0]], ref[0][0], rtol=1e-12)
    np.testing.assert_allclose([scalar[1], wb[0]], ref[1][0], rtol=1e-10)
