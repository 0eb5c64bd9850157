"""The compiled window simulator (fricenv.effects.kernels) against the numpy EffectSimulator, quarter_car.step and
relaxation_step: the same formula, so equal to 1e-12 of each channel's magnitude; plug-in effects with Python
hooks fall back to the numpy simulator."""

from dataclasses import replace

import numpy as np
import pytest

from fricenv.effects import kernels, registry
from fricenv.effects.quarter_car import EffectSimulator, ModelBatch
from fricenv.effects.relaxation import relaxation_step
from fricenv.plants import compiled, rosenbrock
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import DRY, WET, magic_formula

P = qc.PAPER_PARAMS
N_LOG, H, DT, SUBSTEPS, T0 = 300, 11, 0.01, 5, 0.3
RTOL = 1e-12

# effect name -> ModelBatch fields of a batch of n (drawn from rng)
EFFECT_DRAWS = {
    "brake_lag": lambda rng, n: {"tau": rng.uniform(0.0, 0.08, n)},
    "brake_delay": lambda rng, n: {"delay": rng.uniform(0.0, 0.05, n)},
    "brake_gain": lambda rng, n: {"gain": rng.uniform(0.6, 1.4, n)},
    "mu_change": lambda rng, n: {"t_change": np.where(rng.uniform(size=n) < 0.7, rng.uniform(0.3, 3.2, n), np.inf),
                                 "theta_after": rng.uniform(0.3, 1.0, n)},
    "drag": lambda rng, n: {"c0": rng.uniform(0.0, 80.0, n), "c2": rng.uniform(0.0, 0.6, n)},
    "radius_error": lambda rng, n: {"r_eff": rng.choice([0.29, P.r, 0.315, 0.33], n)},
    "relaxation_length": lambda rng, n: {"sigma": rng.uniform(0.05, 0.6, n)},
    "brake_fade": lambda rng, n: {"fade": rng.uniform(0.0, 2e-5, n)},
    "load_transfer": lambda rng, n: {"load": rng.uniform(-0.3, 0.5, n)},
    "sliding_speed_friction": lambda rng, n: {"slide": rng.uniform(0.0, 0.1, n)},
}


def _batch(effects, n, seed, road=WET):
    rng = np.random.default_rng(seed)
    values = {}
    for e in effects:
        values.update(EFFECT_DRAWS[e](rng, n))
    return replace(ModelBatch.nominal(road, n, P), **values)


def _commands(seed):
    """A hard ABS-like command log: ramps, full applications that lock the wheel, releases to zero."""
    rng = np.random.default_rng(seed)
    base = np.clip(np.cumsum(rng.normal(0.0, 120.0, N_LOG)), 0.0, 1800.0)
    base[rng.uniform(size=N_LOG) < 0.1] = 0.0  # sudden releases (the refinement's cases at low speed)
    base[rng.uniform(size=N_LOG) < 0.1] = 2500.0  # hard applications (lock-ups)
    return base


