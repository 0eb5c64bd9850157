"""A second planar-payload simulator, written from the paper alone: it imports nothing from fricenv.

Paper: Liu, Leung, Tang & Jia, "A New Adaptive Observer for Force-Moment Sensor Calibration" (papers/003_...).
Our reading of it, independent of the library's:

- Eq. (1): ``I_G theta'' = M - rho_y f_x + rho_x f_y`` (the 1/m factor in front of the matrix cancels the m in its
  first row), ``m X'' = cos(theta) f_x - sin(theta) f_y``, ``m Y'' = sin(theta) f_x + cos(theta) f_y``: the wrench
  ``(M, f_x, f_y)`` acts in the body frame, the pose ``(theta, X, Y)`` is that of G in the inertial frame J.
- Eq. (3): ``w = S w_hat``, so the sensor reads ``w_hat = S^-1 w`` (plus noise, plus an offset when it has one).
- Section 4: m = 2.5 kg, I_G = 0.75 kg m^2, rho = (0.2, 0.25) m, the multi-sine of eq. (13) and S of item 4.
- Noise: "variance of 5 % of the amplitude" is read as a standard deviation (a variance in N^2 cannot be a share
  of an amplitude in N), and the amplitude of an element as the peak of its absolute value over the log (the
  library reads the sum of the term amplitudes; on eq. (13) the two differ by a few per cent). Vision: standard
  deviations of 0.1 deg and 0.1 mm.

Integration: Kutta's 3/8-rule fourth-order Runge-Kutta on the full state, ``SUBSTEPS`` substeps between output
times, with the wrench evaluated in continuous time (the library uses the classical RK4 as a quadrature cascade).
The orientation has a closed form under a multi-sine (``theta'' `` is a sum of sines): :func:`theta_closed_form`
checks the integrator in the tests.

Timing convention (docs/contracts.md, payload timing): the row at stamp ``t_k`` holds the pose at the camera's
exposure ``t_k`` (minus the vision delay when the log has one), and the force-moment reading either at ``t_k``
(``ft_sample="end"``) or averaged over the sample period ``(t_k - dt, t_k]`` (``ft_sample="mean"``, exact for a
multi-sine). A pose stamped at its arrival rather than its exposure is a vision delay equal to the transport time.
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "INERTIA",
    "MASS",
    "RHO",
    "S_PAPER",
    "MultiSine",
    "PayloadRecipe",
    "paper_excitation",
    "random_excitation",
    "simulate",
    "theta_closed_form",
    "write_csv",
]

MASS = 2.5  # [kg], Section 4 item 1
INERTIA = 0.75  # [kg m^2], Section 4 item 1
RHO = (0.2, 0.25)  # sensor interface from G in the body frame [m], Section 4 item 2
S_PAPER = ((0.6110, -0.0372, -0.1445), (-0.3361, 1.0020, -0.1443), (-0.1147, 0.1674, 0.9598))  # item 4
NOISE_SHARE = 0.05  # sensor noise std / peak |element| [-]
THETA_STD = math.radians(0.1)  # [rad]
POS_STD = 1e-4  # [m]
SUBSTEPS = 8  # integrator steps per output interval [-]
FT_SAMPLING = ("end", "mean")


@dataclass(frozen=True)
class MultiSine:
    """``w_i(t) = sum_k a_ik sin(omega_ik t + phi_ik)`` for the three elements (M, f_x, f_y)."""

    terms: tuple  # per element, a tuple of (a, omega [rad/s], phi [rad])

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        out = np.zeros(t.shape + (3,))
        for i, row in enumerate(self.terms):
            for a, om, ph in row:
                out[..., i] += a * np.sin(om * t + ph)
        return out

    def mean_over(self, t, h: float) -> np.ndarray:
        """The exact average of the wrench over ``(t - h, t]``."""
        t = np.asarray(t, dtype=float)
        out = np.zeros(t.shape + (3,))
        for i, row in enumerate(self.terms):
            for a, om, ph in row:
                out[..., i] += a * (np.cos(om * (t - h) + ph) - np.cos(om * t + ph)) / (om * h)
        return out


def paper_excitation() -> MultiSine:
    """Eq. (13), each cosine written as a sine advanced by a quarter turn."""
    q = math.pi / 2
    return MultiSine((
        ((1.0, 2.0, 0.0), (0.1, 10.0, q), (0.4, math.pi, math.pi / 6)),
        ((1.0, 1.0, 0.0), (0.1, 4.5, q), (0.4, math.pi, math.pi / 3)),
        ((2.0, 3.0, 0.0), (0.2, 5.0, q), (0.4, 7.0, 0.0)),
    ))


def random_excitation(rng: np.random.Generator) -> MultiSine:
    """Three to five sines per element, amplitudes in the range of eq. (13), angular frequencies from 0.8 to 40 rad/s
    (eq. (13) spans 1-10 rad/s; a rig's excitation may be faster), random phases."""
    rows = []
    for scale in (1.0, 1.0, 2.0):
        k = int(rng.integers(3, 6))
        rows.append(tuple((float(scale * rng.uniform(0.1, 1.0)), float(rng.uniform(0.8, 40.0)),
                           float(rng.uniform(0.0, 2.0 * math.pi))) for _ in range(k)))
    return MultiSine(tuple(rows))


@dataclass(frozen=True)
class PayloadRecipe:
    """What to simulate. Effects (registry names): ``delay`` (vision_delay), ``S_true`` (calibration_error),
    ``rate`` (calibration_drift: ``S(t) = S_true (1 + rate t)``), ``offset`` (wrench_offset, on the raw reading);
    ``damping`` = (b_lin [N s/m], b_rot [N m s/rad]) is viscous damping, outside the library."""

    duration: float = 10.0  # [s]
    dt: float = 0.01  # sample period [s]
    delay: float = 0.0  # [s]
    S_true: tuple = S_PAPER
    rate: float = 0.0  # [1/s]
    offset: tuple = (0.0, 0.0, 0.0)  # (M0 [N m], fx0 [N], fy0 [N])
    damping: tuple = (0.0, 0.0)
    ft_sample: str = "end"  # "end" or "mean", see the module docstring
    t0: float = 0.0  # stamp of the first row [s] (an epoch, say); the motion starts there
    noise_scale: float = 1.0  # multiplies every noise std [-]
    excitation: MultiSine = field(default_factory=paper_excitation)

    def __post_init__(self):
        if self.ft_sample not in FT_SAMPLING:
            raise ValueError(f"ft_sample must be one of {FT_SAMPLING}, got {self.ft_sample!r}")
        if not (self.dt > 0 and self.duration > 10 * self.dt and self.delay >= 0):
            raise ValueError("need dt > 0, duration > 10 dt and delay >= 0")


def _rhs(x: np.ndarray, w: np.ndarray, damping: tuple) -> np.ndarray:
    """Eq. (1) plus optional viscous damping; ``w`` the true wrench at that instant."""
    th, vth, vx, vy = x[0], x[3], x[4], x[5]
    c, s = math.cos(th), math.sin(th)
    b_lin, b_rot = damping
    return np.array([vth, vx, vy,
                     (w[0] - RHO[1] * w[1] + RHO[0] * w[2] - b_rot * vth) / INERTIA,
                     (c * w[1] - s * w[2] - b_lin * vx) / MASS,
                     (s * w[1] + c * w[2] - b_lin * vy) / MASS])


def states_at(times: np.ndarray, wrench: MultiSine, damping: tuple = (0.0, 0.0)) -> np.ndarray:
    """The state (theta, X, Y, theta', X', Y') at the given times (from rest at the origin at time 0; before 0 the
    payload rests there), shape (n, 6). Kutta's 3/8 rule, ``SUBSTEPS`` steps between consecutive output times; the
    wrench at every stage time is evaluated up front (it depends on time only)."""
    times = np.asarray(times, dtype=float)
    order = np.argsort(times, kind="stable")
    targets = np.maximum(times[order], 0.0)
    starts = np.concatenate([[0.0], targets[:-1]])
    h = (targets - starts) / SUBSTEPS  # (n,)
    k = np.arange(SUBSTEPS)
    base = starts[:, None] + k[None, :] * h[:, None]  # (n, SUBSTEPS) step start times
    stage = base[..., None] + h[:, None, None] * np.array([0.0, 1 / 3, 2 / 3, 1.0])
    W = wrench(stage)  # (n, SUBSTEPS, 4, 3)
    out = np.zeros((times.size, 6))
    x = np.zeros(6)
    for j, i in enumerate(order):
        hj = h[j]
        if hj > 0:
            for m in range(SUBSTEPS):
                w = W[j, m]
                k1 = _rhs(x, w[0], damping)
                k2 = _rhs(x + hj * k1 / 3, w[1], damping)
                k3 = _rhs(x + hj * (-k1 / 3 + k2), w[2], damping)
                k4 = _rhs(x + hj * (k1 - k2 + k3), w[3], damping)
                x = x + hj * (k1 + 3 * k2 + 3 * k3 + k4) / 8
        out[i] = x if times[i] >= 0 else 0.0
    return out


def theta_closed_form(t, wrench: MultiSine) -> np.ndarray:
    """theta(t) from rest under a multi-sine (no damping): each sine c sin(om t + ph) of ``I_G theta''`` adds
    ``c / (I_G om^2) (sin(ph) + om t cos(ph) - sin(om t + ph))``."""
    t = np.asarray(t, dtype=float)
    arm = (1.0, -RHO[1], RHO[0])
    out = np.zeros_like(t)
    for i, row in enumerate(wrench.terms):
        for a, om, ph in row:
            c = arm[i] * a / INERTIA
            out += c / om**2 * (math.sin(ph) + om * t * math.cos(ph) - np.sin(om * t + ph))
    return out


def _peak(wrench: MultiSine, t: np.ndarray) -> np.ndarray:
    return np.max(np.abs(wrench(t)), axis=0)


def simulate(recipe: PayloadRecipe, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """One log: ``{"t", "M", "f_x", "f_y", "theta", "X", "Y"}`` arrays (SI units, stamps from ``recipe.t0``)."""
    n = round(recipe.duration / recipe.dt) + 1
    t = np.arange(n) * recipe.dt
    wr = recipe.excitation
    pose = states_at(t - recipe.delay, wr, recipe.damping)[:, :3]
    w = wr(t) if recipe.ft_sample == "end" else wr.mean_over(t, recipe.dt)
    if recipe.ft_sample == "mean":
        w[0] = wr(t[:1])[0]
    scale = 1.0 + recipe.rate * t
    S_inv = np.linalg.inv(np.asarray(recipe.S_true, dtype=float))
    w_hat = (w @ S_inv.T) / scale[:, None] + np.asarray(recipe.offset, dtype=float)
    std_w = NOISE_SHARE * _peak(wr, np.linspace(0.0, recipe.duration, 4001)) * recipe.noise_scale
    w_hat = w_hat + rng.normal(size=w_hat.shape) * std_w
    pose = pose + rng.normal(size=pose.shape) * np.array([THETA_STD, POS_STD, POS_STD]) * recipe.noise_scale
    cols = {"t": t + recipe.t0, "M": w_hat[:, 0], "f_x": w_hat[:, 1], "f_y": w_hat[:, 2],
            "theta": pose[:, 0], "X": pose[:, 1], "Y": pose[:, 2]}
    return cols


def true_noise(recipe: PayloadRecipe) -> dict[str, float]:
    """The noise std the recipe draws per column (SI)."""
    std_w = NOISE_SHARE * _peak(recipe.excitation, np.linspace(0.0, recipe.duration, 4001)) * recipe.noise_scale
    return {"M": float(std_w[0]), "f_x": float(std_w[1]), "f_y": float(std_w[2]),
            "theta": THETA_STD * recipe.noise_scale, "X": POS_STD * recipe.noise_scale,
            "Y": POS_STD * recipe.noise_scale}


def write_csv(path: str | os.PathLike, cols: dict[str, np.ndarray]) -> None:
    """The log as CSV in the payload column contract (t, M, f_x, f_y, theta, X, Y), full precision."""
    names = ("t", "M", "f_x", "f_y", "theta", "X", "Y")
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(names)
        for row in zip(*(cols[c] for c in names)):
            out.writerow([repr(float(v)) for v in row])
