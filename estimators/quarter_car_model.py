"""Discrete-time augmented quarter-car model shared by the MHE and the EKF (Sui & Johansen, eqs. (6)-(7), (19)-(20)).

State ``x = (v, lambda, p_1, ..., p_k)``: vehicle speed [m/s], braking slip [-], and any subset of the Magic
Formula parameters ``(theta, B, C, E)`` as constant augmented states (eqs. (19c), (20)); the parameters that are
not estimated are held at fixed values (by default the paper's nominal eq. (18): theta = 0.6, B = 12, C = 1.3,
E = 0).

Continuous dynamics: the slip form eq. (6), :func:`fricenv.plants.quarter_car.slip_ode` with the Magic Formula of
:func:`fricenv.plants.tire.magic_formula`, the same functions evaluated over CasADi (``CASADI_NP``) to give the
symbolic graph the solvers differentiate.
Measurement eq. (7): ``y = omega = v (1 - lambda) / r``.

Discretization: the slip equation is stiff (time constant ``v / (F_z mu'(lambda) (r^2/J + (1-lambda)/m))``, about
3 ms at 20 m/s near zero slip, well below the 10 ms sample), so an explicit RK4 would need many substeps at low
speed. We use the same L-stable two-stage Rosenbrock method (ROS2, Verwer et al. 1999) as the plant, with the exact
2x2 Jacobian of the (v, lambda) block, over ``substeps`` equal substeps per sample (default 3, i.e. 3.3 ms). ROS2 is
second order for any Jacobian approximation (a W-method) and stable however stiff the slip equation gets. Against
the plant over the ABS cases 1-2 the one-step error is at most 4e-4 m/s in v and 1.1e-3 in slip, i.e. 0.05 rad/s in
the predicted wheel speed, a ninth of the measurement noise (tested); 5 substeps halve it, 2 substeps made the
four-parameter MHE of case 3 diverge. Fewer substeps matter because the MHE's cost is dominated by evaluating this
model and its Jacobian over the horizon. After each substep the slip is clipped to [0, 1] (a locked wheel cannot
slip more than 1) and the speed kept above ``V_FLOOR`` in ``1/v`` so that it stays finite; both are outside the
ABS operating range (v > 3 m/s, slip < 0.5) the estimators are run in.

Speed from the accelerometer (``speed_from_a_x=True``): the input is ``(T_b, a_x)`` and the car's speed follows
the measured acceleration, ``v' = a_x``, instead of eq. (6a); the slip follows
:func:`fricenv.plants.quarter_car.slip_ode_given_accel` (eq. (6b) with that ``v'``). The tire model then reaches the
speed only through the wheel: a tire force that lags its slip (a relaxation length) or a brake that lags its
command moves the slip and the parameters, not the car. ``a_b`` (a deceleration the tire does not explain) has no
meaning there: the deceleration is measured.
"""

from __future__ import annotations

import types
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from estimators.tuning import BRAKE_SETTLE_S
from fricenv.plants import sui_johansen as sj
from fricenv.plants.namespace import with_namespace
from fricenv.plants.quarter_car import PAPER_PARAMS, QuarterCarParams, slip_ode, slip_ode_given_accel
from fricenv.plants.rosenbrock import ROS2_GAMMA
from fricenv.plants.tire import magic_formula

__all__ = [
    "BOUNDS",
    "EXTRA_NAMES",
    "NOMINAL",
    "PARAM_NAMES",
    "V_FLOOR",
    "AugmentedModel",
    "magic_formula_casadi",
]

