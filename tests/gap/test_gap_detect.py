"""What size an effect needs to show above a log's noise (:mod:`fricenv.gap.quarter_car.detectability`), and
the payload F/T filter's lag read from its noise (:func:`fricenv.gap.signals.filters.filter_lag`)."""

from __future__ import annotations

import pickle
import warnings

import numpy as np
import pytest
from scipy import signal

from fricenv.effects.quarter_car import make_effect
from fricenv.gap.quarter_car.config import DiagnoseConfig
from fricenv.gap.quarter_car.detectability import LUCK_Z, _scale, plausible_probes
from fricenv.gap.quarter_car.excitation import NotTestable, excitation, untestable
from fricenv.gap.quarter_car.fitting import fit_nominal, refine_noise, score
from fricenv.gap.quarter_car.simulate import NoiseSpec, simulate_log
from fricenv.gap.quarter_car.stats import fold_data
from fricenv.gap.quarter_car.windows import prepare
from fricenv.gap.signals.filters import filter_lag
from fricenv.logs import QuarterCarLog
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import ROADS

CFG = DiagnoseConfig(jobs=1)


def _testability(log: QuarterCarLog) -> NotTestable:
    """The diagnosis' testability step: the nominal model calibrated on fold 0, then the rules and the power
    analysis."""
    d = prepare(log, qc.PAPER_PARAMS, CFG)
    f0 = fold_data(d, 0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        first = fit_nominal(f0, CFG)
        refine_noise(first, f0)
        nominal = score("nominal", [], first.names, first.x, f0, 0.0)
        return untestable(CFG.candidates, excitation(nominal, d, CFG.sig_z))


def _gain_log(noise: float) -> QuarterCarLog:
    base = NoiseSpec()
    spec = NoiseSpec(omega_var=base.omega_var * noise**2, v_std=base.v_std * noise, a_x_std=base.a_x_std * noise)
    log, _ = simulate_log([make_effect("brake_gain", gain=1.3)], ROADS["dry"], driver="open-loop", seed=3,
                          write_v=False, write_ax=False, noise=spec)
    return log


def test_scale_solves_the_power_equation_below_the_cap():
    """Without the soft cap and orthogonal to the road, s_min = (z + sqrt(z^2 + N dn)) / sqrt(S) (D1), the
    windows of largest and smallest gain left out of S and N (as the paired test leaves them out)."""
    rng = np.random.default_rng(0)
    W, M = 12, 10
    a = 0.3 * rng.standard_normal((W, M))
    J = np.zeros((W * M, 1))  # nothing for the road to absorb
    S_w = np.sum(a**2, axis=1)
    keep = (np.arange(W) != np.argmax(S_w)) & (np.arange(W) != np.argmin(S_w))
    S, N = float(np.sum(S_w[keep])), int(np.sum(keep))
    for dn in (0, 1):
        expected = (4.0 + np.sqrt(16.0 + N * dn)) / np.sqrt(S)
        assert _scale(a, J, M, dn, 4.0) == pytest.approx(expected, rel=1e-8)
    # what the road reproduces is no evidence: a signature inside the road's Jacobian is never detectable
    assert _scale(a, a.reshape(-1, 1), M, 0, 4.0) == np.inf


def test_probes_are_the_validation_draws_extremes():
    road = ROADS["dry"]
    low, high = plausible_probes("brake_gain", road, qc.PAPER_PARAMS, 1.0)
    assert 0.75 <= low["gain"] < 0.76 and 1.29 < high["gain"] <= 1.3
    low, high = plausible_probes("mu_change", road, qc.PAPER_PARAMS, 1.7)
    assert low["t_change"] == high["t_change"] == 1.7  # a change time places the effect; it is not a size
    assert low["theta_after"] < road.theta < high["theta_after"] or high["theta_after"] < road.theta


def test_a_large_effect_is_testable_and_ten_times_the_noise_hides_it():
    """The same open-loop braking (omega only) with the paper's noise shows a brake gain of 1.3; with ten times the
    noise no plausible gain would pass the significance test, and the report says so and by how much."""
    clean = _testability(_gain_log(1.0))
    assert "brake_gain" not in clean
    assert 0.0 < clean.detectable["brake_gain"]["gain"] < 0.3  # |gain - 1| detectable below the drawn 0.3
    noisy = _testability(_gain_log(10.0))
    assert noisy["brake_gain"].startswith("below noise: needs |gain - 1| >= ")
    assert noisy.detectable["brake_gain"]["gain"] > 2.0 * 0.3 * (4.0 - LUCK_Z) / 4.0
    assert noisy.detectable["brake_gain"]["gain"] == pytest.approx(10.0 * clean.detectable["brake_gain"]["gain"],
                                                                   rel=0.8)


def test_a_torque_too_small_to_move_the_wheel_cannot_show_an_actuator_effect():
    """Coasting with a dragging brake (2 N m, apply events included, so the registry's event rule lets the actuator
    effects through): they change the wheel speed by far less than its noise, whatever their plausible size."""
    rng = np.random.default_rng(1)
    n, dt = 400, 0.01
    t = dt * np.arange(n)
    Tb = np.where((t > 0.5) & ((t * 2).astype(int) % 2 == 1), 2.0, 0.0)  # on/off: four apply and release events
    v = 20.0 - 0.05 * t
    omega = v / qc.PAPER_PARAMS.r + 0.4 * rng.standard_normal(n)
    out = _testability(QuarterCarLog(t=t, T_b=Tb, omega=omega, v=None, a_x=None))
    for e in ("brake_gain", "brake_lag", "brake_delay"):
        assert out[e].startswith("below noise"), (e, out.get(e))
    assert out.detectable["brake_lag"]["tau"] > 1.0  # a lag of seconds would be needed


def test_not_testable_pickles_with_its_detectable_sizes():
    nt = NotTestable({"brake_lag": "below noise"}, {"brake_lag": {"tau": 0.2}})
    back = pickle.loads(pickle.dumps(nt))
    assert back == {"brake_lag": "below noise"} and back.detectable == {"brake_lag": {"tau": 0.2}}


def test_an_effect_rated_below_noise_that_the_fits_show_is_testable_after_all():
    nt = NotTestable({"brake_gain": "below noise: needs |gain - 1| >= 0.77", "radius_error": "needs v or a_x"},
                     {"brake_gain": {"gain": 0.77}}, {}, below_noise=["brake_gain"])
    assert pickle.loads(pickle.dumps(nt)).below_noise == ("brake_gain",)
    out = nt.shown({"brake_gain", "radius_error", "drag"})
    assert out == {"radius_error": "needs v or a_x"}  # a registry rule stands; only the power analysis is overruled
    assert "0.77" in out.caveats["brake_gain"] and out.below_noise == ()
    assert nt.shown({"drag"}) == nt


@pytest.mark.parametrize(("rate", "cutoff", "order"), [(100.0, 20.0, 2), (200.0, 20.0, 2), (100.0, 10.0, 4)])
def test_filter_lag_is_the_sensor_filters_group_delay(rate, cutoff, order):
    """Noise through a causal Butterworth at 1 kHz, logged at ``rate``: the lag read from the noise roll-off is the
    filter's low-frequency group delay within 10 %."""
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 20.0, 1e-3)
    x = 3.0 * np.sin(2 * np.pi * 0.7 * t) + 0.05 * rng.standard_normal(t.size)
    sos = signal.butter(order, cutoff, fs=1000.0, output="sos")
    y = signal.sosfilt(sos, x)[:: int(1000 / rate)]
    _, gd = signal.group_delay(signal.sos2tf(sos), w=np.linspace(0.01, 4.0, 20), fs=1000.0)
    out = filter_lag(y, rate, 8.0, 4.0)
    assert out is not None and out["order"] == order
    assert out["lag_s"] == pytest.approx(float(np.mean(gd)) / 1000.0, rel=0.1)


