"""The estimator registry: every entry builds, equals the constructors it replaced, and uses the plant it is given."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from agents.pipeline import assumed_shape
from estimators.base import EstimatorConfigError
from estimators.ekf import QuarterCarEKF
from estimators.ekf_rls import PAPER_CORRECTION_GAIN, QuarterCarEkfRls, TwoAxleEkfRls
from estimators.mhe import RegularizedMHE
from estimators.registry import (
    ESTIMATORS,
    FULL_SHAPE,
    OBSERVATION_ESTIMATORS,
    UnknownEstimatorError,
    get_estimator,
    make_estimator,
)
from estimators.scenarios import ekf_rls_scenario, mhe_case
from estimators.slope_maps import PAPER_MAP
from fricenv.envs.estimator_observation import ESTIMATOR_NAMES, EstimatorObservation
from fricenv.envs.factory import make_braking
from fricenv.plants import sui_johansen as sj
from fricenv.plants.quarter_car import PAPER_PARAMS
from fricenv.plants.tire import DRY
from fricenv.plants.two_axle import TABLE_I

STEPS = 40  # updates compared per estimator (the MHE solves from its 11th)
HEAVY = dataclasses.replace(PAPER_PARAMS, m=400.0, J=1.2, r=0.33, Fz=3900.0)

# What the hand-written factories (paper mhe, bench, the env observation) built before the registry.
OLD = {
    "ekf": lambda est: QuarterCarEKF(estimated=est),
    "mhe": lambda est: RegularizedMHE(estimated=est),
    "mhe-paper": lambda est: RegularizedMHE(estimated=est, arrival="paper", model_error=None),
    "mhe-ekf": lambda est: RegularizedMHE(estimated=est, arrival="ekf", model_error=None, gate=None),
    "mhe-literal": lambda est: RegularizedMHE(estimated=est, weighting="literal", arrival="paper", model_error=None),
    "ekf-rls": lambda est: QuarterCarEkfRls(),
    "ekf-rls-paper-loop": lambda est: QuarterCarEkfRls(correction_gain=PAPER_CORRECTION_GAIN),
    "ekf-rls-paper-map": lambda est: QuarterCarEkfRls(mu_map=PAPER_MAP),
}


def _trace(est, case) -> np.ndarray:
    log = case.log
    Y = np.column_stack([getattr(log, c) for c in est.measurement_columns])
    est.reset()
    rows = []
    for k in range(STEPS):
        e = est.update(Y[k], [log.T_b[k]])
        rows.append([e.values[n] for n in est.names])
    return np.array(rows)


# What the paper commands pass to the entries the env runs with its mismatch settings (fricenv paper mhe, ekf-rls).
PAPER_OPTIONS = {"ekf": {"mismatch_states": ()}, "mhe": {"mismatch_states": ()}, "ekf-rls": {"correction_gain": 0.0}}


@pytest.mark.parametrize("name", sorted(OLD))
def test_entry_equals_the_constructor_it_replaced(name):
    """Bit for bit over the first updates of the paper case (so the paper figures cannot move)."""
    entry = get_estimator(name)
    case = ekf_rls_scenario(noisy=True, seed=3) if entry.family == "ekf-rls" else mhe_case(1, seed=3)
    paper = entry.make(**PAPER_OPTIONS.get(name, {}))
    np.testing.assert_array_equal(_trace(paper, case), _trace(OLD[name](entry.estimated), case))


def test_the_env_entries_carry_the_mismatch_settings():
    for name in ("ekf", "mhe"):
        assert make_estimator(name).model.extras == ("k_T", "a_b", "T_e")
    for name in ("ekf-full", "mhe-full"):
        assert make_estimator(name).model.extras == ("k_T", "a_b")
    assert make_estimator("ekf", mismatch_states=()).model.extras == ()
    assert make_estimator("ekf-rls").core.cfg.K == 20.0


@pytest.mark.parametrize("name, torque_error, gain_walk", [("ekf", True, 0.01), ("mhe", True, 0.01),
                                                           ("ekf-full", False, 0.1), ("mhe-full", False, 0.1),
                                                           ("ekf-ax", False, 0.1), ("mhe-ax", False, 0.1)])
def test_the_brakes_timing_is_the_torque_errors_or_the_brake_gains(name, torque_error, gain_walk):
    # ekf, mhe: a torque error that jumps with the command and fades, a slow brake gain; the full forms and the
    # a_x forms: no torque error, the gain moving fast enough to take the brake's timing
    est = make_estimator(name)
    ekf = getattr(est, "arrival_filter", est)
    k_T = ekf.model.names.index("k_T")
    assert (ekf.torque_error is not None) is torque_error
    assert np.sqrt(ekf.filter.Q[k_T, k_T]) == pytest.approx(gain_walk)
    paper = make_estimator(name, mismatch_states=())  # the paper's model: no brake gain, no torque error
    assert getattr(paper, "arrival_filter", paper).torque_error is None


def test_every_entry_builds_with_its_declared_outputs_and_values():
    assert set(ESTIMATORS) == set(OLD) | {"ekf-full", "mhe-full", "ekf-ax", "mhe-ax"}
    for name, entry in ESTIMATORS.items():
        est = entry.make()
        assert entry.name == name and isinstance(est, entry.cls)
        assert tuple(est.names) == entry.outputs
        assert set(entry.values) == {"v", "slip", "mu", "theta"} and set(entry.values.values()) <= set(entry.outputs)
        if entry.family != "ekf-rls":
            assert est.model.estimated == entry.estimated
    assert get_estimator("mhe-full").estimated == FULL_SHAPE == ("theta", "B", "C", "E")
    assert make_estimator("ekf", estimated=("theta", "B")).model.estimated == ("theta", "B")


def test_the_factory_uses_the_plant_it_is_given():
    """The EKF and MHE models take m, J, r, Fz from the params (the env factories used to drop them)."""
    for name in ("ekf", "mhe", "ekf-full"):
        est = make_estimator(name, HEAVY, dt=0.02)
        assert est.model.p == HEAVY and est.model.dt == 0.02
    x = np.array([20.0, 0.05, 0.6])
    default, heavy = make_estimator("ekf").model, make_estimator("ekf", HEAVY).model
    assert default.h(x) == pytest.approx(20.0 * 0.95 / 0.345, rel=1e-12)
    assert heavy.h(x) == pytest.approx(20.0 * 0.95 / 0.33, rel=1e-12)
    rls = make_estimator("ekf-rls", HEAVY)
    assert (rls.core.cfg.m, rls.core.cfg.I_w, rls.core.cfg.R_w, rls.core.cfg.Fz) == (400.0, 1.2, 0.33, (3900.0,))
    assert isinstance(make_estimator("ekf-rls", TABLE_I), TwoAxleEkfRls)
    with pytest.raises(EstimatorConfigError, match="QuarterCarParams"):
        make_estimator("mhe", TABLE_I)


@pytest.mark.parametrize("name", OBSERVATION_ESTIMATORS)
def test_the_env_estimator_is_built_for_the_env_plant(name):
    env = make_braking(name, params=HEAVY)
    est = env.estimator
    if hasattr(est, "model"):
        assert est.model.p == HEAVY
    else:
        assert est.core.cfg.m == HEAVY.m and est.core.cfg.R_w == HEAVY.r
    assert isinstance(env, EstimatorObservation) and name in ESTIMATOR_NAMES


def test_assumed_shape_is_the_shape_the_estimator_holds():
    assert dict(get_estimator("ekf").assumed_shape) == dict(sj.NOMINAL_SHAPE) == {"theta": 0.6, "B": 12.0,
                                                                                "C": 1.3, "E": 0.0}
    model = make_estimator("mhe").model
    assert {n: model.fixed[n] for n in ("B", "C", "E")} == {"B": 12.0, "C": 1.3, "E": 0.0}
    fam = make_estimator("ekf-rls").core.mu_map
    assert (fam.B, fam.C, fam.E) == (DRY.B, DRY.C, DRY.E)
    assert assumed_shape("ekf-rls") == {"theta": DRY.theta, "B": DRY.B, "C": DRY.C, "E": DRY.E}
    assert assumed_shape("oracle") == dict(sj.NOMINAL_SHAPE)
    with pytest.raises(ValueError, match="no Magic Formula shape"):
        assumed_shape("ekf-rls-paper-map")


def test_unknown_name_lists_the_valid_ones():
    with pytest.raises(UnknownEstimatorError, match="unknown estimator 'kalman'; valid: ekf, mhe") as err:
        get_estimator("kalman")
    assert isinstance(err.value, ValueError)
    for name in ESTIMATORS:
        assert name in str(err.value)
    with pytest.raises(UnknownEstimatorError, match="valid: ekf-rls$"):
        get_estimator("mhe", ("ekf-rls",))
