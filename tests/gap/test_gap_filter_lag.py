"""A low-passed ``v`` / ``a_x`` (an IMU driver's filter) read from the log itself and realigned by
the filter's lag (:func:`fricenv.gap.signals.filters.shared_lag`, :func:`fricenv.gap.quarter_car.windows.prepare`), and an unfiltered
log left as it was."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import butter, group_delay, sosfilt, sosfilt_zi, sosfreqz

from fricenv.gap.quarter_car.config import DiagnoseConfig
from fricenv.gap.quarter_car.windows import prepare
from fricenv.gap.signals.filters import LAG_TOP, _rolloff, advanced, filter_lag, lag_against, shared_lag
from fricenv.gap.signals.sensors import condition_channel
from fricenv.logs import QuarterCarLog
from fricenv.plants import quarter_car as qc

FS = 50.0  # log rate [Hz]
CUTOFF = 5.0  # the IMU filter's cut-off [Hz]


def _lowpass(x: np.ndarray, order: int = 2, cutoff: float = CUTOFF) -> np.ndarray:
    sos = butter(order, cutoff, fs=FS, output="sos")
    return sosfilt(sos, x, zi=sosfilt_zi(sos) * x[0])[0]


def _true_lag(order: int = 2, cutoff: float = CUTOFF, f_use: float = 1.0) -> float:
    """The digital filter's own group delay, averaged over (0, f_use] [s]."""
    b, a = butter(order, cutoff, fs=FS)
    f = np.linspace(0.05, f_use, 20)
    _, gd = group_delay((b, a), w=f, fs=FS)
    return float(np.mean(gd)) / FS


def _braking(seed: int, n: int = 300) -> dict:
    """A braking log's clean signals: a torque with apply/release cycles, the deceleration it gives (wheel and
    vehicle equations without slip dynamics), the speed and the wheel speed."""
    p = qc.PAPER_PARAMS
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    T = np.where(t > 0.4, 600.0 + 300.0 * np.sin(2 * np.pi * 1.3 * t) + 150.0 * np.sin(2 * np.pi * 0.4 * t + 1), 0.0)
    T = np.maximum(T + rng.normal(0.0, 5.0, n), 0.0)
    ax = -T / (p.r * p.m) - 0.3
    v = 28.0 + np.cumsum(ax) / FS
    omega = v / p.r * (1.0 - 0.02 * (T > 0))
    return {"t": t, "T": T, "ax": ax, "v": v, "omega": omega, "rng": rng}


def _log(sig: dict, filtered: bool, v_std: float = 0.03, ax_std: float = 0.1) -> QuarterCarLog:
    rng = sig["rng"]
    n = sig["t"].size
    v = sig["v"] + rng.normal(0.0, v_std, n)
    ax = sig["ax"] + rng.normal(0.0, ax_std, n)
    if filtered:
        v, ax = _lowpass(v), _lowpass(ax)
    return QuarterCarLog(t=sig["t"], T_b=sig["T"], omega=sig["omega"] + rng.normal(0.0, 0.3, n), v=v, a_x=ax)


@pytest.mark.parametrize("order", [1, 2, 3])
def test_butterworth_lag_is_read_back_from_the_noise_roll_off(order):
    """White noise through a known Butterworth: the roll-off fit gives its group delay within 20 %."""
    rng = np.random.default_rng(7 + order)
    x = _lowpass(rng.normal(0.0, 0.2, 4000), order)
    fit = filter_lag(x, FS, 2.0, 1.0, min_cutoff=2.0, families=(False, True))
    assert fit is not None
    assert fit["lag_s"] == pytest.approx(_true_lag(order), rel=0.2)


@pytest.mark.parametrize("fs", [25.0, 100.0, 1000.0])
def test_digital_roll_off_in_closed_form_equals_scipy_butter_response(fs):
    """The closed-form response of the bilinear Butterworth (pre-warped cut-off) is scipy's filter's, in the band
    the roll-off is read in, for every order and for cut-offs up to the clamp at 0.499 fs."""
    f = np.linspace(0.5, LAG_TOP * fs, 200)
    for order in (1, 2, 3, 4):
        for fc in np.geomspace(0.5, fs, 25):
            _, h = sosfreqz(butter(order, min(fc, 0.499 * fs), fs=fs, output="sos"), worN=f, fs=fs)
            expected = np.log(np.maximum(np.abs(h) ** 2, 1e-300))
            assert np.allclose(np.log(_rolloff(f, fc, order, fs, digital=True)), expected, rtol=0, atol=1e-9)


