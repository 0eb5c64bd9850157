"""The payload's false-discovery guard: a candidate's held-out evidence judged again with the effective sample count
read from the nominal model's own residual, not only from the white-noise propagation of the raw channels' noise.

The significance test (:func:`fricenv.gap.payload.diagnose.improvement_z`) counts ``N / rho2`` independent residuals,
``rho2`` the sum of the squared autocorrelation of white raw noise through the diagnosis' filters. A filtered, held
or quantised channel carries noise that is correlated before any filter, so its residual holds fewer independent
samples and noise alone makes larger improvements. The nominal model's residual shows its actual correlation:
where the nominal gap is within the noise, the residual is the noise, and its measured ``rho2`` is the one to use.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ACF_SPAN", "guarded_z", "residual_rho2"]

ACF_SPAN = 4.0  # lags summed: this many periods of the diagnosis' cut-off [-]


def residual_rho2(residual: np.ndarray, scored: np.ndarray, max_lag: int) -> float:
    """Sum over lags ``-max_lag..max_lag`` of the squared autocorrelation of the normalised residual on the scored
    samples, averaged over the channels, less the sum's bias under white noise (``2 max_lag / N``); at least 1.

    :param residual: (n, 3) normalised residual; :param scored: (n,) the scored samples.
    :param max_lag: largest lag [samples].
    """
    r = residual[scored]
    n = r.shape[0]
    max_lag = int(min(max_lag, n // 4))
    if max_lag < 1:
        return 1.0
    x = r - r.mean(axis=0)
    spec = np.abs(np.fft.rfft(x, 2 * n, axis=0)) ** 2
    ac = np.fft.irfft(spec, axis=0)[: max_lag + 1]
    ac = ac / np.maximum(ac[0], 1e-300)
    rho2 = 1.0 + 2.0 * np.sum(ac[1:] ** 2, axis=0) - 2.0 * max_lag / n
    return float(max(np.mean(rho2), 1.0))


def guarded_z(z: float, design_rho2: float, measured_rho2: float) -> float:
    """The held-out z with the larger of the two effective-sample divisors (z scales as ``1 / sqrt(rho2)``)."""
    return float(z * np.sqrt(design_rho2 / max(measured_rho2, design_rho2)))
