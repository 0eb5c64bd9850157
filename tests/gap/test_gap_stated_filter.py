"""A sensor filter the column map states (a data sheet's IMU filter) is undone as stated
(:mod:`fricenv.gap.signals.stated_filter`), instead of the filter the diagnosis would read from the noise roll-off."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.signal import butter, sosfilt, sosfilt_zi

from fricenv.gap.quarter_car.config import DiagnoseConfig
from fricenv.gap.quarter_car.windows import LAG_USE_HZ, NOISE_FLOOR, prepare
from fricenv.gap.signals.filters import deconvolved, group_delay
from fricenv.gap.signals.sensors import condition_channel
from fricenv.logs import QuarterCarLog
from fricenv.logs.sensor_filter import SensorFilter
from fricenv.plants import quarter_car as qc
from tests.gap.test_gap_filter_lag import FS, _braking

ORDER, CUTOFF = 3, 4.0  # the sensor's filter: not the 2nd-order IMU filter the roll-off fit falls back to


def _filtered_log(seed: int) -> tuple[QuarterCarLog, dict]:
    sig = _braking(seed)
    rng, n = sig["rng"], sig["t"].size
    sos = butter(ORDER, CUTOFF, fs=FS * 4, output="sos")  # run at 4x the logger rate, then sampled

    def sensor(x: np.ndarray, std: float) -> np.ndarray:
        fine = np.interp(np.arange(4 * n) / (4 * FS), sig["t"], x) + rng.normal(0.0, std, 4 * n)
        return sosfilt(sos, fine, zi=sosfilt_zi(sos) * fine[0])[0][::4]

    log = QuarterCarLog(t=sig["t"], T_b=sig["T"], omega=sig["omega"] + rng.normal(0.0, 0.3, n),
                        v=sensor(sig["v"], 0.03), a_x=sensor(sig["ax"], 0.1))
    return log, sig


def _ax_error(d, sig) -> float:
    k = slice(50, -10)
    return float(np.sqrt(np.nanmean((d.meas["a_x"][k] - sig["ax"][k]) ** 2)))


@pytest.mark.parametrize("seed", [31, 32])
def test_a_stated_filter_is_undone_as_stated_and_reported(seed):
    log, sig = _filtered_log(seed)
    cfg = DiagnoseConfig(jobs=1)
    stated = prepare(replace(log, sensor_filters={c: SensorFilter(ORDER, CUTOFF) for c in ("v", "a_x")}),
                     qc.PAPER_PARAMS, cfg)
    lag = group_delay(CUTOFF, ORDER, FS, LAG_USE_HZ, False)
    for c in ("v", "a_x"):
        s = stated.sensors[c]
        assert s["filtered"] and s["filter_evidence"] == "column map"
        assert (s["filter"]["order"], s["filter"]["cutoff_hz"]) == (ORDER, CUTOFF)
        assert s["lag_s"] == pytest.approx(lag, rel=1e-12)
    # a_x is the stated filter undone, v advanced by its lag; both far closer to the signal than as logged
    cond = condition_channel(log.a_x, NOISE_FLOOR["a_x"], stated.free_end, True)  # outliers set aside first
    ok = np.isfinite(stated.meas["a_x"])
    np.testing.assert_allclose(stated.meas["a_x"][ok], deconvolved(cond.values, FS, CUTOFF, ORDER)[ok], atol=1e-12)
    raw = float(np.sqrt(np.mean((log.a_x[50:-10] - sig["ax"][50:-10]) ** 2)))
    assert _ax_error(stated, sig) < 0.1 * raw
    assert prepare(log, qc.PAPER_PARAMS, cfg).sensors["a_x"].get("filter_evidence") != "column map"


def test_a_stated_filter_on_a_channel_the_log_lacks_is_ignored():
    log, _ = _filtered_log(33)
    d = prepare(replace(log, a_x=None, sensor_filters={"a_x": SensorFilter(2, 5.0), "v": SensorFilter(2, 5.0)}),
                qc.PAPER_PARAMS, DiagnoseConfig(jobs=1))
    assert "a_x" not in d.sensors and d.sensors["v"]["filter_evidence"] == "column map"