PARAM_NAMES = ("theta", "B", "C", "E")
# Mismatch states a model may carry after the Magic Formula parameters (docs/contracts.md): the random walks
# ``k_T``, the brake gain, and ``a_b``, a deceleration of the car that the tire force does not explain [m/s^2] (drag,
# a slope); and ``T_e``, a torque error of a brake that lags or waits [N m]. The torque on the wheel is
# k_T T_b + T_e; T_e fades over BRAKE_SETTLE_S (the brake reaches its command) and jumps while the commands move
# (the filters' noise on it, estimators.ekf.torque_jump_std).
EXTRA_NAMES = ("k_T", "a_b", "T_e")
EXTRA_NOMINAL = {"k_T": 1.0, "a_b": 0.0, "T_e": 0.0}
# Sui & Johansen eq. (18): nominal values, a priori estimates or fixed values (read-only).
NOMINAL = sj.NOMINAL_SHAPE
# Bounds of Section IV: v >= 0, 0 <= lambda <= 1, 0 <= theta <= 1, 9 <= B <= 15.5, 0 <= C <= 3, -7.5 <= E <= 2.
BOUNDS: dict[str, tuple[float, float]] = {
    "v": (0.0, np.inf),
    "slip": (0.0, 1.0),
    "theta": (0.0, 1.0),
    "B": (9.0, 15.5),
    "C": (0.0, 3.0),
    "E": (-7.5, 2.0),
    "k_T": (0.5, 2.0),
    "a_b": (0.0, 5.0),
    "T_e": (-np.inf, np.inf),
}
V_FLOOR = 0.5  # smallest speed in the estimator model's 1/v (the estimators run above 3 m/s) [m/s]
DEFAULT_SUBSTEPS = 3  # ROS2 substeps per 10 ms sample (5 ms each; see the module docstring)


# CasADi under numpy's names: the plant's plain-math formulas (fricenv.plants.namespace.with_namespace) build the
# symbolic model from the same source as the numeric one.
CASADI_NP = types.SimpleNamespace(arctan=ca.atan, sin=ca.sin, cos=ca.cos, maximum=ca.fmax, minimum=ca.fmin,
                                  where=ca.if_else)
# The Magic Formula, eq. (2), as a CasADi expression (SX or MX): fricenv.plants.tire.magic_formula over CASADI_NP.
magic_formula_casadi = with_namespace(magic_formula, CASADI_NP)
_slip_ode_casadi = with_namespace(slip_ode, CASADI_NP)  # eq. (6): fricenv.plants.quarter_car.slip_ode
_slip_given_accel_casadi = with_namespace(slip_ode_given_accel, CASADI_NP)  # eq. (6b) with v' = a_x


