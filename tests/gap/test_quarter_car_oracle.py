"""The quarter-car oracle judges a log with the noise levels its source drew, not with the tool's estimate."""

from __future__ import annotations

import math
import warnings
from types import SimpleNamespace

import numpy as np
import pytest

from fricenv.effects.quarter_car import make_effect
from fricenv.gap.quarter_car.config import DiagnoseConfig
from fricenv.gap.quarter_car.fitting import fit_nominal, refine_noise
from fricenv.gap.quarter_car.simulate import OMEGA_NOISE_VAR, simulate_log
from fricenv.gap.quarter_car.windows import prepare
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import ROADS
from validation.quarter_car_oracle import true_model_oracle
from validation.real_artifacts import QuarterCarArtifacts
from validation.true_noise import real_like_noise

CFG = DiagnoseConfig(jobs=1)


def test_raising_the_drawn_noise_makes_a_shown_brake_gain_unshowable_with_the_tools_estimate_untouched():
    """A brake gain of 0.7 on a stand-in log (wheel speed only) passes the significance test at the wheel-speed
    noise the stand-in drew; told that the source drew five times that noise, the same log, the same calibrated
    nominal model and the same estimate of the tool do not show it (the paired z falls with the noise level)."""
    log, _ = simulate_log([make_effect("brake_gain", gain=0.7)], ROADS["dry"], driver="open-loop", seed=3,
                          duration=3.0, write_v=False, write_ax=False)
    d = prepare(log, qc.PAPER_PARAMS, CFG)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        nominal = fit_nominal(d, CFG)
        refine_noise(nominal, d)
    dg = SimpleNamespace(data=d, nominal=nominal)
    estimate = dict(d.sigma)
    road = dict(zip(("B", "C", "E", "theta"), ROADS["dry"].as_array()))
    drawn = math.sqrt(OMEGA_NOISE_VAR)
    at_drawn = true_model_oracle({"brake_gain": {"gain": 0.7}}, road, dg, CFG, {"omega": drawn})
    louder = true_model_oracle({"brake_gain": {"gain": 0.7}}, road, dg, CFG, {"omega": 5.0 * drawn})
    assert at_drawn["detectable"] and not louder["detectable"], (at_drawn, louder)
    assert louder["z_true"] < at_drawn["z_true"] / 3.0
    assert d.sigma == estimate  # the tool's own estimate is not what the oracle judged with


def test_a_filtered_channels_true_level_is_its_white_equivalent():
    """Through a real-like export the 100 Hz white noise of v, low-passed at 5 Hz and logged at 25 Hz, has the
    in-band density of white noise of std * sqrt(25 / 100) at the log's rate; the wheel speed, interpolated at the
    logger's instants, keeps most of its std (and gains the quantisation's q^2 / 12)."""
    spec = QuarterCarArtifacts(rate_hz=25.0, jitter=0.0)
    got = real_like_noise(spec, {"omega": 0.4, "v": 0.04, "a_x": 0.1}, ("v",), 0.01)
    assert got["v"] == pytest.approx(0.04 * math.sqrt(0.25), rel=0.05)
    q = 0.1 / 3.6 / spec.radius
    assert got["omega"] == pytest.approx(math.sqrt(0.4**2 + q * q / 12.0), rel=0.05)  # instants on clean samples
    assert "a_x" not in got
    assert np.isfinite(list(got.values())).all()


@pytest.mark.parametrize("speed_logged", [False, True])
def test_a_radius_error_is_told_from_a_brake_gain_only_where_speed_is_logged(speed_logged):
    """(A2) of fricenv.gap.quarter_car.alternatives: from t, T_b and omega alone a rolling radius r_e gives the data
    of a brake gain (r / r_e)^2 on another road, so no fit of these data can tell the two apart; with v and a_x
    logged the speed shows the radius. The alternative oracle reads that: the brake gain refitted at the true
    noise levels against the true radius error, apart only with the speed logged."""
    from fricenv.gap.quarter_car.stats import CandidateFit
    from validation.quarter_car_oracle import alternative_oracle

    p = qc.PAPER_PARAMS
    r_eff = 1.04 * p.r
    log, _ = simulate_log([make_effect("radius_error", r_eff=r_eff)], ROADS["dry"], driver="open-loop", seed=3,
                          duration=3.0, write_v=speed_logged, write_ax=speed_logged)
    d = prepare(log, p, CFG)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        nominal = fit_nominal(d, CFG)
        refine_noise(nominal, d)
    road = dict(zip(("B", "C", "E", "theta"), ROADS["dry"].as_array()))
    x = np.r_[nominal.x, (p.r / r_eff) ** 2]  # the diagnosis' brake gain, as (A2) predicts it
    gain = CandidateFit(effect="brake_gain", names=(*nominal.names, "gain"), x=x, train_mse=1.0, test_mse=1.0,
                        window_mse=np.ones(1), x_folds=(x,) * int(CFG.folds))
    noise = {"omega": math.sqrt(OMEGA_NOISE_VAR), "v": 0.05, "a_x": 0.1}
    out = alternative_oracle({"radius_error": {"r_eff": r_eff}}, road, SimpleNamespace(data=d, candidates=[gain]),
                             CFG, {c: noise[c] for c in d.channels})
    assert out["alternative"] == "brake_gain"
    assert out["apart"] == speed_logged, out