def test_white_noise_shows_no_roll_off():
    x = np.random.default_rng(3).normal(0.0, 0.2, 4000)
    assert filter_lag(x, FS, 2.0, 1.0, min_cutoff=2.0, families=(False, True)) is None


def test_advanced_reads_the_channel_later_and_keeps_missing_samples_missing():
    t = np.arange(100) / FS
    x = np.sin(2 * np.pi * 0.5 * t)
    y = advanced(x, 2.5)
    np.testing.assert_allclose(y[:-3], np.sin(2 * np.pi * 0.5 * (t[:-3] + 2.5 / FS)), atol=2e-3)
    assert np.all(np.isnan(y[-2:]))  # beyond the last sample
    x[40] = np.nan
    y = advanced(x, 1.0)
    assert np.isnan(y[39]) and np.isfinite(y[38]) and np.isfinite(y[40])
    np.testing.assert_allclose(advanced(x, 0.0)[np.isfinite(x)], x[np.isfinite(x)], rtol=0, atol=1e-12)


def test_lag_against_a_reference_finds_the_filter_delay_and_no_delay_without_filter():
    sig = _braking(11)
    ref = sig["ax"]
    noisy = ref + sig["rng"].normal(0.0, 0.1, ref.size)
    assert lag_against(_lowpass(noisy), ref, FS, (0.3, 4.0), 0.15) == pytest.approx(_true_lag(), abs=0.5 / FS)
    assert lag_against(noisy, ref, FS, (0.3, 4.0), 0.15) <= 0.5 / FS


def test_lag_against_gives_no_bound_where_the_reference_does_not_follow_the_channel():
    """A reference unrelated to the channel (a torque that barely moves the car) bounds nothing: ``inf`` with a
    required fit, where the plain least squares reads a lag it cannot know (0 here)."""
    sig = _braking(11)
    rng = np.random.default_rng(4)
    filtered = _lowpass(sig["ax"] + rng.normal(0.0, 0.1, sig["ax"].size))
    unrelated = rng.normal(0.0, 1.0, sig["ax"].size)
    assert np.isfinite(lag_against(filtered, unrelated, FS, (0.3, 4.0), 0.15))
    assert lag_against(filtered, unrelated, FS, (0.3, 4.0), 0.15, min_fit=0.5) == np.inf
    assert lag_against(filtered, sig["ax"], FS, (0.3, 4.0), 0.15, min_fit=0.5) == pytest.approx(_true_lag(),
                                                                                                abs=0.5 / FS)


def test_shared_lag_takes_the_smallest_upper_bound_and_leaves_unflagged_channels():
    rng = np.random.default_rng(5)
    conds = {"v": condition_channel(_lowpass(rng.normal(0.0, 0.1, 3000)), 1e-3),
             "a_x": condition_channel(rng.normal(0.0, 0.1, 3000), 1e-3)}
    assert conds["v"].filtered and not conds["a_x"].filtered
    out = shared_lag(conds, FS, 2.0, 1.0, bounds={"a_x": 0.02})
    assert out["v"].lag_s == pytest.approx(0.02, abs=1e-12)  # the bound is below the roll-off's lag
    assert out["a_x"] is conds["a_x"]
    assert shared_lag(conds, FS, 2.0, 1.0)["v"].lag_s == pytest.approx(_true_lag(), rel=0.2)
    # a filter read from the roll-off alone (no quiet start) is not certain: the channel is shifted, never inverted
    shifted = shared_lag(conds, FS, 2.0, 1.0, deconvolve=("v",))["v"]
    assert not shifted.certain and shifted.summary()["filter_evidence"] == "roll-off"
    np.testing.assert_array_equal(shifted.values, advanced(conds["v"].values, shifted.lag_s * FS))


def test_a_signal_line_at_the_low_end_of_the_band_does_not_lengthen_the_filter_lag():
    """A speed swinging at 3.2 Hz (a sine-modulated brake) puts a line into the bands read from 2 and 3 Hz, which
    lowers their fitted cut-off (86.6 ms read from them alone, twice the filter's lag); the band from 4.5 Hz is clear
    of it."""
    rng = np.random.default_rng(11)
    t = np.arange(3000) / FS
    conds = {"v": condition_channel(_lowpass(rng.normal(0.0, 0.1, t.size) + 0.2 * np.sin(2 * np.pi * 3.2 * t)), 1e-3)}
    assert conds["v"].filtered
    assert shared_lag(conds, FS, 2.0, 1.0)["v"].lag_s == pytest.approx(_true_lag(), rel=0.2)