@dataclass(frozen=True)
class AugmentedModel:
    """The augmented quarter-car model for a chosen set of estimated parameters.

    ``estimated`` is any subset of ``PARAM_NAMES``, stored in canonical order (theta, B, C, E); ``fixed`` holds
    the values of the others. Compiled CasADi functions are built on first use and cached per instance.
    """

    estimated: tuple[str, ...] = ("theta",)  # parameters augmented to the state
    dt: float = sj.SAMPLE_TIME  # sample time [s]
    substeps: int = DEFAULT_SUBSTEPS  # ROS2 substeps per sample [-]
    p: QuarterCarParams = PAPER_PARAMS  # vehicle parameters
    fixed: dict = field(default_factory=lambda: dict(NOMINAL))  # values of non-estimated parameters
    extras: tuple[str, ...] = ()  # mismatch states after the parameters (subset of EXTRA_NAMES)
    speed_from_a_x: bool = False  # input (T_b, a_x) and v' = a_x (module docstring), else input T_b and eq. (6a)
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self):
        unknown = [n for n in self.estimated if n not in PARAM_NAMES]
        if unknown:
            raise ValueError(f"estimated parameters {unknown} unknown; valid: {', '.join(PARAM_NAMES)}")
        object.__setattr__(self, "estimated", tuple(n for n in PARAM_NAMES if n in self.estimated))
        unknown = [n for n in self.extras if n not in EXTRA_NAMES]
        if unknown:
            raise ValueError(f"extra states {unknown} unknown; valid: {', '.join(EXTRA_NAMES)}")
        object.__setattr__(self, "extras", tuple(n for n in EXTRA_NAMES if n in self.extras))
        if self.speed_from_a_x and "a_b" in self.extras:
            raise ValueError("a deceleration bias a_b has no meaning when the speed follows the measured a_x")
        bad = [k for k in self.fixed if k not in PARAM_NAMES]
        if bad:
            raise ValueError(f"fixed parameters {bad} unknown; valid: {', '.join(PARAM_NAMES)}")
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be a finite positive sample time, got {self.dt!r}")
        if self.substeps < 1:
            raise ValueError(f"substeps must be >= 1, got {self.substeps}")

    # ----------------------------------------------------------------- layout
    @property
    def names(self) -> tuple[str, ...]:
        """State names: ``("v", "slip", *estimated, *extras)``."""
        return ("v", "slip") + self.estimated + self.extras

    @property
    def input_names(self) -> tuple[str, ...]:
        """The model's input per sample, held from one sample to the next: ``("T_b",)`` or ``("T_b", "a_x")``."""
        return ("T_b", "a_x") if self.speed_from_a_x else ("T_b",)

    @property
    def nx(self) -> int:
        return 2 + len(self.estimated) + len(self.extras)

    @property
    def torque_fade(self) -> float:
        """The factor by which the torque error ``T_e`` fades over a sample: ``exp(-dt / BRAKE_SETTLE_S)``."""
        return float(np.exp(-self.dt / BRAKE_SETTLE_S))

    def extra(self, x, name: str):
        """The value of mismatch state ``name`` in a (numeric or symbolic) state, its nominal value if not carried."""
        if name not in self.extras:
            return EXTRA_NOMINAL[name]
        return x[2 + len(self.estimated) + self.extras.index(name)]

    def lower(self) -> np.ndarray:
        return np.array([BOUNDS[n][0] for n in self.names])

    def upper(self) -> np.ndarray:
        return np.array([BOUNDS[n][1] for n in self.names])

    def nominal_state(self, v: float, slip: float, params: dict | None = None) -> np.ndarray:
        """State vector from v, slip and parameter values (default: eq. (18) nominal)."""
        params = {**NOMINAL, **EXTRA_NOMINAL, **(params or {})}
        return np.array([v, slip] + [params[n] for n in self.estimated + self.extras], dtype=float)

    def road(self, x) -> tuple:
        """(B, C, E, theta) from a (numeric or symbolic) state, filling in fixed values."""
        vals = {n: self.fixed.get(n, NOMINAL[n]) for n in PARAM_NAMES}
        for i, n in enumerate(self.estimated):
            vals[n] = x[2 + i]
        return vals["B"], vals["C"], vals["E"], vals["theta"]

    # ----------------------------------------------------------------- symbolic pieces
    def rhs_sx(self, x, u):
        """Continuous (v', lambda') of eq. (6)/(19) as SX, speed floored at V_FLOOR; ``u`` the input
        (:attr:`input_names`)."""
        p = self.p
        B, C, E, theta = self.road(x)
        v = ca.fmax(x[0], V_FLOOR)
        lam = x[1]
        Tb = self.extra(x, "k_T") * u[0] + self.extra(x, "T_e")
        if self.speed_from_a_x:
            return u[1], _slip_given_accel_casadi(u[1], v, lam, Tb, B, C, E, theta, p.r, p.J, p.Fz)
        vdot, lamdot = _slip_ode_casadi(v, lam, Tb, B, C, E, theta, p.r, p.m, p.J, p.Fz)
        if "a_b" not in self.extras:
            return vdot, lamdot
        a_b = self.extra(x, "a_b")  # lambda = 1 - omega r / v: a speed change a_b moves the slip by (1 - lambda) / v
        return vdot - a_b, lamdot - (1.0 - lam) * a_b / v

    def step_sx(self, x, u):
        """One sample of the discrete model x+ = f(x, u), eq. (8a), as SX (ROS2 substeps); ``u`` the input held
        over the sample (:attr:`input_names`: the torque, or (T_b, a_x))."""
        h = self.dt / self.substeps
        hg = h * ROS2_GAMMA
        xs = ca.SX.sym("xs", 2)
        prm = ca.SX.sym("prm", self.nx - 2)
        ts = ca.SX.sym("ts", len(self.input_names))
        fv, fl = self.rhs_sx(ca.vertcat(xs, prm), ts)
        f_expr = ca.vertcat(fv, fl)
        rhs = ca.Function("rhs", [xs, prm, ts], [f_expr, ca.jacobian(f_expr, xs)])
        params = x[2:self.nx] if self.nx > 2 else ca.SX(0, 1)

        def rhs_fun(z):
            return rhs(z, params, u)

        z = ca.vertcat(x[0], x[1])
        for _ in range(self.substeps):
            f1, A = rhs_fun(z)
            M = ca.SX.eye(2) - hg * A
            det = M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]

            def solve(b, M=M, det=det):  # 2x2 Cramer's rule: no inverse formed
                return ca.vertcat((M[1, 1] * b[0] - M[0, 1] * b[1]) / det,
                                  (M[0, 0] * b[1] - M[1, 0] * b[0]) / det)

            k1 = solve(f1)
            f2, _ = rhs_fun(z + h * k1)
            k2 = solve(f2 - 2.0 * k1)
            z = z + h * (1.5 * k1 + 0.5 * k2)
            z = ca.vertcat(ca.fmax(z[0], 0.0), ca.fmin(ca.fmax(z[1], 0.0), 1.0))
        fade = {"T_e": self.torque_fade}  # the brake's torque error fades, the other states are constant
        return ca.vertcat(z, *[x[i] * fade.get(n, 1.0) for i, n in enumerate(self.names) if i >= 2])

    def measurement_sx(self, x):
        """Eq. (7): omega = v (1 - lambda) / r."""
        return x[0] * (1.0 - x[1]) / self.p.r

    # ----------------------------------------------------------------- compiled functions
    def _functions(self) -> dict:
        if not self._cache:
            x = ca.SX.sym("x", self.nx)
            u = ca.SX.sym("u", len(self.input_names))
            xn = self.step_sx(x, u)
            y = self.measurement_sx(x)
            self._cache["f"] = ca.Function("f", [x, u], [xn])
            self._cache["fF"] = ca.Function("fF", [x, u], [xn, ca.jacobian(xn, x)])
            self._cache["h"] = ca.Function("h", [x], [y])
            self._cache["hH"] = ca.Function("hH", [x], [y, ca.jacobian(y, x)])
        return self._cache

    @property
    def f_function(self) -> ca.Function:
        """Compiled ``f(x, u) -> x+``."""
        return self._functions()["f"]

    def f(self, x, u) -> np.ndarray:
        """Numeric x+ = f(x, u) (``u``: the torque, or (T_b, a_x))."""
        return np.asarray(self._functions()["f"](x, u)).ravel()

    def f_and_jacobian(self, x, u) -> tuple[np.ndarray, np.ndarray]:
        """Numeric x+ and d x+ / d x."""
        xn, F = self._functions()["fF"](x, u)
        return np.asarray(xn).ravel(), np.asarray(F)

    def h(self, x) -> float:
        """Numeric measurement, eq. (7)."""
        return float(x[0] * (1.0 - x[1]) / self.p.r)

    def h_jacobian(self, x) -> np.ndarray:
        """d h / d x as a (1, nx) array."""
        H = np.zeros((1, self.nx))
        H[0, 0] = (1.0 - x[1]) / self.p.r
        H[0, 1] = -x[0] / self.p.r
        return H

    def values(self, x) -> dict[str, float]:
        """The named values every quarter-car :class:`~estimators.base.Estimate` carries, from a state."""
        B, C, E, theta = self.road(x)
        return {"v": float(x[0]), "slip": float(x[1]), "theta": float(theta), "B": float(B), "C": float(C),
                "E": float(E), "mu": self.mu(x)}

    def mu(self, x, slip: float | None = None) -> float:
        """Friction coefficient of state ``x`` at its own slip (or at ``slip``)."""
        B, C, E, theta = self.road(np.asarray(x, dtype=float))
        return float(magic_formula(x[1] if slip is None else slip, B, C, E, theta))
