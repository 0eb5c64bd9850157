"""Tests of the independent quarter-car log simulator (validation/independent_sim.py) and one slow blind-diagnosis check."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from validation import independent_sim as ind
from validation.independent_sim import (
    CATEGORIES,
    DT,
    ROADS,
    VEHICLE,
    Effect,
    IndependentCase,
    draw_independent_case,
    integrate,
    make_model,
    simulate_case,
    stopping_distance,
    write_independent_log,
)

V0 = 25.0  # initial speed of the integrator checks [m/s]
DIST_RTOL = 1e-3  # stopping distance vs Radau: 0.1 %
LOCK_TORQUE = 3000.0  # far above the dry road's peak tire torque (~1100 N m) [N m]


def _radau_distance(model, v0: float, v_stop: float = ind.V_STOP) -> float:
    """Stopping distance of the same right-hand side by scipy's implicit Radau at a tight tolerance."""
    def reach(t, x):
        return x[0] - v_stop

    reach.terminal, reach.direction = True, -1
    x0 = ind.initial_state(model, v0)
    with np.errstate(over="ignore"):  # scipy's numerical Jacobian probes the unused states with huge steps
        sol = solve_ivp(model.rhs, (0.0, 30.0), x0, method="Radau", rtol=1e-10, atol=1e-9, events=reach)
    assert sol.status == 1, sol.message
    return float(sol.y_events[0][0][5])


@pytest.mark.parametrize("road, cmd", [
    ("dry", lambda t: 700.0),
    ("wet", lambda t: 500.0 + 300.0 * math.sin(2 * math.pi * 3.0 * t)),
    ("snow", lambda t: 150.0 + 100.0 * math.sin(2 * math.pi * 2.0 * t)),
])
def test_rk4_matches_radau_stopping_distance(road, cmd):
    model = make_model(ROADS[road], (), cmd)
    d_rk4 = stopping_distance(model, V0)
    d_ref = _radau_distance(model, V0)
    assert d_rk4 == pytest.approx(d_ref, rel=DIST_RTOL)
    # and the wheel stayed below the lock (the check is on the smooth dynamics)
    assert d_ref > (V0**2 - ind.V_STOP**2) / (2 * ind.G * ROADS[road].mu_max)


def test_lock_holds_omega_zero_and_car_slides_at_g_mu1():
    road = ROADS["dry"]
    model = make_model(road, (), lambda t: LOCK_TORQUE)
    x = ind.initial_state(model, V0)
    t, vs, ws = 0.0, [], []
    for _ in range(150):
        x = integrate(model, x, t, t + DT)
        t += DT
        vs.append(x[0])
        ws.append(x[1])
    ws = np.array(ws)
    locked = np.flatnonzero(ws == 0.0)
    assert locked.size > 100 and np.all(ws[locked[0]:] == 0.0)  # once locked, exactly 0 throughout
    k0 = locked[0] + 5
    decel = -(vs[-1] - vs[k0]) / ((len(vs) - 1 - k0) * DT)
    assert decel == pytest.approx(ind.G * road.mu(1.0), rel=2e-3)  # Fz = 3188 N ~ m g = 3188.25 N


@pytest.mark.parametrize("share, stays_locked", [(1.05, True), (0.9, False)])
def test_locked_wheel_stays_locked_until_tire_torque_exceeds_brake(share, stays_locked):
    road, p = ROADS["dry"], VEHICLE
    hold = share * p.r * p.Fz * road.mu(1.0)  # below the peak torque, around the sliding torque
    model = make_model(road, (), lambda t: LOCK_TORQUE if t < 0.5 else hold)
    x = integrate(model, ind.initial_state(model, V0), 0.0, 0.45)
    assert x[1] == 0.0
    x = integrate(model, x, 0.45, 0.8)
    assert (x[1] == 0.0) == stays_locked


def _coast(effects, t_end: float = 3.0, v0: float = V0):
    model = make_model(ROADS["dry"], effects, lambda t: 0.0)
    return integrate(model, ind.initial_state(model, v0), 0.0, t_end)