def test_prepare_realigns_a_filtered_log_and_leaves_an_unfiltered_one_unchanged():
    sig = _braking(21)
    cfg = DiagnoseConfig(jobs=1)
    d = prepare(_log(sig, filtered=True), qc.PAPER_PARAMS, cfg)
    for c in ("v", "a_x"):
        assert d.sensors[c]["filtered"]
        assert d.sensors[c]["lag_s"] == pytest.approx(_true_lag(), rel=0.25)
    # the realigned channel follows the clean signal far closer than the raw filtered one
    k = slice(50, -10)
    raw = _lowpass(sig["ax"])
    assert np.sqrt(np.nanmean((d.meas["a_x"][k] - sig["ax"][k]) ** 2)) < \
        0.5 * np.sqrt(np.mean((raw[k] - sig["ax"][k]) ** 2))
    sig = _braking(21)
    log = _log(sig, filtered=False)
    d = prepare(log, qc.PAPER_PARAMS, cfg)
    for c in ("v", "a_x"):
        assert "lag_s" not in d.sensors[c] and "filter" not in d.sensors[c] and not d.sensors[c]["filtered"]
        ok = np.isfinite(d.meas[c])
        np.testing.assert_allclose(d.meas[c][ok], getattr(log, c)[ok], rtol=0, atol=1e-12)
        assert d.sensors[c]["noise_std"] == condition_channel(getattr(log, c), 1e-3, d.free_end).noise


def test_a_rough_unfiltered_channel_that_fails_the_difference_test_is_not_filtered_without_a_roll_off():
    """A deceleration with fast cycles (ABS) correlates its differences like a filter would; without a roll-off in
    its noise (or with a bound that says there is no lag) it is not filtered, and is not shifted."""
    t = np.arange(3000) / FS
    x = np.sign(np.sin(2 * np.pi * 6.0 * t)) * np.minimum(1.0, (t % 1.0) * 4) + \
        np.random.default_rng(9).normal(0.0, 0.05, t.size)
    cond = condition_channel(x, 1e-3)
    assert cond.filtered  # the difference test alone is fooled
    out = shared_lag({"a_x": cond}, FS, 2.0, 1.0, bounds={"a_x": 0.0})
    assert not out["a_x"].filtered and out["a_x"].lag_s == 0.0
    np.testing.assert_array_equal(out["a_x"].values, cond.values)


def _true_set_z(case, tmp) -> float:
    """Paired z of the log's TRUE effect set (true road and parameters, no fit) against the cross-fitted calibrated
    nominal model, by the diagnosis' own significance statistic."""
    from fricenv.commands.gap_convert import convert
    from fricenv.effects import registry
    from fricenv.gap.quarter_car.fitting import fit_nominal, refine_noise, score
    from fricenv.gap.quarter_car.params import ROAD_NAMES, param_names
    from fricenv.gap.quarter_car.stats import cross_fitted, fold_data, paired_z
    from fricenv.logs import read_log
    from validation.independent_sim import write_real_log

    csv, mp, truth = write_real_log(tmp / "export", case)
    convert(csv, mp, "quarter-car", str(tmp / "log.csv"))
    cfg = DiagnoseConfig(jobs=1)
    d = prepare(read_log(str(tmp / "log.csv"), "quarter-car"), qc.PAPER_PARAMS, cfg)
    folds = [fold_data(d, j) for j in range(cfg.folds)]
    first = fit_nominal(folds[0], cfg)
    refine_noise(first, folds[0])
    nominal = cross_fitted([score("nominal", [], first.names, first.x, folds[0], 0.0)]
                           + [fit_nominal(f, cfg) for f in folds[1:]], d)
    names = [e.name for e in case.effects]
    x = [truth["road"][k] for k in ROAD_NAMES] + [e.params[k] for e in case.effects
                                                   for k in registry.get(e.name).param_names]
    return paired_z(nominal, score("+".join(names), names, param_names(names), np.array(x), d, 0.0), d)


@pytest.mark.slow
def test_true_two_effect_set_is_significant_on_a_filtered_log_only_once_realigned(tmp_path, monkeypatch):
    """A real-like export (IMU filter 5 Hz on v and a_x, 50 Hz) with a brake gain and drag: the true set started at
    the truth passes the significance rule once the channels are realigned, and did not without (a tuning
    log: the independent simulator's real-like two-effect draw, seed 1801, log 5)."""
    from fricenv.gap.quarter_car import windows
    from validation.independent_sim import draw_cases

    case = draw_cases(8, 1801, real=True, combos=True)[5]
    assert [e.name for e in case.effects] == ["brake_gain", "drag"]
    sig_z = DiagnoseConfig().sig_z
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    assert _true_set_z(case, tmp_path / "a") > sig_z
    monkeypatch.setattr(windows, "shared_lag", lambda conds, *a, **k: dict(conds))  # the channels as logged
    assert _true_set_z(case, tmp_path / "b") < sig_z


