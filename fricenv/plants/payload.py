"""Planar payload held through a force-moment sensor (Liu, Leung, Tang & Jia), plain numpy.

State ``x = (theta, X, Y, theta', X', Y')`` [rad, m, m, rad/s, m/s, m/s], arrays of shape ``(..., 6)``.

Frames (our reading of the paper, Section 2 and Fig. 1). ``theta, X, Y`` are the pose of the payload's centre of
mass G in the inertial (vision) frame J. The sensor sits at the interface, ``rho = (rho_x, rho_y)`` from G,
expressed in the body frame B. The wrench ``w = (M, f_x, f_y)`` is the resultant applied at the interface and is
expressed in the body frame B (the sensor turns with the payload). Hence, eq. (1):

    I_G theta'' = M - rho_y f_x + rho_x f_y          (moment about G: M + rho x f, z-component)
    m X''       = cos(theta) f_x - sin(theta) f_y    (body force rotated into J)
    m Y''       = sin(theta) f_x + cos(theta) f_y

The true wrench is ``w = S w_hat`` (3); the sensor reads ``w_hat = S^-1 w + noise``. Noise (Section 4): the
paper says "variance of 5 % of the amplitude" for the wrench and "variances of 0.1 deg and 0.1 mm" for the vision;
the units (deg, mm) only make sense for standard deviations, so :class:`NoiseParams` reads all three as standard
deviations: sensor noise std = 5 % of each wrench element's amplitude, vision std 0.1 deg and 0.1 mm.

Integration. ``theta''`` does not depend on the state (only on the wrench), so eq. (1) is a cascade of two pure
quadratures: theta from the wrench, then X, Y from the wrench and theta. :func:`integrate` applies the classical
RK4 formulas to each quadrature (``v+ = v + h/6 (a0 + 4 a_half + a1)``, ``x+ = x + h v + h^2/6 (a0 + 2 a_half)``),
theta on a half-step grid so that X'' is available at RK4's mid points; all steps are done at once with cumulative
sums, so 100 s at 1 ms costs milliseconds. It is 4th order and checked against ``solve_ivp`` (DOP853) in the tests.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from fricenv.plants import liu_leung_tang_jia as paper

__all__ = [
    "NO_NOISE",
    "PAPER_NOISE",
    "PAPER_PARAMS",
    "PAPER_S",
    "PAPER_WRENCH_AMPLITUDE",
    "CalibrationSchedule",
    "NoiseParams",
    "PayloadParams",
    "Trajectory",
    "accelerations",
    "calibration_error",
    "constant_calibration",
    "derivatives",
    "integrate",
    "paper_wrench",
    "random_calibration",
    "sensor_reading",
    "simulate",
    "step",
    "table1_schedule",
    "vision",
]

# The paper's calibration matrix, Section 4, item 4.
PAPER_S = np.array(paper.CALIBRATION)

# Table 1: diagonal (s11, s22, s33) from these start times [s]; off-diagonal entries stay those of PAPER_S.
TABLE1_TIMES = paper.TABLE1_TIMES
TABLE1_DIAGONALS = paper.TABLE1_DIAGONALS

# Eq. (13): each wrench element is a sum of (amplitude, angular frequency [rad/s], phase [rad], is_cosine).
PAPER_WRENCH_TERMS = paper.WRENCH_TERMS
# Amplitude of each element of eq. (13) (sum of its term amplitudes): the reference of the "5 %" sensor noise.
PAPER_WRENCH_AMPLITUDE = np.array([sum(term[0] for term in terms) for terms in PAPER_WRENCH_TERMS])

# Random calibration matrices: entries uniform in [-RANDOM_S_BOUND, RANDOM_S_BOUND] (Section 4, Fig. 3).
RANDOM_S_BOUND = paper.RANDOM_S_BOUND
RANDOM_S_MAX_COND = 10.0  # rejection threshold on the 2-norm condition number
RANDOM_S_MAX_TRIES = 10_000


@dataclass(frozen=True)
class PayloadParams:
    """Mass properties and sensor location of the payload (Section 4, items 1-2)."""

    m: float = paper.MASS  # payload mass [kg]
    I_G: float = paper.INERTIA  # moment of inertia about the z-axis through G [kg m^2]
    rho_x: float = paper.RHO_X  # sensor interface from G, body-frame x [m]
    rho_y: float = paper.RHO_Y  # sensor interface from G, body-frame y [m]

    def __post_init__(self):
        for name in ("m", "I_G"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"PayloadParams.{name} must be finite and > 0, got {value!r}")
        for name in ("rho_x", "rho_y"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"PayloadParams.{name} must be finite, got {getattr(self, name)!r}")

    @property
    def moment_row(self) -> np.ndarray:
        """``(1, -rho_y, rho_x)``: ``I_G theta'' = moment_row . w``, eq. (1) first row."""
        return np.array([1.0, -self.rho_y, self.rho_x])


PAPER_PARAMS = PayloadParams()


@dataclass(frozen=True)
class NoiseParams:
    """Measurement noise (standard deviations; see the module docstring for the reading of the paper)."""

    wrench_rel: float = paper.WRENCH_NOISE_REL  # sensor noise std / each wrench element's amplitude [-]
    theta_std: float = float(np.deg2rad(paper.THETA_NOISE_DEG))  # vision orientation noise std [rad] (0.1 deg)
    position_std: float = paper.POSITION_NOISE  # vision position noise std [m] (0.1 mm)
    wrench_amplitude: tuple[float, float, float] = tuple(PAPER_WRENCH_AMPLITUDE)  # [N m, N, N], eq. (13)

    def __post_init__(self):
        for name in ("wrench_rel", "theta_std", "position_std"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"NoiseParams.{name} must be finite and >= 0, got {value!r}")
        amp = np.asarray(self.wrench_amplitude, dtype=float)
        if amp.shape != (3,) or not np.all(np.isfinite(amp)) or np.any(amp < 0):
            raise ValueError(f"NoiseParams.wrench_amplitude must be 3 finite values >= 0, got {self.wrench_amplitude!r}")

    @property
    def wrench_std(self) -> np.ndarray:
        """Sensor noise std of (M, f_x, f_y) [N m, N, N]."""
        return self.wrench_rel * np.asarray(self.wrench_amplitude, dtype=float)

    def scaled(self, wrench: float = 1.0, vision: float = 1.0) -> NoiseParams:
        """The same noise with the sensor and the vision standard deviations multiplied by the given factors."""
        return NoiseParams(self.wrench_rel * wrench, self.theta_std * vision, self.position_std * vision,
                           self.wrench_amplitude)


PAPER_NOISE = NoiseParams()
NO_NOISE = NoiseParams(0.0, 0.0, 0.0)


def paper_wrench(t) -> np.ndarray:
    """The multi-sine wrench of eq. (13) at times ``t`` [s]: shape ``(*t.shape, 3)`` = (M, f_x, f_y)."""
    t = np.asarray(t, dtype=float)
    out = np.zeros(t.shape + (3,))
    for i, terms in enumerate(PAPER_WRENCH_TERMS):
        for amp, omega, phase, is_cos in terms:
            out[..., i] += amp * (np.cos if is_cos else np.sin)(omega * t + phase)
    return out


@dataclass(frozen=True)
class CalibrationSchedule:
    """A calibration matrix that is piecewise constant in time: ``matrices[k]`` holds from ``times[k]`` on."""

    times: tuple[float, ...] = (0.0,)  # start time of each piece [s], increasing, first 0
    matrices: tuple = field(default_factory=lambda: (PAPER_S.copy(),))  # one 3x3 S [-] per piece

    def __post_init__(self):
        times = np.asarray(self.times, dtype=float)
        if times.ndim != 1 or times.size == 0 or times[0] != 0.0 or np.any(np.diff(times) <= 0):
            raise ValueError(f"CalibrationSchedule.times must start at 0 and increase, got {self.times!r}")
        if len(self.matrices) != times.size:
            raise ValueError(f"CalibrationSchedule needs one matrix per time, got {len(self.matrices)} matrices "
                             f"for {times.size} times")
        for k, S in enumerate(self.matrices):
            S = np.asarray(S, dtype=float)
            if S.shape != (3, 3) or not np.all(np.isfinite(S)):
                raise ValueError(f"CalibrationSchedule.matrices[{k}] must be a finite 3x3 matrix")
            if np.linalg.cond(S) > 1e12:
                raise ValueError(f"CalibrationSchedule.matrices[{k}] is singular")

    def index(self, t) -> np.ndarray:
        """Piece index at times ``t``."""
        return np.searchsorted(np.asarray(self.times), np.asarray(t, dtype=float), side="right") - 1

    def at(self, t) -> np.ndarray:
        """S at times ``t``: shape ``(*t.shape, 3, 3)``."""
        return np.asarray(self.matrices, dtype=float)[self.index(t)]

    def inverse_at(self, t) -> np.ndarray:
        """S^-1 at times ``t``: shape ``(*t.shape, 3, 3)``."""
        return np.linalg.inv(np.asarray(self.matrices, dtype=float))[self.index(t)]

    @property
    def change_times(self) -> tuple[float, ...]:
        """The times [s] at which S changes (all but the first start time)."""
        return tuple(float(t) for t in self.times[1:])


def constant_calibration(S=PAPER_S) -> CalibrationSchedule:
    """A calibration that never changes."""
    return CalibrationSchedule((0.0,), (np.asarray(S, dtype=float).copy(),))


def table1_schedule() -> CalibrationSchedule:
    """The paper's time-varying case (Table 1): s11, s22, s33 change at 100 s and 200 s."""
    mats = []
    for diag in TABLE1_DIAGONALS:
        S = PAPER_S.copy()
        S[np.diag_indices(3)] = diag
        mats.append(S)
    return CalibrationSchedule(TABLE1_TIMES, tuple(mats))


