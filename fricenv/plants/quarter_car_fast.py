"""Fast variants of one ROS2 physics substep of :func:`fricenv.plants.quarter_car.step` (plain numpy / math).

:func:`fricenv.plants.quarter_car.step` is the reference integrator (and :mod:`fricenv.plants.tire` the one home of
the Magic Formula and the slip); these two kernels are fast paths of the same substep (ROS2 with the exact
Jacobian, the lock event, ``v >= 0``) for the braking env's hot loop, with the Magic Formula and its slope written
out to share subexpressions. They are tested to equal the reference to 1e-12 (``tests/envs/test_braking_vector.py``,
``tests/plants/test_quarter_car_plant.py``), and a substep that breaks the braking invariant is redone by the reference:

* :func:`make_scalar_substep` (and :func:`ros2_substep_scalar`): one car in Python floats (``math``), for the single env, where numpy's per-call
  overhead on 1-element arrays costs more than the arithmetic;
* :class:`Ros2Batch`: ``n`` cars with the road's constants cached per car and the Magic Formula and its slope
  sharing their arctangents.

Both use the structure of eq. (1): the force ``F_x(v, omega)`` enters both equations through the fixed column
``u = (-1/m, r/J)``, so ``f(x) = u F_x + e`` with ``e = (0, -T_b/J)`` and the Jacobian ``A = u g^T`` has rank one
(``g`` the gradient of ``F_x``). With ``a = dF/dv`` and ``b = -(dF/domega)/r`` (both ``F_z mu'`` times a slip
partial), Sherman-Morrison gives ``det = det(I - gamma h A) = 1 + gamma h (a/m + r^2 b/J)`` and, with
``HB = gamma h b r T_b / J``, the two ROS2 stages in closed form:

    k1 = u F1s + e,  F1s = (F_x(x) + HB) / det
    k2 = u (Z - HB) / det - e,  Z = F_x(x + h k1) - 2 F1s
    x+ = x + h (3/2 k1 + 1/2 k2) = x + h (u Y + e),  Y = (3 F1s + (Z - HB) / det) / 2

which is the same ROS2 step as the reference's Cramer solve, in about two thirds of the operations.

Road constants per car: ``(B, C, E, theta)`` and ``mu(1)`` (sliding friction, used by the lock event).
"""

from __future__ import annotations

import math

import numpy as np

from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import SLIP_SPEED_FLOOR, magic_formula

__all__ = ["ROS2_GAMMA", "Ros2Batch", "make_scalar_substep", "ros2_core", "ros2_substep_scalar", "scalar_road",
           "substep_constants"]

ROS2_GAMMA = float(qc.ROS2_GAMMA)  # quarter_car.step's constant (L-stable ROS2)
_TINY = 1e-300  # guard of the lock-crossing interpolation, as in quarter_car._lock_event
_INV_TOL = qc.INVARIANT_TOL  # relative tolerance of the braking-invariant check
FULL_ARRAY_SHARE = 8  # lock events on more than 1/8 of the cars are computed on whole arrays


def scalar_road(B: float, C: float, E: float, theta: float, h: float,
                p: qc.QuarterCarParams = qc.PAPER_PARAMS) -> tuple[float, ...]:
    """The per-road constants of :func:`make_scalar_substep`'s substep: (B, C, E, F_z theta, F_z theta C B,
    1 - E, h F_z mu(1) / m)."""
    mu_slide = float(magic_formula(1.0, B, C, E, theta))
    return (float(B), float(C), float(E), p.Fz * theta, p.Fz * theta * C * B, 1.0 - E, h * p.Fz * mu_slide / p.m)


def substep_constants(h: float, p: qc.QuarterCarParams = qc.PAPER_PARAMS) -> tuple[float, ...]:
    """The per-substep constants of :func:`ros2_core`: (r, gamma h/m, gamma h r^2/J, gamma h r/J, h/m, h r/J, h/J)."""
    r, m, J = p.r, p.m, p.J
    hg = h * ROS2_GAMMA
    return (r, hg / m, hg * r * r / J, hg * r / J, h / m, h * r / J, h / J)


