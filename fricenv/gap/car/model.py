"""The car model over a braking event's prediction windows.

The body's deceleration comes from every wheel's brake force and the drag, the wheels' speeds from the body's
speed and each tire's slip:

    m_e v'    = -(sum_c T_c / r_c) - c0 - c2 v^2             (the four wheels; T_c the brake torque of corner c)
    omega_c   = v (1 - lambda_c) / r_c,  lambda_c = (T_c / r_c) / (F_z,c S)

The wheels are quasi-static (a braked tire's slip settles within milliseconds, far below a 25 Hz sample) and the
tires linear in slip (``S``: the event's slip stiffness per unit load, its road state). The mapped wheel's torque is
``gain`` times the nominal ``T_b`` (pressure times the map's factor), through the actuator's lag ``tau`` and delay;
the other axle's wheels carry ``(1 - balance) / balance`` (front mapped) or ``balance / (1 - balance)`` (rear
mapped) of it, ``balance`` being the front axle's share of the brake torque. ``F_z,c`` is the static wheel load, ``m_e = m + sum_c J / r_c^2`` the mass with the wheels' rotation.

A window starts from the speed ``v0`` that best fits its own samples (a linear least squares: every predicted
channel is linear in ``v0``); the drag uses the logged speed. ``a_x``, when used, is compared with ``v'``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from fricenv.gap.car.session import CORNERS, CarParams

__all__ = ["EFFECT_PARAMS", "PARAM_BOUNDS", "EventData", "nominal_params", "predict_event", "window_residuals"]

# The car's parameters each library effect frees (radius_error: one radius per logged wheel).
EFFECT_PARAMS = {"brake_gain": ("gain",), "radius_error": tuple(f"r_{c}" for c in CORNERS),
                 "drag": ("c0", "c2"), "brake_lag": ("tau",), "brake_delay": ("delay",)}
PARAM_BOUNDS = {"gain": (0.3, 3.0), "balance": (0.3, 0.85), **{f"r_{c}": (0.25, 0.45) for c in CORNERS},
                "c0": (0.0, 3000.0), "c2": (0.0, 10.0), "tau": (1e-3, 0.4), "delay": (0.0, 0.25)}
SLIP_STIFFNESS_BOUNDS = (3.0, 300.0)  # per unit load [-]
SLIP_STIFFNESS_START = 30.0


@dataclass
class EventData:
    """One event's samples for the car model; ``T`` starts ``pre`` samples before the event (the actuator's
    history)."""

    v: np.ndarray  # (n,) logged speed
    T: np.ndarray  # (pre + n,) the mapped wheel's nominal brake torque
    pre: int
    wheels: dict  # corner -> (n,) omega, NaN where missing
    a_x: np.ndarray | None
    dt: float
    starts: np.ndarray  # window starts within the event
    horizon: int
    block: np.ndarray  # (W,) block of each window (the hold-out within the event)
    t0: float  # the event's first time (from the session's first sample)

    @property
    def n(self) -> int:
        return len(self.v)

    def channels(self) -> list[str]:
        return ["v"] + [f"omega_{c}" for c in self.wheels] + (["a_x"] if self.a_x is not None else [])


def nominal_params(r: float, car: CarParams, radii: dict | None = None) -> dict:
    """The nominal car: the map's brake factor, the stated or static brake balance, each wheel's radius as the map
    converted it (``radii``, corner -> m) else ``r``, no drag and an ideal actuator."""
    radii = radii or {}
    return {"gain": 1.0, "balance": car.front_share, **{f"r_{c}": radii.get(c, r) for c in CORNERS}, "c0": 0.0,
            "c2": 0.0, "tau": 0.0, "delay": 0.0}


def _actuator(T: np.ndarray, dt: float, tau: float, delay: float) -> np.ndarray:
    """The applied torque: ``T`` delayed (linear interpolation) and through a first-order lag (exact for a torque
    held over each step)."""
    if delay > 0:
        k = np.arange(len(T)) - delay / dt
        T = np.interp(k, np.arange(len(T)), T, left=T[0])
    if tau > 0:  # y[k] = y[k-1] + a (T[k-1] - y[k-1]), y[0] = T[0]
        a = 1.0 - np.exp(-dt / tau)
        T = lfilter([0.0, a], [1.0, a - 1.0], T, zi=[T[0]])[0]
    return T


def _corner_torques(T: np.ndarray, x: dict, mapped: str) -> dict:
    """Brake torque of each corner from the mapped wheel's applied torque and the brake balance."""
    b = x["balance"]
    other = (1.0 - b) / b if mapped.startswith("f") else b / (1.0 - b)
    front, rear = (T, T * other) if mapped.startswith("f") else (T * other, T)
    return {c: (front if c.startswith("f") else rear) for c in CORNERS}


def predict_event(e: EventData, x: dict, stiffness: float, car: CarParams, mapped: str):
    """The model's inputs over the event: (deceleration model a (n,), slip per logged corner (n,), radius per
    logged corner)."""
    T = _actuator(x["gain"] * e.T, e.dt, x["tau"], x["delay"])[e.pre:]
    torque = _corner_torques(T, x, mapped)
    force = sum(torque[c] / x[f"r_{c}"] for c in CORNERS)
    a = -(force + x["c0"] + x["c2"] * e.v ** 2) / car.effective_mass([x[f"r_{c}"] for c in CORNERS])
    slip = {c: torque[c] / x[f"r_{c}"] / (car.static_load(c) * stiffness) for c in e.wheels}
    return a, slip


def window_residuals(e: EventData, x: dict, stiffness: float, car: CarParams, mapped: str, sigma: dict,
                     widx: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Normalised residuals of the windows ``widx`` (all by default), each started from its best-fitting ``v0``.

    :return: (r (W, H * channels), NaN where a sample is missing; counts (W,) of the finite residuals).
    """
    widx = np.arange(len(e.starts)) if widx is None else np.asarray(widx)
    rows = e.starts[widx][:, None] + np.arange(e.horizon)[None, :]
    a, slip = predict_event(e, x, stiffness, car, mapped)
    integral = np.r_[0.0, np.cumsum(0.5 * (a[1:] + a[:-1]) * e.dt)]
    D = integral[rows] - integral[rows[:, :1]]
    parts = [(np.ones_like(D), D, e.v[rows], sigma["v"])]
    for c, w in e.wheels.items():
        k = (1.0 - slip[c][rows]) / x[f"r_{c}"]
        parts.append((k, D * k, w[rows], sigma[f"omega_{c}"]))
    if e.a_x is not None:
        parts.append((np.zeros_like(D), a[rows], e.a_x[rows], sigma["a_x"]))
    num = np.zeros(len(widx))
    den = np.zeros(len(widx))
    for A, B, m, s in parts:
        ok = np.isfinite(m)
        num += np.sum(np.where(ok, A * (m - B), 0.0), axis=1) / s ** 2
        den += np.sum(np.where(ok, A * A, 0.0), axis=1) / s ** 2
    v0 = num / np.maximum(den, 1e-300)
    r = np.concatenate([(v0[:, None] * A + B - m) / s for A, B, m, s in parts], axis=1)
    return r, np.count_nonzero(np.isfinite(r), axis=1)


def window_mse(r: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Mean squared normalised residual per window, corrected for the fitted start speed (one degree of
    freedom)."""
    return np.nansum(r * r, axis=1) / np.maximum(counts - 1, 1)
