"""The payload diagnosis on logs from a second simulator written from the paper alone (validation.payload_sim):
its integrator checked against a closed form and solve_ivp, no effect on its nominal logs whatever the timing
convention, a vision delay read within 15 % or 5 ms, report times from the first sample, and the oracle of what the
data show."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fricenv.gap.payload.diagnose import diagnose_payload
from fricenv.logs import read_log
from validation import payload_sim as ps
from validation.payload_oracle import payload_shown


def _fast(rng: np.random.Generator) -> ps.MultiSine:
    """Four sines per element up to 40 rad/s (6.4 Hz). Sampled at 10 ms, their second differences correlate like a
    low-passed channel's: drawn with seed 0, the F/T read as filtered with a 9 ms lag that only a vision delay could
    undo, and this nominal log came back vision_delay (9 ms; 4 ms with the reading averaged over the sample)."""
    return ps.MultiSine(tuple(tuple((sc * rng.uniform(0.2, 1.0), rng.uniform(1, 40), rng.uniform(0, 6.28))
                                    for _ in range(4)) for sc in (1, 1, 2)))


def _diagnose(tmp_path, recipe: ps.PayloadRecipe, seed: int | np.random.Generator):
    cols = ps.simulate(recipe, np.random.default_rng(seed))
    path = tmp_path / f"log{seed}.csv"
    ps.write_csv(path, cols)
    return diagnose_payload(read_log(path, "payload"))


def test_integrator_matches_the_closed_form_and_solve_ivp():
    wr = ps.random_excitation(np.random.default_rng(3))
    t = np.arange(601) * 0.01  # the simulator's 10 ms rows
    x = ps.states_at(t, wr)
    assert np.max(np.abs(x[:, 0] - ps.theta_closed_form(t, wr))) < 1e-9

    def f(tt, s):
        M, fx, fy = wr(tt)
        c, si = math.cos(s[0]), math.sin(s[0])
        return [s[3], s[4], s[5], (M - ps.RHO[1] * fx + ps.RHO[0] * fy) / ps.INERTIA,
                (c * fx - si * fy) / ps.MASS, (si * fx + c * fy) / ps.MASS]

    ref = solve_ivp(f, (0, 6.0), np.zeros(6), t_eval=t, method="DOP853", rtol=1e-11, atol=1e-12).y.T
    assert np.max(np.abs(x[:, 1:3] - ref[:, 1:3])) < 1e-9


def test_averaged_reading_is_the_mean_of_the_wrench_over_the_sample():
    wr = ps.paper_excitation()
    for t in (0.5, 1.3):
        fine = np.linspace(t - 0.01, t, 2001)
        assert np.allclose(wr.mean_over(t, 0.01), np.trapezoid(wr(fine), fine, axis=0) / 0.01, atol=1e-9)


@pytest.mark.parametrize(("fast", "kw"), [
    (True, {}),
    (True, {"ft_sample": "mean"}),
    (False, {"ft_sample": "mean", "t0": 1.7e9}),
], ids=["fast", "fast-averaged", "paper-averaged-epoch"])
def test_a_nominal_log_from_the_independent_simulator_gets_no_effect(tmp_path, fast, kw):
    rng = np.random.default_rng(0)
    recipe = ps.PayloadRecipe(excitation=_fast(rng) if fast else ps.paper_excitation(), **kw)
    dg = _diagnose(tmp_path, recipe, rng)
    assert dg.verdict == "none", (dg.verdict, dg.params, dg.gap_before)


def test_a_vision_delay_reads_within_fifteen_percent_or_five_ms_and_times_start_at_the_first_sample(tmp_path):
    recipe = ps.PayloadRecipe(excitation=ps.paper_excitation(), delay=0.04, t0=1.7e9)
    dg = _diagnose(tmp_path, recipe, seed=5)
    assert dg.verdict == "vision_delay"
    assert abs(dg.params["delay"] - 0.04) <= 0.005
    assert dg.where["time_base"] == {"origin": "first_sample", "offset_s": pytest.approx(1.7e9)}
    assert all(0.0 <= s["t_start"] < s["t_end"] <= recipe.duration for s in dg.where["segments"])


@pytest.mark.parametrize(("delay", "shown"), [(0.05, True), (0.0005, False)])
def test_the_oracle_shows_a_large_delay_and_not_a_sub_millisecond_one(tmp_path, delay, shown):
    recipe = ps.PayloadRecipe(excitation=ps.paper_excitation(), delay=delay)
    dg = _diagnose(tmp_path, recipe, seed=2)
    assert payload_shown(dg, {"shift": delay}, ps.true_noise(recipe), 1) is shown