def _starts(batch, seed):
    rng = np.random.default_rng(seed + 1)
    n = len(batch)
    v0 = rng.uniform(3.0, 30.0, n)
    # low speed: stiff, and lock-ups. Not a car that stops within the window: near v = 0 the plant amplifies
    # rounding (a wheel stopped there spins up again under the floored slip), and numpy's and the compiled
    # transcendentals, equal to 1e-15 per substep, drift apart to ~1e-9 in ten samples; the single-substep test
    # below covers those states
    v0[: n // 8] = rng.uniform(3.0, 4.0, n // 8)
    w0 = v0 / batch.r_eff * (1.0 - rng.uniform(-0.05, 1.0, n))
    return rng.integers(0, N_LOG - H, n), v0, w0


def _numpy_windows(batch, cmd, k0, v0, w0, Ta0=None, lt0=None):
    sim = EffectSimulator(batch, DT, N_LOG, P, SUBSTEPS, T0, commands=cmd)
    sim.reset(v0, w0, k0=k0, Ta=Ta0, lam_t=lt0)
    out = np.empty((3, len(batch), H))
    for j in range(H):
        out[0, :, j], out[1, :, j], out[2, :, j] = sim.omega, sim.v, sim.accel()
        if j < H - 1:
            sim.step()
    return out


def _assert_channels_equal(out, ref):
    for c in range(3):
        scale = np.max(np.abs(ref[c]))
        np.testing.assert_allclose(out[c], ref[c], rtol=0, atol=RTOL * scale)


@pytest.mark.parametrize("effects", [[], *([e] for e in EFFECT_DRAWS),
                                     ["brake_lag", "brake_delay", "brake_gain", "mu_change", "drag", "radius_error"],
                                     ["relaxation_length", "drag", "radius_error", "mu_change"],
                                     ["brake_fade", "load_transfer", "sliding_speed_friction", "brake_delay"]])
def test_compiled_windows_equal_the_effect_simulator(effects):
    batch = _batch(effects, 160, seed=len(effects) + 7 * len("".join(effects)))
    cmd = _commands(3)
    k0, v0, w0 = _starts(batch, 5)
    ref = _numpy_windows(batch, cmd, k0, v0, w0)
    out = kernels.simulate_windows(batch, cmd, k0, v0, w0, None, None, H, DT, T0, SUBSTEPS, P)
    _assert_channels_equal(out, ref)
    assert np.any(ref[0] == 0.0), "the batch should lock some wheels"


def test_compiled_windows_take_the_lag_state_and_transient_slip_given():
    batch = _batch(["brake_lag", "relaxation_length"], 80, seed=11)
    cmd = _commands(4)
    k0, v0, w0 = _starts(batch, 6)
    rng = np.random.default_rng(2)
    Ta0, lt0 = rng.uniform(0.0, 1500.0, 80), rng.uniform(-0.1, 0.9, 80)
    ref = _numpy_windows(batch, cmd, k0, v0, w0, Ta0, lt0)
    out = kernels.simulate_windows(batch, cmd, k0, v0, w0, Ta0, lt0, H, DT, T0, SUBSTEPS, P)
    _assert_channels_equal(out, ref)


def _scalar_step(v, w, Tb, road, h, r):
    B, C, E, th = road
    s1 = float(magic_formula(1.0, B, C, E, 1.0))
    return compiled.substep_refined(v, w, Tb, B, C, E, th, th * s1, h, r, P.m, P.J, P.Fz)


def test_compiled_substep_equals_quarter_car_step_with_lock_ups_and_refinements():
    """Random states, the reference's step, and the count of refined substeps (the test must exercise them)."""
    rng = np.random.default_rng(8)
    n, h = 4000, DT / SUBSTEPS
    v = rng.uniform(0.0, 3.0, n)
    w = v / P.r * rng.uniform(0.0, 1.02, n)
    Tb = np.where(rng.uniform(size=n) < 0.5, 0.0, rng.uniform(0.0, 2500.0, n))
    road = np.where(rng.uniform(size=(n, 1)) < 0.5, DRY.as_array(), WET.as_array())
    ref_v, ref_w = qc.step(v, w, Tb, road, h, P, 1)
    out = np.array([_scalar_step(v[i], w[i], Tb[i], road[i], h, P.r) for i in range(n)])
    np.testing.assert_allclose(out[:, 0], ref_v, rtol=RTOL, atol=RTOL)
    np.testing.assert_allclose(out[:, 1], ref_w, rtol=RTOL, atol=RTOL)
    B, C, E, th = road.T
    broken = rosenbrock.ros2_substep(v, w, Tb, B, C, E, th, magic_formula(1.0, B, C, E, th), h, P.r, P.m, P.J,
                                     P.Fz)[2]
    assert sum(broken) >= 10, "the states should include substeps the reference refines"
    assert np.any(ref_w == 0.0), "the states should include lock-ups"


def test_compiled_relaxation_equals_relaxation_step():
    rng = np.random.default_rng(9)
    n, h = 500, DT / SUBSTEPS
    v = rng.uniform(0.0, 30.0, n)
    w = v / P.r * rng.uniform(-0.1, 1.1, n)
    w[:20] = 0.0
    lt, Tb = rng.uniform(-0.3, 1.0, n), rng.uniform(-200.0, 2500.0, n)
    r, sig = rng.uniform(0.28, 0.33, n), rng.uniform(0.05, 0.8, n)
    c0, c2 = rng.uniform(0.0, 60.0, n), rng.uniform(0.0, 0.5, n)
    road = np.tile(WET.as_array(), (n, 1))
    ref = np.array(relaxation_step(v, w, lt, Tb, road, h, r, sig, c0, c2, P))
    out = np.array([kernels._relax(v[i], w[i], lt[i], Tb[i], *road[i], h, r[i], sig[i], c0[i], c2[i], P.m, P.J,
                                   P.Fz, kernels.RELAX_GAMMA) for i in range(n)]).T
    np.testing.assert_allclose(out, ref, rtol=RTOL, atol=RTOL)


@pytest.mark.parametrize("effects", [["brake_delay", "brake_lag"], ["brake_fade", "brake_lag", "brake_gain"]])
def test_compiled_actuator_run_equals_the_simulator(effects):
    batch = _batch(effects, 40, seed=12)
    cmd = _commands(5)
    sim = EffectSimulator(batch, DT, N_LOG, P, SUBSTEPS, T0, commands=cmd)
    sim.reset(np.full(40, 20.0), np.full(40, 60.0), k0=7, Ta=cmd[7])
    ref = sim.actuator_run(200)
    out = kernels.actuator_run(batch, cmd, 7, cmd[7], 200, DT, SUBSTEPS)
    np.testing.assert_allclose(out, ref, rtol=0, atol=RTOL * np.max(np.abs(ref)))


def test_a_plugin_with_hooks_is_not_compiled_and_the_windows_fall_back_to_numpy():
    """A hooked plug-in: supported() is False and window_residuals gives the numpy path's residuals exactly."""
    from fricenv.gap.quarter_car.diagnose import DiagnoseConfig
    from fricenv.gap.quarter_car.simulate import simulate_log
    from fricenv.gap.quarter_car.windows import prepare, window_residuals
    from tests.effects.test_effect_registry import TOY

    assert kernels.supported(_batch(["brake_lag"], 4, seed=1))
    with registry.registered(TOY):
        batch = ModelBatch.nominal(WET, 4, P)
        assert not kernels.supported(batch)
        log, _ = simulate_log([], WET, "open-loop", seed=4, duration=1.5)
        d = prepare(log, P, DiagnoseConfig(jobs=1))
        names = ("B", "C", "E", "theta", "T_res")
        x = np.array([[*WET.as_array(), 90.0]])
        compiled = window_residuals(["brake_drag"], names, x, d)
        numpy_path = window_residuals(["brake_drag"], names, x, replace(d, compiled=False))
    assert np.array_equal(compiled, numpy_path)
    assert np.max(np.abs(compiled)) > 1.0  # the 90 N m residual torque shows in the residuals


def test_window_residuals_of_the_compiled_and_numpy_paths_agree():
    """The whole residual function (nuisance Gauss-Newton included) on a logged stop with every channel."""
    from fricenv.effects.quarter_car import make_effect
    from fricenv.gap.quarter_car.diagnose import DiagnoseConfig
    from fricenv.gap.quarter_car.simulate import simulate_log
    from fricenv.gap.quarter_car.windows import prepare, window_residuals

    log, _ = simulate_log([make_effect("brake_delay", delay=0.03)], WET, "abs", seed=2, duration=2.0)
    d = prepare(log, P, DiagnoseConfig(jobs=1))
    names = ("B", "C", "E", "theta", "delay", "tau")
    x = np.array([[*WET.as_array(), 0.02, 0.03], [*WET.as_array()[:3], 0.7, 0.04, 0.0]])
    effects = ["brake_delay", "brake_lag"]
    compiled = window_residuals(effects, names, x, d)
    numpy_path = window_residuals(effects, names, x, replace(d, compiled=False))
    np.testing.assert_allclose(compiled, numpy_path, rtol=0, atol=1e-9 * np.max(np.abs(numpy_path)))
    assert d.compiled and DiagnoseConfig().compiled


def test_the_thread_count_does_not_change_the_windows():
    batch = _batch(["brake_lag", "relaxation_length", "drag"], 120, seed=13)
    cmd = _commands(6)
    k0, v0, w0 = _starts(batch, 7)
    one = kernels.simulate_windows(batch, cmd, k0, v0, w0, None, None, H, DT, T0, SUBSTEPS, P, threads=1)
    two = kernels.simulate_windows(batch, cmd, k0, v0, w0, None, None, H, DT, T0, SUBSTEPS, P, threads=2)
    assert np.array_equal(one, two) and np.all(np.isfinite(one))


def test_repeat_stands_for_the_repeated_batch():
    batch = _batch(["brake_delay", "mu_change", "radius_error"], 30, seed=14)
    full = batch.repeat(4)
    cmd = _commands(7)
    k0, v0, w0 = _starts(full, 8)
    expected = kernels.simulate_windows(full, cmd, k0, v0, w0, None, None, H, DT, T0, SUBSTEPS, P)
    out = kernels.simulate_windows(batch, cmd, k0, v0, w0, None, None, H, DT, T0, SUBSTEPS, P, repeat=4)
    assert np.array_equal(out, expected) and out.shape == (3, 120, H)


def test_a_changed_dependency_flushes_the_compiled_cache(monkeypatch, tmp_path):
    """numba checks only kernels.py's own source: a different hash of the compiled-in modules must flush."""
    import os

    import numba

    flushed = []
    monkeypatch.setattr(numba.core.caching.Cache, "flush", lambda self: flushed.append(self))
    stamp = os.path.join(kernels._windows._cache.cache_path, "kernels.deps")
    with open(stamp) as fh:
        digest = fh.read()
    kernels._guard_cache()
    assert flushed == []  # unchanged dependencies: the cache is kept
    with open(stamp, "w") as fh:
        fh.write("an older formula")
    kernels._guard_cache()
    assert len(flushed) >= 5  # every cached kernel function
    with open(stamp) as fh:
        assert fh.read() == digest
