"""A periodic line in the nominal model's wheel-speed residual (fricenv/gap/quarter_car/periodic.py)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from fricenv.gap.quarter_car.periodic import LINE_RATIO, periodic_line
from fricenv.gap.quarter_car.stats import CandidateFit

FS, H, WINDOWS = 100.0, 10, 50


def _nominal(series: np.ndarray) -> CandidateFit:
    """A nominal fit whose held-out residual is ``series`` (omega's block; a second channel of zeros after it)."""
    omega = series.reshape(WINDOWS, H)
    resid = np.concatenate([omega, np.zeros_like(omega)], axis=1)
    return CandidateFit(effect="nominal", names=(), x=np.zeros(0), train_mse=1.0, test_mse=1.0,
                        window_mse=np.ones(WINDOWS), resid=resid)


DATA = SimpleNamespace(horizon=H, dt=1.0 / FS)
T = np.arange(WINDOWS * H) / FS


def test_a_wheel_hop_below_the_noise_level_is_found():
    """A 12 Hz oscillation of 0.5 noise std adds 0.125 noise variances (a gap of 0.35, far below gap_none) yet
    stands out of the spectrum."""
    rng = np.random.default_rng(0)
    line = periodic_line(_nominal(rng.standard_normal(T.size) + 0.5 * np.sin(2 * np.pi * 12.0 * T)), DATA)
    assert line is not None and abs(line["freq_hz"] - 12.0) <= 0.2 and line["ratio"] > LINE_RATIO
    assert line["decided"] is False  # the diagnosis decides


@pytest.mark.parametrize("seed", range(20))
def test_white_noise_shows_no_line(seed):
    assert periodic_line(_nominal(np.random.default_rng(seed).standard_normal(T.size)), DATA) is None


def test_an_error_that_repeats_with_every_window_is_not_a_line():
    """Each window restarts the prediction, so a smooth model error grows the same way in every window: a pattern at
    the window rate (10 Hz here) and its multiples, which no oscillating cause needs to explain."""
    ramp = np.tile(np.linspace(0.0, 2.0, H) ** 2, WINDOWS)
    series = np.random.default_rng(1).standard_normal(T.size) + ramp
    assert periodic_line(_nominal(series), DATA) is None
    assert periodic_line(_nominal(series + 0.5 * np.sin(2 * np.pi * 13.0 * T)), DATA) is not None


def test_a_line_below_the_band_is_left_to_the_braking():
    """Below 8 Hz the braking's own content (a sine driver, ABS cycles) leaks into the residual."""
    series = np.random.default_rng(2).standard_normal(T.size) + 0.8 * np.sin(2 * np.pi * 5.0 * T)
    assert periodic_line(_nominal(series), DATA) is None


@pytest.mark.slow
def test_a_load_oscillation_under_the_gap_threshold_reads_unexplained():
    """omega-only tuning log (independent simulator seed 3000, log 12): a 10.7 Hz load oscillation of 19 % leaves a
    nominal gap of 0.86 noise units, below gap_none, and no candidate is significant; before the line test the
    verdict was `none`."""
    import tempfile

    from fricenv.gap.quarter_car.diagnose import DiagnoseConfig, diagnose_file
    from validation import independent_sim as ind

    case = ind.draw_cases(40, 3000, columns=())[12]
    assert case.effects[0].name == "load_oscillation"
    with tempfile.TemporaryDirectory() as tmp:
        path, _ = ind._diagnosable_log(tmp, case)
        dg = diagnose_file(path, cfg=DiagnoseConfig(jobs=1))
    line = dg.where["periodic"]
    assert dg.verdict == "unexplained" and line["decided"]
    assert abs(line["freq_hz"] - case.effects[0].params["freq"]) < 0.3
