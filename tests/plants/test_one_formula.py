"""The physics written once: the Magic Formula, the slip, the ROS2 substep and the slip ODE have one source each,
and every path built on them (numpy, numba-compiled, CasADi) equals that source and an independent reference."""

from __future__ import annotations

import math
import pathlib
import re

import casadi as ca
import numpy as np
import pytest

from estimators.quarter_car_model import AugmentedModel, magic_formula_casadi
from fricenv.plants import compiled, rosenbrock
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import ROADS, ecu_slip, longitudinal_slip, magic_formula, magic_formula_and_dslip

ROOT = pathlib.Path(__file__).resolve().parents[2]
LIBRARY = ("fricenv", "estimators", "agents")
# An arctangent (numpy's, math's or CasADi's spelling).
ARCTAN = re.compile(r"\b(arctan|atan)\s*\(")
# The Magic Formula's sine or slope of ``C`` times an arctangent.
C_ARCTAN = re.compile(r"\bC\s*\*\s*(?:\w+\.)*(?:arctan|atan)\s*\(")
P = qc.PAPER_PARAMS


def _library_files():
    for package in LIBRARY:
        yield from sorted((ROOT / package).rglob("*.py"))


def _writes_the_magic_formula(text: str) -> bool:
    """Whether ``text`` writes the Magic Formula: ``C`` times an arctangent (its sine and its slope), or an
    arctangent inside an arctangent's argument (``atan(B lam - E (B lam - atan(B lam)))``). Other physics may
    use an arctangent (the time of a stop under quadratic drag, :func:`fricenv.envs.scenario.
    effect_limit_distance`)."""
    if C_ARCTAN.search(text):
        return True
    for match in ARCTAN.finditer(text):
        depth, i = 1, match.end()
        while depth and i < len(text):
            if ARCTAN.match(text, i):
                return True
            depth += {"(": 1, ")": -1}.get(text[i], 0)
            i += 1
    return False


def test_the_magic_formula_detector():
    by_hand = "theta * math.sin(C * math.atan(B * lam - E * (B * lam - math.atan(B * lam))))"
    assert _writes_the_magic_formula(by_hand)
    assert _writes_the_magic_formula("np.arctan(bs - E * (bs - np.arctan(bs)))")
    assert _writes_the_magic_formula("angle = C * np.arctan(inner)")
    assert not _writes_the_magic_formula("(math.atan(k * v1) - math.atan(k * v2)) / math.sqrt(a * b)")


def test_the_magic_formula_is_written_in_one_library_file():
    """The Magic Formula (its sin(C atan(...)) and its slope) is written in tire.py alone."""
    holders = {str(f.relative_to(ROOT)) for f in _library_files() if _writes_the_magic_formula(f.read_text())}
    assert holders == {"fricenv/plants/tire.py"}


def _mf_by_hand(lam: float, B: float, C: float, E: float, theta: float) -> float:
    """Eq. (2) of Sui & Johansen written out in this test (the independent reference)."""
    return theta * math.sin(C * math.atan(B * lam - E * (B * lam - math.atan(B * lam))))


def _points(n: int, seed: int):
    rng = np.random.default_rng(seed)
    roads = np.array([r.as_array() for r in ROADS.values()])[rng.integers(len(ROADS), size=n)]
    return rng.uniform(-1.0, 1.0, n), roads


def test_every_magic_formula_path_equals_eq2():
    lam, roads = _points(400, 1)
    B, C, E, theta = roads.T
    ref = np.array([_mf_by_hand(*row) for row in zip(lam, B, C, E, theta)])
    np.testing.assert_allclose(magic_formula(lam, B, C, E, theta), ref, rtol=1e-13, atol=1e-15)
    assert np.array_equal(magic_formula_and_dslip(lam, B, C, E, theta)[0], magic_formula(lam, B, C, E, theta))
    comp = np.array([compiled.magic_formula_f(*row) for row in zip(lam, B, C, E, theta)])
    np.testing.assert_allclose(comp, ref, rtol=1e-13, atol=1e-15)
    sx = ca.SX.sym("x", 5)
    f = ca.Function("mf", [sx], [magic_formula_casadi(sx[0], sx[1], sx[2], sx[3], sx[4])])
    cas = np.array([float(f(np.array(row))) for row in zip(lam, B, C, E, theta)])
    np.testing.assert_allclose(cas, ref, rtol=1e-13, atol=1e-15)