def test_a_quiet_start_makes_a_filter_certain_and_white_noise_does_not():
    """On a still stretch the differences of a low-passed channel correlate (about +0.6 here), white noise's read
    -1/2: 12 quiet samples are enough to tell them apart (threshold -1/2 + 3 / sqrt(11) = 0.40)."""
    rng = np.random.default_rng(4)
    quiet = 12
    filtered = _lowpass(np.r_[np.zeros(quiet), np.linspace(0.0, -6.0, 200)] + rng.normal(0.0, 0.1, quiet + 200))
    white = np.r_[np.zeros(quiet), np.linspace(0.0, -6.0, 200)] + rng.normal(0.0, 0.1, quiet + 200)
    assert condition_channel(filtered, 1e-3, quiet).certain
    assert not condition_channel(white, 1e-3, quiet).certain
    assert not condition_channel(filtered, 1e-3, 6).certain  # too short a quiet start: no certainty


def test_a_certain_filter_is_kept_without_a_roll_off_and_realigned_by_its_bound():
    """A filter the quiet start shows stays a filter even when the signal hides its noise roll-off: it is advanced by
    the torque bound when one reads a filter's lag, and left in place (lag 0) but still ``filtered`` (its noise
    then comes from the model's residual) when the only bound is too short for any filter."""
    rng = np.random.default_rng(6)
    x = _lowpass(np.r_[np.zeros(30), np.sin(np.linspace(0.0, 40.0, 400)) * 5.0] + rng.normal(0.0, 0.05, 430))
    cond = condition_channel(x, 1e-3, 30)
    assert cond.certain
    kept = shared_lag({"v": cond}, FS, 2.0, 1.0, bounds={"a_x": 0.05})["v"]
    assert kept.filtered and kept.lag_s == pytest.approx(0.05)
    np.testing.assert_allclose(kept.values[:-5], advanced(cond.values, 0.05 * FS)[:-5])
    none = shared_lag({"a_x": cond}, FS, 2.0, 1.0, bounds={"a_x": 0.0}, deconvolve=("a_x",))["a_x"]
    assert none.filtered and none.lag_s == 0.0
    np.testing.assert_array_equal(none.values, cond.values)


@pytest.mark.parametrize("rate", [FS, 25.0])
def test_deconvolution_restores_a_filtered_deceleration_better_than_a_shift(rate):
    """An IMU filter (2nd order, 5 Hz, run at 100 Hz) on brake applies of 150 ms and 6 Hz ABS cycles, read at the
    logger's rate: undoing the filter (:func:`deconvolved`, the filter :func:`filter_of_lag` derives from its
    delay alone) leaves at most half the error of advancing the channel by that delay, which keeps the smoothing
    that a model would otherwise read as a brake lag."""
    from fricenv.gap.signals.filters import deconvolved, filter_of_lag

    t = np.arange(800) / 100.0
    u = np.clip((t - 1) / 0.15, 0, 1) * -6 + np.clip((t - 3) / 0.15, 0, 1) * 6 + \
        np.where(t > 4, -3 * np.clip(6 * np.abs((t * 6) % 1 - 0.5) - 1, -1, 1), 0.0)
    y = sosfilt(butter(2, CUTOFF, fs=100.0, output="sos"), u)
    step = round(100.0 / rate)
    y, u = y[::step], u[::step]
    lag = float(np.sqrt(2.0) / (2 * np.pi * CUTOFF))  # the analog filter's low-frequency delay [s]
    fc, order, digital = filter_of_lag(None, lag, rate)
    assert (fc, order, digital) == (pytest.approx(CUTOFF), 2, False)
    k = slice(10, -10)
    err = np.sqrt(np.mean((deconvolved(y, rate, fc, order, digital)[k] - u[k]) ** 2))
    shifted = np.sqrt(np.nanmean((advanced(y, lag * rate)[k] - u[k]) ** 2))
    assert err < 0.5 * shifted


