"""The effect registry: a toy effect registered at run time goes through make_effect, the simulator, the speed
reconstruction, a candidate fit and the validation draw without touching any other library file."""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pytest

from fricenv.effects import registry
from fricenv.effects.quarter_car import EFFECT_PARAMS, EFFECTS, ModelBatch, make_effect, simulate_with_effects
from fricenv.effects.registry import Param, QuarterCarEffect
from fricenv.plants.quarter_car import PAPER_PARAMS as PAPER
from fricenv.plants.tire import WET


@dataclass(frozen=True)
class BrakeDrag:
    """A dragging brake pad: the applied torque carries a residual torque ``T_res`` on top of the command."""

    T_res: float  # residual torque [N m]
    name: ClassVar[str] = "brake_drag"


TOY = QuarterCarEffect(
    BrakeDrag, (Param("T_res", "N m", (0.0, 400.0), 0.0, 1.0, 20.0, field=None),),
    "free rolling or light braking, where the residual torque is a large share",
    lambda ctx: [{"T_res": v} for v in (20.0, 80.0, 200.0)],
    draw=lambda road, rng, p: BrakeDrag(T_res=float(rng.uniform(60.0, 150.0))),
    builtin=False, torque=lambda params, torque: torque + params["T_res"])


@pytest.fixture
def toy():
    with registry.registered(TOY) as entry:
        yield entry
    assert "brake_drag" not in EFFECTS  # unregistered again


def test_a_registered_effect_is_a_library_effect_by_its_name(toy):
    assert "brake_drag" in EFFECTS and EFFECT_PARAMS["brake_drag"] == ("T_res",)
    assert make_effect("brake_drag", T_res=50.0) == BrakeDrag(50.0)
    with pytest.raises(ValueError, match="its parameters are: T_res"):
        make_effect("brake_drag", tau=0.1)
    assert np.array_equal(ModelBatch.nominal(WET, 3).extra["T_res"], np.zeros(3))  # off by default


def test_the_toy_effect_simulates_as_the_torque_it_adds(toy):
    """Its hook adds T_res to the applied torque: the same run as the nominal car under command + T_res."""
    n = 200
    cmd = np.concatenate([np.zeros(40), np.linspace(0.0, 900.0, 60), np.full(100, 900.0)])
    with_toy = simulate_with_effects([make_effect("brake_drag", T_res=120.0)], WET, cmd, 25.0, n)
    shifted = simulate_with_effects([], WET, cmd + 120.0, 25.0, n)
    for k in ("v", "omega", "a_x", "T_applied"):
        np.testing.assert_allclose(with_toy[k], shifted[k], rtol=0, atol=1e-12)


def test_registry_rejects_a_taken_name_a_clashing_parameter_and_a_plugin_without_hook(toy):
    with pytest.raises(ValueError, match="already registered"):
        registry.register(TOY)

    @dataclass(frozen=True)
    class Lagged:
        tau: float
        name: ClassVar[str] = "other_lag"

    with pytest.raises(ValueError, match="tau already used"):
        registry.register(QuarterCarEffect(Lagged, (Param("tau", "s", (0.0, 1.0)),), "-", builtin=False,
                                           torque=lambda params, t: t))

    @dataclass(frozen=True)
    class Hookless:
        x_h: float
        name: ClassVar[str] = "hookless"

    with pytest.raises(ValueError, match="needs a torque or theta hook"):
        registry.register(QuarterCarEffect(Hookless, (Param("x_h", "-", (0.0, 1.0)),), "-", builtin=False))
    with pytest.raises(ValueError, match="must be its spec's fields"):
        registry.register(QuarterCarEffect(Hookless, (Param("y", "-", (0.0, 1.0)),), "-", builtin=False,
                                           torque=lambda params, t: t))


def test_the_toy_effect_is_drawn_and_fitted_by_the_gap_tool(toy):
    """A log with a dragging brake: the validation draw makes the effect, and a candidate fit through the gap
    tool's windows and least squares recovers T_res within 15 %."""
    from fricenv.gap.quarter_car.candidates import fit_candidate
    from fricenv.gap.quarter_car.diagnose import DiagnoseConfig, fit_nominal
    from fricenv.gap.quarter_car.simulate import simulate_log
    from fricenv.gap.quarter_car.stats import fold_data
    from fricenv.gap.quarter_car.validate import _random_effect
    from fricenv.gap.quarter_car.windows import prepare
    from fricenv.plants.quarter_car import PAPER_PARAMS

    effect = _random_effect("brake_drag", WET, np.random.default_rng(3), PAPER_PARAMS)
    assert isinstance(effect, BrakeDrag) and 60.0 <= effect.T_res <= 150.0
    log, _ = simulate_log([effect], WET, "open-loop", seed=4, duration=3.0)
    cfg = DiagnoseConfig(jobs=1, candidates=("brake_drag",))
    d = fold_data(prepare(log, PAPER_PARAMS, cfg), 0)
    nominal = fit_nominal(d, cfg)
    fit = fit_candidate(["brake_drag"], nominal.road_x(), d, cfg)
    assert fit.names[-1] == "T_res"
    assert abs(fit.effect_params()["T_res"] - effect.T_res) / effect.T_res < 0.15
    assert fit.train_mse < nominal.train_mse


@dataclass(frozen=True)
class ThetaStep:
    """A road whose peak factor steps to ``th_sw`` at ``t_sw`` (mu_change without the substep blend)."""

    t_sw: float  # switching time [s]
    th_sw: float  # theta after the switch [-]
    name: ClassVar[str] = "theta_step"


def test_a_plugin_theta_hook_enters_the_speed_reconstruction():
    """The speed reconstruction applies a plug-in's theta hook: a step of theta gives exactly the speed of the
    built-in mu_change with the same switch (the reconstruction switches theta per sample)."""
    from fricenv.gap.quarter_car.simulate import simulate_log
    from fricenv.gap.signals.speed import reconstruct_speed

    entry = QuarterCarEffect(ThetaStep, (Param("t_sw", "s", (0.0, 10.0), np.inf, field=None),
                                         Param("th_sw", "-", (0.03, 1.6), 1.0, field=None)), "-",
                             builtin=False, theta=lambda q, theta, t: np.where(t >= q["t_sw"], q["th_sw"], theta))
    log, _ = simulate_log([make_effect("mu_change", t_change=1.2, theta_after=0.4)], WET, "abs", seed=2,
                          duration=3.0)
    builtin = ModelBatch.from_effects(WET, [make_effect("mu_change", t_change=1.2, theta_after=0.4)])
    with registry.registered(entry):
        plugin = ModelBatch.from_effects(WET, [ThetaStep(1.2, 0.4)])
        nominal = ModelBatch.from_effects(WET, [])
        args = (log.omega, float(log.t[0]), log.dt, 30, PAPER)
        v_plugin, v_nominal = reconstruct_speed(plugin, *args), reconstruct_speed(nominal, *args)
    v_builtin = reconstruct_speed(builtin, *args)
    np.testing.assert_allclose(v_plugin, v_builtin, rtol=0, atol=1e-12)
    assert np.max(np.abs(v_plugin - v_nominal)) > 0.1  # the hook does change the speed