def test_logged_command_is_zero_order_held_over_each_sample():
    case = draw_independent_case("none", np.random.default_rng(8), driver="sine", road=ROADS["wet"])
    sim = simulate_case(case)
    x = None
    for k, Tb in enumerate(sim["T_b"]):
        model = make_model(case.road, (), lambda t, Tb=Tb: Tb)  # this sample's command, over the whole sample
        x = ind.initial_state(model, case.v0) if x is None else x
        assert x[1] == pytest.approx(sim["omega_true"][k], rel=1e-12, abs=1e-12)
        assert model.applied(k * DT, x) == pytest.approx(sim["T_applied"][k], rel=1e-12)
        x = integrate(model, x, k * DT, (k + 1) * DT)


def test_drag_shortens_coast_down_closed_form():
    c0, c2, t_end = 200.0, 0.4, 3.0
    x0 = _coast((), t_end)
    x = _coast((Effect("drag", {"c0": c0, "c2": c2}),), t_end)
    assert x0[0] == pytest.approx(V0, abs=1e-6)  # no drag: free rolling keeps the speed
    # rolling wheel: m v' = -D - (J / r^2) v'  ->  v' = -(c0 + c2 v^2) / m_eff, closed form
    m_eff = VEHICLE.m + VEHICLE.J / VEHICLE.r**2
    k = math.sqrt(c0 * c2) / m_eff
    a = math.sqrt(c0 / c2)
    v_exact = a * math.tan(math.atan(V0 / a) - k * t_end)
    assert x[0] == pytest.approx(v_exact, rel=1e-3)
    assert x[5] < x0[5]


def _constant_brake(effects, torque: float = 600.0, road: str = "dry", t_end: float = 1.0):
    model = make_model(ROADS[road], effects, lambda t: torque if t >= 0.1 else 0.0)
    x = ind.initial_state(model, V0)
    out = [x]
    for k in range(round(t_end / DT)):
        x = integrate(model, x, k * DT, (k + 1) * DT)
        out.append(x)
    return model, np.array(out)


def test_brake_gain_increases_deceleration():
    gain = 1.2
    _, base = _constant_brake(())
    _, more = _constant_brake((Effect("brake_gain", {"gain": gain}),))
    # after the transient the car decelerates at ~ T_applied / (r m_eff): the ratio is the gain
    d_base = base[50, 0] - base[100, 0]
    d_more = more[50, 0] - more[100, 0]
    assert d_more / d_base == pytest.approx(gain, rel=0.02)
    assert more[20, 1] < base[20, 1]  # the wheel decelerates faster


def test_brake_lag_first_order_response():
    tau = 0.05
    model, xs = _constant_brake((Effect("brake_lag", {"tau": tau}),), t_end=0.3)
    t_step = 0.1
    k = round((t_step + tau) / DT)
    assert model.applied(k * DT, xs[k]) == pytest.approx(600.0 * (1 - math.exp(-1)), rel=1e-3)


def test_brake_delay_is_continuous_time():
    delay = 0.013  # not a multiple of the sample time
    model = make_model(ROADS["dry"], (Effect("brake_delay", {"delay": delay}),),
                       lambda t: 600.0 if t >= 0.1 else 0.0)
    x = ind.initial_state(model, V0)
    assert model.applied(0.1 + delay - 1e-4, x) == 0.0
    assert model.applied(0.1 + delay + 1e-4, x) == 600.0
    _, base = _constant_brake(())
    _, late = _constant_brake((Effect("brake_delay", {"delay": delay}),))
    assert late[12, 1] > base[12, 1]  # the wheel responds later


def test_relaxation_length_delays_tire_force():
    sigma = 0.4
    _, base = _constant_brake(())
    _, relax = _constant_brake((Effect("relaxation_length", {"sigma": sigma}),))
    # the tire force builds up over ~sigma / v = 16 ms: the car decelerates less and the wheel more at first
    assert relax[12, 0] > base[12, 0] + 1e-4
    assert relax[12, 1] < base[12, 1]
    # the transient slip settles at the slip in steady braking
    lam = 1 - relax[-1, 1] * VEHICLE.r / relax[-1, 0]
    assert relax[-1, 2] == pytest.approx(lam, rel=1e-2)


def test_radius_error_changes_free_rolling_omega():
    r_eff = 0.335
    case = draw_independent_case("radius_error", np.random.default_rng(0), driver="pedal",
                                 effects=(Effect("radius_error", {"r_eff": r_eff}),))
    sim = simulate_case(case)
    assert sim["omega_true"][0] == pytest.approx(case.v0 / r_eff, rel=1e-9)
    free = int(case.free_roll / DT) - 1
    ratio = np.mean(sim["omega"][:free]) * VEHICLE.r / np.mean(sim["v"][:free])
    assert ratio == pytest.approx(VEHICLE.r / r_eff, abs=0.01)