def test_the_slip_derivative_equals_central_differences():
    lam, roads = _points(200, 2)
    lam = np.clip(lam, -0.98, 0.98)
    B, C, E, theta = roads.T
    d = 1e-6
    fd = (magic_formula(lam + d, B, C, E, theta) - magic_formula(lam - d, B, C, E, theta)) / (2 * d)
    np.testing.assert_allclose(magic_formula_and_dslip(lam, B, C, E, theta)[1], fd, rtol=1e-6, atol=1e-6)


def test_slip_definitions():
    """Eq. (3) braking slip, Li-Du-Li traction slip with the sign flipped, the floor; the ECU's estimate."""
    r = P.r
    assert longitudinal_slip(20.0, 20.0 * 0.9 / r, r) == pytest.approx(0.1, rel=1e-14)
    assert longitudinal_slip(10.0, 12.5 / r, r) == pytest.approx(-(12.5 - 10.0) / 12.5, rel=1e-14)
    assert longitudinal_slip(0.0, 0.0, r) == 0.0 and longitudinal_slip(0.05, 0.0, r) == pytest.approx(0.5)
    assert ecu_slip(20.0 * 0.8 / r, 20.0, r) == pytest.approx(0.2, rel=1e-14)
    assert ecu_slip(0.0, 0.0, r, 0.5) == 1.0 and ecu_slip(0.1 / r, 0.0, r, 0.5) == pytest.approx(0.8)


def _dense_ros2(v: float, w: float, Tb: float, road: np.ndarray, h: float) -> tuple[float, float]:
    """ROS2 with a dense 2x2 solve of (I - gamma h A) k = b, A from :func:`quarter_car.jacobian`, and the lock
    event and v >= 0 as the module docstring states them (the reference of the closed form)."""
    g = 1.0 + 1.0 / math.sqrt(2.0)
    A = np.array(qc.jacobian(v, w, road, P), dtype=float).reshape(2, 2)
    M = np.eye(2) - g * h * A
    k1 = np.linalg.solve(M, np.array(qc.derivatives(v, w, Tb, road, P), dtype=float))
    f2 = np.array(qc.derivatives(v + h * k1[0], max(w + h * k1[1], 0.0), Tb, road, P), dtype=float)
    k2 = np.linalg.solve(M, f2 - 2.0 * k1)
    v1, w1 = v + h * (1.5 * k1[0] + 0.5 * k2[0]), w + h * (1.5 * k1[1] + 0.5 * k2[1])
    if w1 < 0.0:
        frac = w / (w - w1)
        v1 = v + frac * (v1 - v) - (1.0 - frac) * h * P.Fz * _mf_by_hand(1.0, *road) / P.m
        w1 = 0.0
    return max(v1, 0.0), w1


def test_the_ros2_closed_form_equals_a_dense_solve_of_the_same_stages():
    rng = np.random.default_rng(3)
    n, h = 600, 0.002
    _, roads = _points(n, 4)
    v = rng.uniform(0.05, 40.0, n)
    w = v / P.r * rng.uniform(0.0, 1.3, n)
    Tb = rng.uniform(-500.0, 3000.0, n)
    B, C, E, th = roads.T
    got_v, got_w, _ = rosenbrock.ros2_substep(v, w, Tb, B, C, E, th, magic_formula(1.0, B, C, E, th), h, P.r, P.m,
                                              P.J, P.Fz)
    ref = np.array([_dense_ros2(v[i], w[i], Tb[i], roads[i], h) for i in range(n)])
    assert np.sum(ref[:, 1] == 0.0) > 10  # the lock event is exercised
    np.testing.assert_allclose(got_v, ref[:, 0], rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(got_w, ref[:, 1], rtol=1e-10, atol=1e-9)


def test_the_casadi_slip_ode_equals_the_numeric_one():
    model = AugmentedModel(estimated=("theta", "B", "C", "E"))
    x, Tb = ca.SX.sym("x", model.nx), ca.SX.sym("Tb")
    rhs = ca.Function("rhs", [x, Tb], [ca.vertcat(*model.rhs_sx(x, Tb))])
    lam, roads = _points(100, 5)
    rng = np.random.default_rng(6)
    v, torque = rng.uniform(3.0, 40.0, 100), rng.uniform(0.0, 2500.0, 100)
    for i in range(100):
        B, C, E, theta = roads[i]
        sym = np.asarray(rhs(np.array([v[i], abs(lam[i]), theta, B, C, E]), torque[i])).ravel()
        num = qc.slip_form_derivatives(v[i], abs(lam[i]), torque[i], roads[i], P)
        np.testing.assert_allclose(sym, num, rtol=1e-13, atol=1e-12)