def random_calibration(rng: np.random.Generator, bound: float = RANDOM_S_BOUND,
                       max_cond: float = RANDOM_S_MAX_COND) -> np.ndarray:
    """A random S with entries uniform in ``[-bound, bound]``, redrawn until ``cond(S) <= max_cond``.

    :param rng: the random generator.
    :param bound: entry bound [-].
    :param max_cond: largest accepted 2-norm condition number (well conditioned calibration).
    """
    if not np.isfinite(max_cond) or max_cond < 1:
        raise ValueError(f"max_cond must be >= 1, got {max_cond!r}")
    for _ in range(RANDOM_S_MAX_TRIES):
        S = rng.uniform(-bound, bound, size=(3, 3))
        if np.linalg.cond(S) <= max_cond:
            return S
    raise ValueError(f"no S with cond <= {max_cond} found in {RANDOM_S_MAX_TRIES} draws; raise max_cond")


def calibration_error(S_hat, S) -> np.ndarray:
    """E = ||I - S_hat S^-1||_2, eq. (16); batched over leading dimensions."""
    S_hat = np.asarray(S_hat, dtype=float)
    S = np.asarray(S, dtype=float)
    D = np.eye(3) - S_hat @ np.linalg.inv(S)
    return np.linalg.norm(D, ord=2, axis=(-2, -1))