def test_mu_change_scales_sliding_deceleration():
    road = ROADS["dry"]
    model = make_model(road, (Effect("mu_change", {"t_change": 0.5, "theta_after": 0.6}),),
                       lambda t: LOCK_TORQUE)
    x = integrate(model, ind.initial_state(model, V0), 0.0, 0.3)
    assert x[1] == 0.0
    assert -model.accel(0.4, x) == pytest.approx(VEHICLE.Fz * road.mu(1.0) / VEHICLE.m, rel=1e-9)
    assert -model.accel(0.6, x) == pytest.approx(VEHICLE.Fz * road.mu(1.0) * 0.6 / VEHICLE.m, rel=1e-9)


def test_load_oscillation_modulates_force():
    road, A, f = ROADS["dry"], 0.2, 10.0
    model = make_model(road, (Effect("load_oscillation", {"amplitude": A, "freq": f, "phase": 0.0}),),
                       lambda t: LOCK_TORQUE)
    x = integrate(model, ind.initial_state(model, V0), 0.0, 0.3)
    t_crest = 0.3 + 0.25 / f - 0.3 % (1 / f)
    assert -model.accel(t_crest, x) == pytest.approx(VEHICLE.Fz * (1 + A) * road.mu(1.0) / VEHICLE.m, rel=1e-6)


def test_brake_fade_reduces_applied_torque_10_to_30_percent_on_a_dry_stop():
    rng = np.random.default_rng(4)
    drops = []
    for _ in range(3):
        fade = ind._fade_effect(V0, rng, VEHICLE)
        model = make_model(ROADS["dry"], (fade,), lambda t: 700.0)
        x, t = ind.initial_state(model, V0), 0.0
        while x[0] > ind.V_STOP:
            x = integrate(model, x, t, t + DT)
            t += DT
        assert t < ind.MAX_DURATION + 1.0
        drops.append(1 - model.applied(t, x) / 700.0)
    assert all(0.07 <= d <= 0.3 for d in drops), drops


def test_drivers_behave():
    rng = np.random.default_rng(11)
    for rn in ("dry", "wet", "snow"):
        road = ROADS[rn]
        t_peak = VEHICLE.r * VEHICLE.Fz * road.mu_max
        sine = simulate_case(draw_independent_case("none", rng, driver="sine", road=road))
        above = np.mean(sine["T_b"] > t_peak)
        assert sine["T_b"].max() > t_peak and 0 < above < 0.3  # the crest exceeds the peak briefly
        pedal = simulate_case(draw_independent_case("none", rng, driver="pedal", road=road))
        assert pedal["T_b"].max() <= 0.8 * 1.08 * t_peak
        abs_ = simulate_case(draw_independent_case("none", rng, driver="bosch-abs", road=road))
        assert np.mean(abs_["omega_true"] == 0.0) < 0.02  # the ABS keeps the wheel turning
        drops = np.sum(np.diff(abs_["T_b"]) < -0.05 * t_peak)
        assert drops >= 2  # it releases repeatedly
        for sim in (sine, pedal, abs_):
            free = np.flatnonzero(sim["T_b"] > 0)[0]
            assert 0.2 - 1e-9 <= free * DT <= 0.5 + DT  # free-rolling start


def test_written_log_is_readable_with_the_right_columns(tmp_path):
    from fricenv.logs import read_log

    rng = np.random.default_rng(2)
    for columns in ind.COLUMN_SETS:
        case = dataclasses.replace(draw_independent_case("brake_lag", rng), columns=columns)
        path = tmp_path / f"log_{len(columns)}_{'_'.join(columns)}.csv"
        truth = write_independent_log(path, case)
        log = read_log(path)
        assert len(log) == truth["samples"]
        assert (log.v is not None) == ("v" in columns) and (log.a_x is not None) == ("a_x" in columns)
        assert log.dt == pytest.approx(DT)
        assert not any("brake_lag" in c or "lag" in c for c in log.comments)
        assert truth["effect"] == "brake_lag" and set(truth["params"]) == {"tau"}
        sim = simulate_case(case)  # deterministic in the case's seed
        np.testing.assert_allclose(log.omega, sim["omega"], rtol=1e-8, atol=1e-8)


