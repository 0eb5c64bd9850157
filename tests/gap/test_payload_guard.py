"""The payload's false-discovery guard measures the residual's correlation: white noise counts every sample, a
low-passed noise far fewer, and the held-out z shrinks by the square root of the ratio."""

import numpy as np
from scipy.signal import butter, sosfiltfilt

from fricenv.gap.payload.guard import guarded_z, residual_rho2


def test_white_residual_counts_every_sample_and_a_filtered_one_fewer():
    rng = np.random.default_rng(1)
    white = rng.standard_normal((20000, 3))
    scored = np.ones(20000, dtype=bool)
    assert abs(residual_rho2(white, scored, 200) - 1.0) < 0.1
    sos = butter(4, 0.02, output="sos")  # cut-off at 1 % of the sample rate
    coloured = sosfiltfilt(sos, white, axis=0)
    rho2 = residual_rho2(coloured, scored, 200)
    # the sum of the squared autocorrelation of this filter's output, from its impulse response
    ac = np.correlate(sosfiltfilt(sos, np.eye(1, 801, 400)[0]), sosfiltfilt(sos, np.eye(1, 801, 400)[0]), "full")
    assert abs(rho2 - np.sum((ac / ac.max()) ** 2)) < 0.15 * rho2


def test_guarded_z_uses_the_larger_divisor():
    assert guarded_z(8.0, 10.0, 40.0) == 4.0
    assert guarded_z(8.0, 10.0, 5.0) == 8.0
