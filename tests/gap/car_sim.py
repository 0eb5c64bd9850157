"""A car's session simulated independently of the car diagnosis' model: a straight-line car with four wheels, each
with its inertia, radius and a Pacejka tire, integrated at 2 ms steps (Strang splitting: the stiff wheel equations
by the exponential Euler method, exact for a linear wheel, between two half steps of the body) through drive, coasting and braking stretches; the brake torque is a line pressure times a true factor per corner, the rear wheels are driven."""

from __future__ import annotations

import math
import types

import numpy as np

MASS, LF, LR, G = 790.0, 1.248, 1.7328, 9.81
J = 1.2  # wheel inertia [kg m^2]
RADII = {"fl": 0.3285, "fr": 0.3290, "rl": 0.3340, "rr": 0.3345}
TIRE = (12.0, 1.6, 1.1)  # Pacejka B, C, D
C0, C2 = 400.0, 2.0  # drag [N], [N s^2/m^2]
FRONT_SHARE = 0.6  # brake balance
FACTOR_TRUE = 1.5e-4  # front wheel torque per Pa [N m/Pa]
DRIVE = 8.0  # rear wheel drive torque per throttle percent [N m/%]


def _load(c: str) -> float:
    return MASS * G * (LR if c[0] == "f" else LF) / (2.0 * (LF + LR))


def _force(c: str, v: float, w: float) -> float:
    lam = (w * RADII[c] - v) / max(v, w * RADII[c], 0.5)
    B, C, D = TIRE
    return _load(c) * D * np.sin(C * np.arctan(B * lam))


def profile(brakes: list[float], drive: float = 8.0, coast: float = 4.0, hold: float = 3.0):
    """The stretches ``(kind, t_start, t_end, peak pressure [Pa])``: per braking event (its peak pressure) a
    ``drive`` s stretch at 35 % throttle, a ``coast`` s coast, a 0.6 s pressure ramp and ``hold`` s of braking."""
    segs, t = [], 0.0
    for p in brakes:
        segs.append(("drive", t, t + drive, 0.0))
        segs.append(("coast", t + drive, t + drive + coast, 0.0))
        segs.append(("brake", t + drive + coast, t + drive + coast + 0.6 + hold, p))
        t += drive + coast + 0.6 + hold + 0.5
    segs.append(("coast", t - 0.5, t + 2.0, 0.0))
    return segs, t + 2.0


def simulate(brakes=(1.2e6, 0.8e6, 1.5e6, 1.0e6), dt=0.04, seed=0, gain=1.4, v0=12.0, noise=(0.01, 0.15),
             step=0.002, **durations):
    """A session: returns (a log-like object with the contract's and the session's channels, the stretches);
    ``T_b`` is the line pressure times the nominal factor ``FACTOR_TRUE / gain``; ``durations`` go to
    :func:`profile`."""
    segs, T_end = profile(list(brakes), **durations)

    def inputs(t):
        for kind, a, b, p in segs:
            if a <= t < b:
                if kind == "drive":
                    return 35.0, 0.0
                if kind == "brake":
                    return 0.0, p * min((t - a) / 0.6, 1.0)
                return 0.0, 0.0
        return 0.0, 0.0

    corners = list(RADII)
    r = [RADII[c] for c in corners]
    Fz = [_load(c) for c in corners]
    share = [1.0 if c[0] == "f" else (1 - FRONT_SHARE) / FRONT_SHARE for c in corners]
    driven = [c[0] == "r" for c in corners]
    B, C, D = TIRE
    h = step
    sub = round(dt / h)
    t = np.arange(0.0, T_end, dt)
    v, w = v0, [v0 / x for x in r]

    def tire(i, v, w):
        den = max(v, w * r[i], 0.5)
        lam = (w * r[i] - v) / den
        u = math.atan(B * lam)
        return Fz[i] * D * math.sin(C * u), Fz[i] * D * math.cos(C * u) * C * B / (1 + (B * lam) ** 2) * r[i] / den

    def accel(v, w):
        return (sum(tire(i, v, w[i])[0] for i in range(4)) - C0 - C2 * v * v) / MASS

    out = np.empty((len(t), 5))
    for n, tn in enumerate(t):
        out[n] = [v, *w]
        for j in range(sub):
            thr, p = inputs(tn + (j + 0.5) * h)
            v = v + 0.5 * h * accel(v, w)  # Strang splitting: half a body step, a wheel step, half a body step
            for i in range(4):
                F, dF = tire(i, v, w[i])
                f = ((DRIVE * thr if driven[i] else 0.0) - FACTOR_TRUE * p * share[i] - r[i] * F) / J
                stiff = r[i] * dF / J  # the wheel equation's stiffness [1/s]
                w[i] = max(w[i] + f * (-math.expm1(-stiff * h) / stiff), 0.0)
            v = v + 0.5 * h * accel(v, w)
    sol_y = out.T
    rng = np.random.default_rng(seed)
    v = sol_y[0] + noise[0] * rng.standard_normal(len(t))
    wheels = {c: sol_y[1 + i] + noise[1] * rng.standard_normal(len(t)) for i, c in enumerate(RADII)}
    thr = np.array([inputs(x)[0] for x in t])
    p = np.array([inputs(x)[1] for x in t])
    return types.SimpleNamespace(t=t, T_b=p * FACTOR_TRUE / gain, omega=wheels["fl"], v=v, a_x=None, throttle=thr,
                                 yaw_rate=np.zeros(len(t)), steer=None, source="simulated", t_offset=0.0,
                                 torque_from_pressure=True, warnings=[], true_v=sol_y[0],
                                 **{f"omega_{c}": w for c, w in wheels.items()}), segs
