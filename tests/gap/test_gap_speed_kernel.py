"""The compiled speed recursion (fricenv.gap.signals.speed_kernel) against the numpy sample-by-sample reference and the
numpy Newton solve, over road shapes, relaxation, rolling radius, drag and a friction change."""

import numpy as np
import pytest

from fricenv.gap.signals import speed
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import DRY, ICE, WET

from .test_gap_speed import ROWS, _batch, _log


@pytest.mark.parametrize("road,driver,seed", [(DRY, "abs", 1), (WET, "open-loop", 2), (ICE, "abs", 3)])
def test_compiled_recursion_equals_the_numpy_paths(road, driver, seed):
    log, _ = _log(road, driver, seed)
    args = (_batch(ROWS), log.omega, float(log.t[0]), float(log.t[1] - log.t[0]), 20, qc.PAPER_PARAMS)
    compiled = speed.reconstruct_speed(*args, compiled=True)
    assert compiled.shape == (len(ROWS), len(log.omega))
    np.testing.assert_allclose(compiled, speed.reconstruct_speed_sequential(*args), rtol=0, atol=1e-12)
    np.testing.assert_allclose(compiled, speed.reconstruct_speed(*args), rtol=0, atol=1e-9)


def test_an_elements_speed_does_not_depend_on_the_rest_of_the_batch():
    log, _ = _log(DRY, "abs", 4)
    args = (log.omega, float(log.t[0]), float(log.t[1] - log.t[0]), 20, qc.PAPER_PARAMS)
    batch = speed.reconstruct_speed(_batch(ROWS), *args, compiled=True)
    for i, row in enumerate(ROWS):
        np.testing.assert_array_equal(speed.reconstruct_speed(_batch([row]), *args, compiled=True)[0], batch[i])
    assert np.ptp(batch[:, -1]) > 0.1  # the rows' parameters do give different speeds [m/s]