def accelerations(theta, w, p: PayloadParams = PAPER_PARAMS) -> np.ndarray:
    """(theta'', X'', Y'') of eq. (1) for true body-frame wrench ``w = (M, f_x, f_y)``; shape ``(..., 3)``."""
    w = np.asarray(w, dtype=float)
    theta = np.asarray(theta, dtype=float)
    M, fx, fy = w[..., 0], w[..., 1], w[..., 2]
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([(M - p.rho_y * fx + p.rho_x * fy) / p.I_G, (c * fx - s * fy) / p.m, (s * fx + c * fy) / p.m],
                    axis=-1)


def derivatives(state, w, p: PayloadParams = PAPER_PARAMS) -> np.ndarray:
    """Time derivative of the state ``(theta, X, Y, theta', X', Y')`` under wrench ``w``, eq. (1)."""
    state = np.asarray(state, dtype=float)
    return np.concatenate([state[..., 3:], accelerations(state[..., 0], w, p)], axis=-1)


def _rk4_quadrature(x0, v0, acc, h):
    """RK4 for x'' = a(t) on a grid of step ``h``; ``acc[..., 2k]`` at grid points, ``acc[..., 2k+1]`` at mid points.

    Returns x and v at the N+1 grid points (last axis). Exactly the classical RK4 result for a time-only right side.
    """
    a0, ah, a1 = acc[..., 0:-1:2], acc[..., 1::2], acc[..., 2::2]
    dv = h / 6.0 * (a0 + 4.0 * ah + a1)
    zeros = np.zeros(acc.shape[:-1] + (1,))
    v = v0[..., None] + np.concatenate([zeros, np.cumsum(dv, axis=-1)], axis=-1)
    dx = h * v[..., :-1] + h * h / 6.0 * (a0 + 2.0 * ah)
    x = x0[..., None] + np.concatenate([zeros, np.cumsum(dx, axis=-1)], axis=-1)
    return x, v