def test_real_like_export_reads_back_to_the_simulated_log(tmp_path):
    """--real: the export (validation/real_artifacts.py) read through its map is the simulated log on a coarser grid."""
    from fricenv.logs import read_log

    plain = ind.draw_cases(4, seed=3)
    real = ind.draw_cases(4, seed=3, real=True)
    assert [dataclasses.replace(c, real=None) for c in real] == plain  # same cases, only the export differs
    case = dataclasses.replace(real[0], columns=("v", "a_x"))
    csv_path, map_path, truth = ind.write_real_log(tmp_path / "export", case)
    log = read_log(csv_path, column_map=map_path)
    assert 25.0 <= case.real["rate_hz"] <= 100.0
    assert log.torque_from_pressure and abs(1.0 / log.dt - case.real["rate_hz"]) < 0.02 * case.real["rate_hz"]
    assert len(log) >= truth["samples"]  # dropped rows filled in
    sim = simulate_case(case)
    # wheel speed: the simulated measurement at the grid times, but for the few outliers (5-15 km/h, i.e. at least
    # 4 rad/s) and the 0.1 km/h quantum plus interpolation over 2 steps of the noisy signal (noise std 0.45 rad/s)
    err = np.abs(log.omega - np.interp(log.t, sim["t"], sim["omega"]))
    assert np.count_nonzero(err > 4.0) <= 3 * 2  # an outlier spreads over at most 2 grid points
    # torque: zero-order hold, so every value is one of the simulated commands (through kPa and the factor)
    nearest = np.min(np.abs(log.T_b[:, None] - sim["T_b"][None, :]), axis=1)
    assert nearest.max() <= 1e-9 * sim["T_b"].max()


def test_white_wheel_noise_is_the_sensor_noise_at_each_logged_sample():
    """``--white-wheel-noise``: the real-like wheel speed is the true one at each logged instant plus the sensor's
    noise drawn there, white and of the simulator's std at any logger rate. The default export interpolates the
    simulated (noisy, 100 Hz) measurement instead, as a logger that resamples a bus signal does: where an instant falls
    between two clean samples that halves the noise's variance, and near 100 Hz neighbouring samples correlate."""
    case = ind.draw_cases(4, seed=3, real=True)[0]
    sim = simulate_case(case)
    std = float(np.sqrt(ind.OMEGA_NOISE_VAR))
    figures = {}
    for noise in (std, None):
        real = {"rate_hz": 97.0, "outliers": 0, "wheel_quantum_kmh": None, "wheel_noise_std": noise}
        export = ind.real_export(dataclasses.replace(case, real=real))
        s = export.truth["instants"]
        radius = export.truth["spec"]["radius"]
        e = export.columns["wheel_rl(kmph)"] / (radius * 3.6) - np.interp(s, sim["t"], sim["omega_true"])
        figures[noise] = (float(np.std(e)), float(np.corrcoef(e[:-1], e[1:])[0, 1]))
    (sd, ac), (sd_old, ac_old) = figures[std], figures[None]
    assert abs(sd / std - 1.0) < 0.1 and abs(ac) < 0.12  # white, of the sensor's std (n ~ 480 samples)
    assert sd_old < 0.9 * std and ac_old > 0.15  # interpolated: smaller and correlated


@pytest.mark.parametrize("flag", list(ind.ARTIFACT_OPTIONS))
def test_artifact_options_draw_the_same_cases_and_need_real(flag):
    setting = ind.ARTIFACT_OPTIONS[flag][0]
    plain = ind.draw_cases(6, seed=3, real=True)
    other = ind.draw_cases(6, seed=3, real=True, artifacts=setting)
    assert [dataclasses.replace(c, real=None) for c in other] == [dataclasses.replace(c, real=None) for c in plain]
    assert all(w.real == {**p.real, **setting} for w, p in zip(other, plain))
    with pytest.raises(ValueError, match="real"):
        ind.measure(1, 3, artifacts=setting)


def test_combos_carry_several_effects():
    cases = ind.draw_cases(len(ind.COMBOS), seed=4, combos=True)
    assert sorted(tuple(e.name for e in c.effects) for c in cases) == sorted(ind.COMBOS)
    assert all(c.category == c.effects[0].name for c in cases)


