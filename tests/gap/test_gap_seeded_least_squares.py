"""A least-squares run takes the residuals at its start from the start search of
:func:`fricenv.gap.quarter_car.fitting.fit` instead of simulating them again. Allowed only because a row of a batched
``window_residuals`` call equals the same parameter set evaluated alone, bit for bit (the windows are simulated
element by element): the run's path, and so the fitted parameters, stay exactly those of an unseeded run."""

import numpy as np
import pytest

from fricenv.effects.quarter_car import make_effect
from fricenv.gap.quarter_car import fitting
from fricenv.gap.quarter_car.config import DiagnoseConfig
from fricenv.gap.quarter_car.fitting import bounds, effect_start_matrix, least_squares_run
from fricenv.gap.quarter_car.params import param_names
from fricenv.gap.quarter_car.simulate import simulate_log
from fricenv.gap.quarter_car.stats import fold_data
from fricenv.gap.quarter_car.windows import prepare, window_residuals
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import DRY, WET

P = qc.PAPER_PARAMS
CFG = DiagnoseConfig(jobs=1, max_nfev=6)
# the effects cover every start state the nuisance fit can have (speed logged or not, a transient slip, a delayed
# and lagged command)
EFFECTS = [[], ["brake_lag", "brake_delay"], ["relaxation_length"], ["brake_gain", "drag"]]


def _fold(write_v: bool):
    log, _ = simulate_log([make_effect("brake_lag", tau=0.04)], WET, "abs", seed=5, duration=2.0, write_v=write_v)
    return fold_data(prepare(log, P, DiagnoseConfig(jobs=1)), 1)


def _counting(monkeypatch) -> list:
    """Count the parameter sets ``fitting`` simulates (rows of its window_residuals calls)."""
    rows: list = []

    def counted(effects, names, X, d, widx=None, per_channel=False):
        rows.append(len(np.atleast_2d(X)))
        return window_residuals(effects, names, X, d, widx, per_channel)

    monkeypatch.setattr(fitting, "window_residuals", counted)
    return rows


@pytest.mark.parametrize("write_v", [True, False])
@pytest.mark.parametrize("effects", EFFECTS, ids=lambda e: "+".join(e) or "nominal")
def test_a_row_of_a_batch_equals_its_parameter_set_alone(write_v, effects):
    d = _fold(write_v)
    names = param_names(effects)
    starts = effect_start_matrix(effects, WET.as_array(), d)
    train = np.flatnonzero(~d.test)
    batch = window_residuals(effects, names, starts, d, train)
    assert len(starts) >= 4
    for i in range(len(starts)):
        np.testing.assert_array_equal(batch[i], window_residuals(effects, names, starts[i:i + 1], d, train)[0])


def _runs(monkeypatch, effects: list, x0: np.ndarray, d) -> tuple:
    """One least-squares run from ``x0`` without and one with the residuals at ``x0`` given: (unseeded result,
    seeded result, parameter sets each simulated)."""
    names = param_names(effects)
    lo, hi = bounds(names, d)
    train, fidx = np.flatnonzero(~d.test), np.arange(len(names))
    r0 = window_residuals(effects, names, x0, d, train)[0].ravel()
    rows = _counting(monkeypatch)
    plain = least_squares_run(effects, names, x0.copy(), fidx, lo, hi, train, d, CFG)
    unseeded = sum(rows)
    rows.clear()
    seeded = least_squares_run(effects, names, x0.copy(), fidx, lo, hi, train, d, CFG, r0)
    return plain, seeded, unseeded, sum(rows)


@pytest.mark.parametrize("effects", EFFECTS[1:3], ids=lambda e: "+".join(e))
def test_a_seeded_run_ends_where_the_unseeded_one_does_with_one_simulation_less(monkeypatch, effects):
    d = _fold(True)
    x0 = effect_start_matrix(effects, DRY.as_array(), d)[0]
    lo, hi = bounds(param_names(effects), d)
    assert np.all((x0 > lo) & (x0 < hi)), "the start must lie inside its bounds"
    plain, seeded, unseeded, rows = _runs(monkeypatch, effects, x0, d)
    np.testing.assert_array_equal(seeded[0], plain[0])
    assert seeded[1] == plain[1]
    assert rows == unseeded - 1  # the start's residuals came from r0


def test_a_start_on_its_bound_is_evaluated_where_the_run_moves_it(monkeypatch):
    d = _fold(True)
    effects = ["brake_lag"]
    names = param_names(effects)
    x0 = effect_start_matrix(effects, WET.as_array(), d)[0]
    x0[names.index("tau")] = bounds(names, d)[0][names.index("tau")]  # the run starts 1e-12 inside, not at r0
    plain, seeded, unseeded, rows = _runs(monkeypatch, effects, x0, d)
    np.testing.assert_array_equal(seeded[0], plain[0])
    assert rows == unseeded  # r0 was not used


def test_fit_seeds_each_run_with_its_own_start(monkeypatch):
    d = _fold(True)
    effects = ["brake_lag", "brake_gain"]
    names = param_names(effects)
    starts = effect_start_matrix(effects, DRY.as_array(), d)
    rows = _counting(monkeypatch)
    x = fitting.fit(effects, names, starts, d, CFG, runs=2)
    seeded = sum(rows)
    rows.clear()
    run = fitting.least_squares_run
    monkeypatch.setattr(fitting, "least_squares_run", lambda *args: run(*args[:9]))  # r0 dropped
    plain = fitting.fit(effects, names, starts, d, CFG, runs=2)
    np.testing.assert_array_equal(x, plain)  # a wrong row as r0 would send a run elsewhere
    assert seeded <= sum(rows) - 1  # at least one run started inside its bounds and was not simulated again