@pytest.mark.parametrize("rate", [25.0, FS, 100.0])
def test_an_undone_filter_gives_back_the_sensor_s_white_noise_level(rate):
    """White noise of std 0.1 through a 5 Hz second-order filter, undone (:func:`undone`): the noise level is the
    sensor's own within 10 %. The inverse filter zeroes the band where the filter's gain is below a tenth, which
    holds most of a white noise's second-difference power, so the plain difference-based estimate on the undone
    samples reads it 1.6-12 times too small."""
    from fricenv.gap.core.noise import estimate_noise
    from fricenv.gap.signals.filters import undone

    rng = np.random.default_rng(12)
    x = 0.1 * rng.standard_normal(3000)
    y = sosfilt(butter(2, CUTOFF, fs=rate, output="sos"), x)
    k = undone(condition_channel(y, 1e-4, 0), rate, CUTOFF, 2, True)
    assert k.white and k.summary()["white"]
    assert k.noise == pytest.approx(0.1, rel=0.1)
    assert estimate_noise(k.values) < 0.65 * 0.1


def test_the_filter_certainty_is_the_logs_even_where_no_lag_is_read():
    """One logger filters ``v`` and ``a_x`` alike: when one channel's quiet start makes the filter certain, every
    filtered channel carries that certainty (and so the median-square noise level), also when no lag estimate
    exists and the channels stay where they are."""
    rng = np.random.default_rng(6)
    x = _lowpass(np.r_[np.zeros(30), np.sin(np.linspace(0.0, 40.0, 400)) * 5.0] + rng.normal(0.0, 0.05, 430))
    sure = condition_channel(x, 1e-3, 30)
    unsure = condition_channel(x, 1e-3, 0)  # no quiet start read: filtered by the whole-channel test only
    assert sure.certain and unsure.filtered and not unsure.certain
    out = shared_lag({"v": unsure, "a_x": sure}, FS, 2.0, 1.0, bounds={"a_x": 0.0})
    for c in ("v", "a_x"):
        assert out[c].certain and out[c].lag_s == 0.0 and out[c].summary()["filter_evidence"] == "quiet start"


def test_a_filter_the_torque_cannot_bound_is_read_from_the_noise_on_a_real_like_export():
    """A nominal stop on ice (sine-modulated torque, 0.22 s of free rolling) exported at 29 Hz with the logger's
    5 Hz IMU filter on ``v`` and ``a_x`` (validation/real_artifacts.py): the torque barely moves the car on ice, so
    it cannot bound the filter's lag (its deceleration explains 26 % of ``a_x``'s motion). Read as a bound of 0
    it vetoed the filter the noise shows, and the filter's lag was named a relaxation length (z 12.5); without
    the bound the channels are read as filtered and the verdict is ``none``."""
    from validation.independent_model import Road
    from validation.independent_sim import IndependentCase, diagnose_case

    case = IndependentCase("none", (), Road(4.001966911605736, 2.0, 1.0, 0.10745352459361933, "ice"), "sine",
                           24.19004498203084, 0.22354702982765248, ("v", "a_x"), 0.04914974621819358,
                           0.09811256299955115, 1685753236, real={"rate_hz": 28.993353591426118})
    row = diagnose_case(case)
    assert row["sensors"]["v"]["filtered"] and row["sensors"]["a_x"]["filtered"]
    assert row["verdict"] == "none", row["verdict"]


def test_a_drag_shows_in_an_acceleration_whose_stated_filter_is_undone_on_a_real_like_export():
    """A drag (c0 299 N, c2 0.57 N s^2/m^2) under ABS on a dry road, exported at 30 Hz with the logger's 5 Hz IMU
    filter on ``v`` and ``a_x``, the filter stated in the column map and undone on ``a_x``. Read from the nominal
    model's residual times the square root of that residual's correlation time, the noise level held the drag's
    own error and the drag drowned; read from the undone samples as white noise, the drag is named."""
    from validation.independent_model import Effect, Road
    from validation.independent_sim import IndependentCase, diagnose_case

    drag = {"c0": 299.2062820314693, "c2": 0.5747342767747936}
    case = IndependentCase("drag", (Effect("drag", drag),),
                           Road(10.418913862706429, 1.65, 0.65663, 1.0449329271803325, "dry"), "bosch-abs",
                           26.981941850500107, 0.4782145695537006, ("v", "a_x"), 0.032517745346164875,
                           0.09876856224710395, 1868405061, real={"rate_hz": 29.953673314593022, "state_filter": True})
    row = diagnose_case(case)
    assert row["verdict"] == "drag", row["verdict"]
    assert row["params"]["c0"] == pytest.approx(drag["c0"], rel=0.15)