def test_selection_figures_of_a_combo_log():
    """Both effects named with their errors; a third, untestable one still counts as named-or-untestable; an effect
    the selection added that is not in the log is counted; a confounded step is listed."""
    from types import SimpleNamespace

    case = ind.draw_cases(len(ind.COMBOS), seed=4, combos=True)[0]
    case = dataclasses.replace(case, effects=(ind.Effect("drag", {"c0": 200.0, "c2": 0.4}),
                                              ind.Effect("relaxation_length", {"sigma": 0.4}),
                                              ind.Effect("radius_error", {"r_eff": 0.335})))
    dg = SimpleNamespace(effects=[{"effect": "drag", "params": {"c0": 220.0, "c2": 0.4}},
                                  {"effect": "relaxation_length", "params": {"sigma": 0.5}},
                                  {"effect": "brake_lag", "params": {"tau": 0.02}}],
                         where={"forward_selection": [{"effect": "brake_gain", "z_over_set": 1.0, "added": False,
                                                       "confounded_with": ["drag"]}]})
    out = {"named": ["drag", "relaxation_length", "brake_lag"], "not_testable": ["radius_error"]}
    ind._selection_figures(out, case, dg)
    assert out["extra_named"] == ["brake_lag"]
    assert not out["all_named"] and out["named_or_untestable"]
    assert out["confounded"] == [["brake_gain", "drag"]]
    assert out["effect_errors"]["relaxation_length"] == pytest.approx(0.25, abs=1e-12)
    assert 0.0 < out["effect_errors"]["drag"] < 0.1  # the registry's figure: the drag force at 15 m/s
    assert set(out["effect_errors"]) == {"drag", "relaxation_length"}


@pytest.mark.slow
def test_draws_cover_categories_and_stop_conditions():
    rng = np.random.default_rng(5)
    for cat in CATEGORIES:
        case = draw_independent_case(cat, rng)
        assert 18.0 <= case.v0 <= 30.0
        assert (case.effects == ()) == (cat == "none")
        if cat == "out_of_library":
            assert case.effects[0].name in ind.OUT_OF_LIBRARY_EFFECTS
        elif cat != "none":
            assert case.effects[0].name == cat
        sim = simulate_case(case)
        assert len(sim["t"]) <= int(ind.MAX_DURATION / DT)
        assert sim["v_true"].min() >= ind.V_STOP


def test_bad_inputs_raise_clear_errors():
    with pytest.raises(ValueError, match="unknown effect 'brake_lags'.*brake_lag"):
        Effect("brake_lags", {"tau": 0.1})
    with pytest.raises(ValueError, match="takes parameters"):
        Effect("brake_lag", {"delay": 0.1})
    with pytest.raises(ValueError, match="unknown category.*none"):
        draw_independent_case("friction", np.random.default_rng(0))
    with pytest.raises(ValueError, match="unknown driver.*bosch-abs"):
        draw_independent_case("none", np.random.default_rng(0), driver="abs")


# Mid-range effect sizes, fixed seeds; roads and drivers chosen before looking at any verdict.
SLOW_CASES = [
    ("brake_lag", {"tau": 0.05}, "dry", "bosch-abs", 101),
    ("brake_delay", {"delay": 0.03}, "wet", "bosch-abs", 102),
    ("brake_gain", {"gain": 1.2}, "dry", "pedal", 103),
    ("relaxation_length", {"sigma": 0.4}, "wet", "bosch-abs", 104),
    ("radius_error", {"r_eff": 0.335}, "dry", "pedal", 105),
    ("mu_change", {"t_change": 1.5, "theta_after": 0.6}, "dry", "bosch-abs", 106),
    ("drag", {"c0": 200.0, "c2": 0.4}, "wet", "pedal", 107),
    ("none", {}, "dry", "bosch-abs", 108),
]


def slow_case(category, params, road, driver, seed) -> IndependentCase:
    """A fixed case for the slow test; mu_change's theta_after is a share of the road's theta."""
    rng = np.random.default_rng(seed)
    base = ROADS[road]
    if category == "mu_change":
        params = dict(params, theta_after=params["theta_after"] * base.theta)
    effects = () if category == "none" else (Effect(category, dict(params)),)
    case = draw_independent_case(category, rng, driver=driver, road=base, effects=effects)
    return dataclasses.replace(case, columns=("v", "a_x"))


@pytest.mark.slow
def test_diagnosis_names_independent_effects():
    results = [ind.diagnose_case(slow_case(*c)) for c in SLOW_CASES]
    summary = [(r["category"], r["verdict"], r["right"]) for r in results]
    print(summary)
    assert sum(r["right"] for r in results) >= 7, summary