def ros2_core(v: float, w: float, Tb: float, road: tuple, k: tuple) -> tuple[float, float, bool]:
    """One ROS2 substep of eq. (1) for one car in floats, with the lock event and ``v >= 0``, WITHOUT the
    refinement: returns (v, omega, broken), ``broken`` where :func:`quarter_car.braking_invariant_broken` holds
    (the caller then redoes the substep in finer parts). ``road`` from :func:`scalar_road`, ``k`` from
    :func:`substep_constants`. Plain ``math``, so that numba compiles this same function
    (:mod:`fricenv.effects.kernels`): the one scalar form of the substep.
    """
    B, C, E, fz_theta, fz_theta_cb, one_minus_E, slide = road
    r, hg_m, hg_r2_J, hg_r_J, h_m, h_r_J, h_J = k
    # Point 1: force and slope (eq. (2), (3)).
    wr = wr0 = w * r
    vw = v if v >= wr else wr  # noqa: FURB136 (a builtin call costs more in this hot loop)
    denom = vw if vw > SLIP_SPEED_FLOOR else SLIP_SPEED_FLOOR  # noqa: FURB136
    bs = B * (v - wr) / denom
    inner = bs - E * (bs - math.atan(bs))
    ci = C * math.atan(inner)
    P = fz_theta_cb * math.cos(ci) * (one_minus_E + E / (1.0 + bs * bs)) / (1.0 + inner * inner) / (denom * denom)
    # a = dF/dv, b = -(dF/domega)/r: P times the slip partials' numerators (see the module docstring).
    if denom <= SLIP_SPEED_FLOOR:
        a = b = P * denom
    elif v >= wr:
        a, b = P * wr, P * denom
    else:
        a, b = P * denom, P * v
    inv_det = 1.0 / (1.0 + hg_m * a + hg_r2_J * b)
    HB = hg_r_J * b * Tb
    F1s = (fz_theta * math.sin(ci) + HB) * inv_det
    # Point 2: x + h k1, omega clipped at 0.
    v2 = v - h_m * F1s
    wr = w + h_r_J * F1s - h_J * Tb
    wr = wr * r if wr > 0.0 else 0.0
    vw = v2 if v2 >= wr else wr  # noqa: FURB136
    denom = vw if vw > SLIP_SPEED_FLOOR else SLIP_SPEED_FLOOR  # noqa: FURB136
    bs = B * (v2 - wr) / denom
    F2 = fz_theta * math.sin(C * math.atan(bs - E * (bs - math.atan(bs))))
    Y2 = 3.0 * F1s + (F2 - 2.0 * F1s - HB) * inv_det
    v_new = v - 0.5 * h_m * Y2
    w_new = w + 0.5 * h_r_J * Y2 - h_J * Tb
    if w_new < 0.0:
        # Lock event (quarter_car._lock_event): lock where omega crosses zero, slide at mu(1) for the rest.
        frac = w / max(w - w_new, _TINY)
        v_new = v + frac * (v_new - v) - (1.0 - frac) * slide
        w_new = 0.0
    v_new = max(v_new, 0.0)
    tol = _INV_TOL * (1.0 + v)
    broken = Tb >= 0.0 and wr0 <= v and (w_new * r > v_new + tol or v_new > v + tol)
    return v_new, w_new, broken


def make_scalar_substep(h: float, p: qc.QuarterCarParams = qc.PAPER_PARAMS):
    """A function ``substep(v, w, Tb, road) -> (v, omega)``: one ROS2 substep of ``h`` seconds for one car in
    Python floats, ``road`` from :func:`scalar_road`; equals ``quarter_car.step(v, w, Tb, road, h, p, 1)``.

    :func:`ros2_core` with the constants bound once; a substep that breaks the braking invariant is redone by the
    reference, in finer parts.
    """
    k = substep_constants(h, p)
    core = ros2_core

    def substep(v: float, w: float, Tb: float, road: tuple[float, ...]) -> tuple[float, float]:
        v_new, w_new, broken = core(v, w, Tb, road, k)
        if broken:  # rare: redo this substep the reference way, in finer parts
            vf, wf = qc.step(np.array([v]), np.array([w]), np.array([Tb]), np.array([*road[:3], road[3] / p.Fz]),
                             h, p, qc.REFINE_PARTS)
            return float(vf[0]), float(wf[0])
        return v_new, w_new

    return substep


def ros2_substep_scalar(v: float, w: float, Tb: float, B: float, C: float, E: float, theta: float, h: float,
                        p: qc.QuarterCarParams = qc.PAPER_PARAMS) -> tuple[float, float]:
    """One ROS2 substep of eq. (1) for one car in Python floats; equals ``quarter_car.step(..., h, p, 1)``.

    Convenience form of :func:`make_scalar_substep` (which a hot loop should use: it binds the constants once).

    :param v: vehicle speed [m/s].
    :param w: wheel speed [rad/s].
    :param Tb: brake torque [N m].
    :param B: Magic Formula stiffness factor.
    :param C: shape factor.
    :param E: curvature factor.
    :param theta: peak factor.
    :param h: substep [s].
    :param p: quarter-car parameters.
    :return: (v, omega) after the substep.
    """
    return make_scalar_substep(h, p)(v, w, Tb, scalar_road(B, C, E, theta, h, p))


