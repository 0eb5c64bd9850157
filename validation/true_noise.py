"""The noise levels a source drew, as the diagnosis' test sees them: per logged channel, the white-noise standard
deviation at the log's rate with the same low-frequency power (``sqrt(sum_k gamma_k)``, ``gamma_k`` the
autocovariance of the noise sequence on the logged samples). White noise keeps its std; a channel that a logger
low-passes or interpolates between the simulator's samples gets its std times the square root of its integrated
autocorrelation time, the form in which the diagnosis normalises a filtered channel. The chain a real-like export
applies (:mod:`validation.real_artifacts`) is run on a long white sequence drawn at the simulator's rate; a
quantised channel adds ``q^2 / 12``.

This module knows nothing of the tool (numpy and the artifact functions only).
"""

from __future__ import annotations

import math

import numpy as np

from validation.real_artifacts import KMH_PER_MS, QuarterCarArtifacts, imu_lowpass, sample_at, sample_instants

__all__ = ["MC_SECONDS", "low_frequency_std", "real_like_noise", "white_noise"]

MC_SECONDS = 600.0  # length of the white sequence run through a logger's chain [s]
LAG_SPAN_S = 1.0  # autocovariance lags summed [s]: many times the 5 Hz IMU filter's correlation time


def white_noise(stds: dict[str, float], channels) -> dict[str, float]:
    """White noise drawn at each logged sample: its std, for the logged ``channels``."""
    return {c: float(stds[c]) for c in channels}


def low_frequency_std(x: np.ndarray, max_lag: int) -> float:
    """``sqrt(gamma_0 + 2 sum_{k=1..max_lag} gamma_k)`` of a zero-mean noise sequence (autocovariance by FFT)."""
    x = np.asarray(x, dtype=float) - float(np.mean(x))
    n = x.size
    spec = np.abs(np.fft.rfft(x, 2 * n)) ** 2
    ac = np.fft.irfft(spec)[: max_lag + 1] / (n - np.arange(max_lag + 1))
    return float(math.sqrt(max(ac[0] + 2.0 * float(np.sum(ac[1:])), 0.0)))


def real_like_noise(spec: QuarterCarArtifacts, stds: dict[str, float], channels, clean_dt: float,
                    seed: int = 0) -> dict[str, float]:
    """The noise levels of a real-like export's logged channels (``omega`` and those of ``channels``), from white
    noise of ``stds`` drawn at the clean rate and put through the export's chain: ``v`` and ``a_x`` low-passed by
    the IMU filter, every channel sampled at the logger's jittered instants, the wheel speed quantised (or, with
    ``spec.wheel_noise_std``, drawn white at each logged sample).

    :param spec: the export's artifacts; :param stds: the std drawn at the clean rate per channel.
    :param channels: the logged channels; :param clean_dt: the simulator's sample time [s].
    :param seed: seed of the long white sequence (the figure varies by about a percent between seeds).
    """
    if spec.v_rate_hz is not None:
        raise ValueError("real_like_noise: a reference speed held at its own rate (v_rate_hz) is not modelled")
    rng = np.random.default_rng(seed)
    t = np.arange(round(MC_SECONDS / clean_dt)) * clean_dt
    s, _ = sample_instants(float(t[-1]), spec.rate_hz, spec.jitter, 0.0, rng)
    lags = max(1, math.ceil(LAG_SPAN_S * spec.rate_hz))
    out = {}
    if spec.wheel_noise_std is not None:
        out["omega"] = float(spec.wheel_noise_std)
    else:
        out["omega"] = low_frequency_std(sample_at(t, rng.normal(0.0, stds["omega"], t.size), s), lags)
    if spec.wheel_quantum_kmh is not None:
        q = spec.wheel_quantum_kmh / KMH_PER_MS / spec.radius  # [rad/s]
        out["omega"] = math.sqrt(out["omega"] ** 2 + q * q / 12.0)
    fs = 1.0 / clean_dt
    for c in ("v", "a_x"):
        if c not in channels:
            continue
        x = rng.normal(0.0, stds[c], t.size)
        if spec.imu_cutoff_hz is not None:
            x = imu_lowpass(x, fs, spec.imu_cutoff_hz, spec.imu_order)
        out[c] = low_frequency_std(sample_at(t, x, s), lags)
    return out