def integrate(state0, wrench_quarter, h: float, p: PayloadParams = PAPER_PARAMS) -> np.ndarray:
    """Integrate eq. (1) over N steps of ``h`` given the true wrench at quarter steps.

    :param state0: initial state, shape ``(..., 6)``.
    :param wrench_quarter: true wrench at ``t0 + j h/4``, ``j = 0..4N``, shape ``(..., 4N+1, 3)``.
    :param h: step [s].
    :param p: payload parameters.
    :return: states at ``t0 + n h``, ``n = 0..N``, shape ``(..., N+1, 6)``.
    """
    state0 = np.asarray(state0, dtype=float)
    wq = np.asarray(wrench_quarter, dtype=float)
    if wq.shape[-1] != 3 or (wq.shape[-2] - 1) % 4 != 0 or wq.shape[-2] < 5:
        raise ValueError(f"wrench_quarter must have shape (..., 4N+1, 3) with N >= 1, got {wq.shape}")
    if state0.shape[-1] != 6:
        raise ValueError(f"state0 must end in 6 entries (theta, X, Y, theta', X', Y'), got shape {state0.shape}")
    # theta on the half-step grid (step h/2, mid points at the quarter steps); theta'' depends on w only.
    a_theta = (wq @ p.moment_row) / p.I_G
    theta_half, omega_half = _rk4_quadrature(state0[..., 0], state0[..., 3], a_theta, h / 2.0)
    # X'', Y'' on the half-step grid, then RK4 with step h.
    acc = accelerations(theta_half, wq[..., ::2, :], p)
    X, VX = _rk4_quadrature(state0[..., 1], state0[..., 4], acc[..., 1], h)
    Y, VY = _rk4_quadrature(state0[..., 2], state0[..., 5], acc[..., 2], h)
    return np.stack([theta_half[..., ::2], X, Y, omega_half[..., ::2], VX, VY], axis=-1)


def step(state, w, dt: float, substeps: int, p: PayloadParams = PAPER_PARAMS) -> np.ndarray:
    """Hold the wrench ``w`` (zero-order hold) for ``dt`` and return the states at the ``substeps`` sub-steps.

    :param state: shape ``(..., 6)``.
    :param w: true wrench, shape ``(..., 3)``, constant over the step.
    :param dt: step length [s].
    :param substeps: number of equal sub-steps.
    :return: states at ``t0 + k dt/substeps``, ``k = 0..substeps``, shape ``(..., substeps+1, 6)``.
    """
    if int(substeps) != substeps or substeps < 1:
        raise ValueError(f"substeps must be a positive integer, got {substeps!r}")
    w = np.asarray(w, dtype=float)
    wq = np.broadcast_to(w[..., None, :], w.shape[:-1] + (4 * int(substeps) + 1, 3))
    return integrate(state, wq, dt / substeps, p)


def sensor_reading(w, S_inv, noise: NoiseParams, rng: np.random.Generator | None) -> np.ndarray:
    """The raw sensor reading ``w_hat = S^-1 w + noise``, eq. (3); ``S_inv`` broadcast, shape ``(..., 3, 3)``."""
    w = np.asarray(w, dtype=float)
    w_hat = np.einsum("...ij,...j->...i", np.asarray(S_inv, dtype=float), w)
    std = noise.wrench_std
    if rng is not None and np.any(std > 0):
        w_hat = w_hat + rng.standard_normal(w_hat.shape) * std
    return w_hat


def vision(state, noise: NoiseParams, rng: np.random.Generator | None) -> np.ndarray:
    """The vision measurement (theta, X, Y) with noise; shape ``(..., 3)``."""
    pose = np.array(np.asarray(state, dtype=float)[..., :3])
    if rng is not None:
        std = np.array([noise.theta_std, noise.position_std, noise.position_std])
        if np.any(std > 0):
            pose = pose + rng.standard_normal(pose.shape) * std
    return pose


@dataclass(frozen=True)
class Trajectory:
    """A simulated experiment sampled every ``dt``."""

    t: np.ndarray  # time [s], shape (n,)
    state: np.ndarray  # true state, shape (n, 6)
    w: np.ndarray  # true wrench [N m, N, N], shape (n, 3)
    w_hat: np.ndarray  # raw sensor reading, shape (n, 3)
    pose: np.ndarray  # vision (theta [rad], X [m], Y [m]), shape (n, 3)
    S: np.ndarray  # true calibration at each sample, shape (n, 3, 3)


def _integrate_euler(state0: np.ndarray, w: np.ndarray, h: float, p: PayloadParams) -> np.ndarray:
    """Explicit Euler on eq. (1) at the sample points (``w`` of shape (N+1, 3)); vectorised with cumulative sums."""
    a_theta = (w[:-1] @ p.moment_row) / p.I_G
    omega = state0[3] + np.concatenate([[0.0], np.cumsum(h * a_theta)])
    theta = state0[0] + np.concatenate([[0.0], np.cumsum(h * omega[:-1])])
    acc = accelerations(theta[:-1], w[:-1], p)
    out = np.empty((len(w), 6))
    out[:, 0], out[:, 3] = theta, omega
    for i, j in ((1, 4), (2, 5)):
        v = state0[j] + np.concatenate([[0.0], np.cumsum(h * acc[:, i])])
        out[:, i] = state0[i] + np.concatenate([[0.0], np.cumsum(h * v[:-1])])
        out[:, j] = v
    return out