class Ros2Batch:
    """ROS2 substeps of ``n`` quarter cars with per-car road constants cached (see the module docstring).

    Call :meth:`set_torque` when the brake torques change (once per control step), then :meth:`substep`.

    :param n: number of cars.
    :param h: substep [s].
    :param p: quarter-car parameters.
    """

    def __init__(self, n: int, h: float, p: qc.QuarterCarParams = qc.PAPER_PARAMS):
        self.n, self.h, self.p = int(n), float(h), p
        hg = h * ROS2_GAMMA
        self._hg_m = hg / p.m  # det = 1 + (hg/m) a + (hg r^2/J) b
        self._hg_r2_J = hg * p.r * p.r / p.J
        self._h_m = h / p.m
        self._h_r_J = h * p.r / p.J
        self._h_r2_J = h * p.r * p.r / p.J
        z = lambda: np.zeros(self.n)
        self.B, self.C, self.E, self.theta = z(), z(), z(), z()
        self._one_minus_E, self._fz_theta, self._fz_theta_cb = z(), z(), z()
        self._slide_decel = z()  # h F_z mu(1) / m [m/s]
        self._hg_r_tb_J = z()  # gamma h r T_b / J
        self._h_tb_J = z()  # h T_b / J [rad/s]
        self._h_r_tb_J = z()  # h r T_b / J [m/s]
        self._Tb = z()  # brake torques [N m]

    def set_road(self, idx, road: np.ndarray) -> None:
        """Set the road constants of cars ``idx`` (index array, mask or slice) from rows (B, C, E, theta)."""
        road = np.asarray(road, dtype=float).reshape(-1, 4)
        B, C, E, theta = road[:, 0], road[:, 1], road[:, 2], road[:, 3]
        p = self.p
        self.B[idx], self.C[idx], self.E[idx], self.theta[idx] = B, C, E, theta
        self._one_minus_E[idx] = 1.0 - E
        self._fz_theta[idx] = p.Fz * theta
        self._fz_theta_cb[idx] = p.Fz * theta * C * B
        self._slide_decel[idx] = self.h * p.Fz * magic_formula(1.0, B, C, E, theta) / p.m

    def set_torque(self, Tb: np.ndarray) -> None:
        """Set the brake torques [N m] of all cars (held over the following substeps)."""
        p = self.p
        np.copyto(self._Tb, Tb)
        np.multiply(Tb, self.h * ROS2_GAMMA * p.r / p.J, out=self._hg_r_tb_J)
        np.multiply(Tb, self.h / p.J, out=self._h_tb_J)
        np.multiply(Tb, self.h * p.r / p.J, out=self._h_r_tb_J)

    def substep(self, v: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One ROS2 substep of every car under the torques of :meth:`set_torque`; equals
        ``quarter_car.step(v, w, Tb, road, h, p, 1)``.

        :param v: vehicle speeds [m/s], shape (n,).
        :param w: wheel speeds [rad/s], shape (n,).
        :return: new (v, omega) arrays.
        """
        F1s, inv_det, HB, wr, vw, denom, scratch = self._stage1(v, w)
        v_new, w_new = self._stage2(v, w, F1s, inv_det, HB, wr, vw, denom, scratch)
        if w_new.min() < 0.0:
            self._lock_event(v, w, v_new, w_new)
        np.maximum(v_new, 0.0, out=v_new)
        bad = qc.braking_invariant_broken(v, w, v_new, w_new, self._Tb, self.p.r)
        if bad.any():  # rare: redo those cars the reference way, in finer parts
            idx = np.flatnonzero(bad)
            road = np.column_stack([self.B[idx], self.C[idx], self.E[idx], self.theta[idx]])
            v_new[idx], w_new[idx] = qc.step(v[idx], w[idx], self._Tb[idx], road, self.h, self.p, qc.REFINE_PARTS)
        return v_new, w_new

    def _stage1(self, v: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, ...]:
        """Point 1: force, slope, ``inv_det``, ``HB`` and ``F1s`` (k1 = u F1s + e); also returns buffers to reuse."""
        r = self.p.r
        B, C, E = self.B, self.C, self.E
        # Point 1 (eq. (2), (3)): lam = (v - wr) / denom, denom = max(v, wr, floor).
        wr = w * r
        vw = np.maximum(v, wr)
        denom = np.maximum(vw, SLIP_SPEED_FLOOR)
        bs = v - wr
        bs /= denom
        bs *= B
        inner = np.arctan(bs)
        np.subtract(bs, inner, out=inner)
        inner *= E
        np.subtract(bs, inner, out=inner)
        ci = np.arctan(inner)
        ci *= C
        F = np.sin(ci)
        F *= self._fz_theta
        # P = F_z mu' / denom^2, mu' = theta C B (1 - E + E/(1 + bs^2)) cos(ci) / (1 + inner^2).
        np.multiply(bs, bs, out=bs)
        bs += 1.0
        np.divide(E, bs, out=bs)
        bs += self._one_minus_E
        P = np.cos(ci, out=ci)
        P *= bs
        np.multiply(inner, inner, out=inner)
        inner += 1.0
        P /= inner
        P *= self._fz_theta_cb
        np.multiply(denom, denom, out=inner)
        P /= inner
        # a = dF/dv = P num_v, b = -(dF/domega)/r = P num_w with num_v = wr, num_w = v in braking (denom = v) and
        # in traction (denom = wr) alike, and both = denom where the denominator is floored.
        a = P * wr
        b = P * v
        if vw.min() <= SLIP_SPEED_FLOOR:
            floored = vw <= SLIP_SPEED_FLOOR
            Pd = P * denom
            np.copyto(a, Pd, where=floored)
            np.copyto(b, Pd, where=floored)
        # inv_det = 1 / (1 + hg (a/m + r^2 b/J)); HB = hg b r Tb / J; F1s = (F + HB) inv_det (k1 = u F1s + e).
        inv_det = np.multiply(b, self._hg_r2_J)
        a *= self._hg_m
        inv_det += a
        inv_det += 1.0
        np.divide(1.0, inv_det, out=inv_det)
        HB = b
        HB *= self._hg_r_tb_J
        F1s = F
        F1s += HB
        F1s *= inv_det
        return F1s, inv_det, HB, wr, vw, denom, (a, P)

    def _stage2(self, v, w, F1s, inv_det, HB, wr, vw, denom, scratch) -> tuple[np.ndarray, np.ndarray]:
        """Point 2 (x + h k1, omega clipped at 0) and the ROS2 update; the arrays of :meth:`_stage1` are reused."""
        a, P = scratch
        B, C, E = self.B, self.C, self.E
        v2 = np.multiply(F1s, -self._h_m, out=a)
        v2 += v
        wr2 = np.multiply(F1s, self._h_r2_J, out=P)  # r (w + h k1w) = wr + (h r^2/J) F1s - h r Tb/J
        wr2 += wr
        wr2 -= self._h_r_tb_J
        np.maximum(wr2, 0.0, out=wr2)
        denom = np.maximum(v2, wr2, out=denom)
        np.maximum(denom, SLIP_SPEED_FLOOR, out=denom)
        bs = np.subtract(v2, wr2, out=wr)  # wr is not needed any more
        bs /= denom
        bs *= B
        inner = np.arctan(bs, out=vw)
        np.subtract(bs, inner, out=inner)
        inner *= E
        np.subtract(bs, inner, out=inner)
        np.arctan(inner, out=inner)
        inner *= C
        F2 = np.sin(inner, out=inner)
        F2 *= self._fz_theta
        # Y2 = 2 Y = 3 F1s + (F2 - 2 F1s - HB) inv_det; x+ = x + h (u Y + e).
        F2 -= HB
        Y2 = np.multiply(F1s, 2.0, out=bs)
        F2 -= Y2
        F2 *= inv_det
        Y2 += F1s
        Y2 += F2
        v_new = np.multiply(Y2, -0.5 * self._h_m, out=denom)
        v_new += v
        w_new = np.multiply(Y2, 0.5 * self._h_r_J, out=F2)
        w_new += w
        w_new -= self._h_tb_J
        return v_new, w_new

    def _lock_event(self, v, w, v_new, w_new) -> None:
        """Lock event (quarter_car._lock_event), in place: lock where omega crosses zero, slide at mu(1) for the
        rest. The same elementwise formula on the crossing cars only, or on all cars and then selected when many
        cross (a locked wheel crosses in every substep)."""
        crossing = w_new < 0.0
        idx = np.flatnonzero(crossing)
        if len(idx) * FULL_ARRAY_SHARE < self.n:
            wi, wn = w[idx], w_new[idx]
            frac = wi / np.maximum(wi - wn, _TINY)
            vi = v[idx]
            v_new[idx] = vi + frac * (v_new[idx] - vi) - (1.0 - frac) * self._slide_decel[idx]
        else:
            frac = w / np.maximum(w - w_new, _TINY)
            v_lock = v + frac * (v_new - v) - (1.0 - frac) * self._slide_decel
            np.copyto(v_new, v_lock, where=crossing)
        np.maximum(w_new, 0.0, out=w_new)