def test_filter_lag_of_white_noise_is_none():
    y = np.random.default_rng(2).standard_normal(4000)
    assert filter_lag(y, 100.0, 8.0, 4.0) is None


def test_report_markdown_says_what_the_log_cannot_tell():
    from fricenv.gap.quarter_car.report import _testability_lines

    w = {"not_testable": {"brake_lag": "below noise: needs |tau| >= 0.2"},
         "detectable": {"brake_lag": {"tau": 0.2}, "brake_gain": {"gain": 0.05}}}
    text = "\n".join(_testability_lines(w))
    assert "- `brake_lag`: below noise: needs |tau| >= 0.2" in text
    assert "- `brake_gain`: |gain - off| = 0.05" in text and "tau - off" not in text  # untested: no size line
    assert _testability_lines({}) == []


def test_report_markdown_names_confounded_effects():
    from fricenv.gap.quarter_car.report import _testability_lines

    w = {"forward_selection": [{"effect": "drag", "z_over_set": 1.2, "added": False, "confounded_with": ["brake_gain"]},
                               {"effect": "brake_lag", "z_over_set": 0.3, "added": False}]}
    text = "\n".join(_testability_lines(w))
    assert "- `drag` with `brake_gain`" in text and "brake_lag" not in text


def test_a_brake_gain_the_power_analysis_under_rates_is_still_fitted_and_named(tmp_path):
    """A real-like wheel-speed-only log (tuning seed 3000 of ``tests.independent_sim --real``, log 20: pedal, snow,
    gain 0.77): the power analysis, linearised at the nominal road, rates a brake gain below noise (it acts through
    the wheel's lock-ups). It was not fitted, and the verdict was `none`; fitted all the same, it is significant and
    the verdict, with a caveat instead of a not-testable entry."""
    from fricenv.gap.quarter_car.diagnose import diagnose_file
    from tests import independent_sim as ind

    case = ind.draw_cases(60, 3000, real=True)[20]
    assert case.effects[0].name == "brake_gain" and not case.columns
    path, _ = ind._diagnosable_log(str(tmp_path), case)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dg = diagnose_file(path, cfg=DiagnoseConfig(jobs=1))
    assert dg.verdict == "brake_gain"
    assert "brake_gain" not in dg.where["not_testable"]
    assert dg.where["caveats"]["brake_gain"].startswith("rated below noise")