INTEGRATORS = ("rk4", "euler")


def simulate(duration: float, dt: float = paper.SAMPLE_TIME, *, wrench: Callable = paper_wrench,
             calibration: CalibrationSchedule | None = None, noise: NoiseParams = PAPER_NOISE,
             rng: np.random.Generator | None = None, state0=None, p: PayloadParams = PAPER_PARAMS,
             integrator: str = "rk4") -> Trajectory:
    """Simulate the payload under a wrench given as a function of time, with sensor and vision measurements.

    The paper's set-up is free space: started at rest, the multi-sine of eq. (13) has a non-zero-mean velocity
    response, so the payload drifts (about 50 m and 65 rad after 100 s). Nothing in eq. (1) depends on X, Y, so
    this does not matter for calibration; the env keeps the payload in a workspace instead.

    :param duration: simulated time [s]; samples at ``0, dt, ..., duration``.
    :param dt: sample time and integration step [s].
    :param wrench: ``wrench(t) -> (..., 3)`` true body-frame wrench; default eq. (13).
    :param calibration: the true S over time; default the paper's constant S.
    :param noise: measurement noise; ``NO_NOISE`` for exact measurements.
    :param rng: random generator for the noise (required unless ``noise`` is zero).
    :param state0: initial state (default at rest at the origin).
    :param p: payload parameters.
    :param integrator: ``"rk4"`` (the accurate cascade of :func:`integrate`, default) or ``"euler"`` (explicit
        Euler at ``dt``, the same discretization as the paper's observer; used to show where the observer's
        noise-free floor comes from).
    """
    if integrator not in INTEGRATORS:
        raise ValueError(f"integrator must be one of {', '.join(INTEGRATORS)}, got {integrator!r}")
    if not np.isfinite(duration) or duration <= 0:
        raise ValueError(f"duration must be > 0 s, got {duration!r}")
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"dt must be > 0 s, got {dt!r}")
    calibration = calibration or constant_calibration()
    n = round(duration / dt)
    tq = np.arange(4 * n + 1) * (dt / 4.0)
    wq = np.asarray(wrench(tq), dtype=float)
    x0 = np.zeros(6) if state0 is None else np.asarray(state0, dtype=float)
    t = tq[::4]
    states = integrate(x0, wq, dt, p) if integrator == "rk4" else _integrate_euler(x0, wq[::4], dt, p)
    w = wq[::4]
    noisy = noise.wrench_rel > 0 or noise.theta_std > 0 or noise.position_std > 0
    if noisy and rng is None:
        raise ValueError("rng is required when the noise is not zero")
    w_hat = sensor_reading(w, calibration.inverse_at(t), noise, rng)
    pose = vision(states, noise, rng)
    return Trajectory(t, states, w, w_hat, pose, calibration.at(t))


# Random excitation: eq. (13)'s terms with frequencies scaled in this range [-] and uniform random phases.
RANDOM_WRENCH_FREQ_SCALE = (0.7, 1.4)
WRENCH_KINDS = ("paper", "random")


def multisine_wrench(kind: str, rng: np.random.Generator):
    """A true wrench ``w(t)``: the paper's multi-sine, eq. (13), or a random variant of it.

    :param kind: ``"paper"`` or ``"random"`` (eq. (13)'s amplitudes, frequencies scaled by a factor drawn in
        :data:`RANDOM_WRENCH_FREQ_SCALE`, random phases).
    :param rng: generator for the random variant.
    :return: a function of time ``t`` (array) returning ``(..., 3)`` wrenches (M, f_x, f_y).
    """
    if kind == "paper":
        return paper_wrench
    if kind != "random":
        raise ValueError(f"unknown wrench {kind!r}; valid: {', '.join(WRENCH_KINDS)}")
    terms = [[(a, w * rng.uniform(*RANDOM_WRENCH_FREQ_SCALE), rng.uniform(0, 2 * np.pi)) for a, w, _, _ in row]
             for row in PAPER_WRENCH_TERMS]

    def wrench(t):
        t = np.asarray(t, dtype=float)
        out = np.zeros(t.shape + (3,))
        for i, row in enumerate(terms):
            for a, w, ph in row:
                out[..., i] += a * np.sin(w * t + ph)
        return out

    return wrench
