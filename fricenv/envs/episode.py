"""One braking episode over a plant: the actuator, the substep accounting (stop and friction change located inside
the substep), the wheel-lock counter, the ECU measurement, the reward, written once.

The model is a handful of pure functions below (:func:`brake_torque`, :func:`stop_crossing`, :func:`lock_count`,
:func:`measure`, :func:`step_reward`, :func:`substep_accounting`, :func:`car_substeps`): plain arithmetic, so the
same function serves floats (one car) and arrays over ``n`` cars. :class:`fricenv.envs.braking_sim.BrakingSim`
steps its cars with them in three drivers that differ only in control flow: ``n`` nominal cars through
:func:`cars_substeps_compiled` (the substeps of one control step of every car in one compiled call: the ROS2
substep of :mod:`fricenv.plants.rosenbrock` compiled on arrays, the accounting car by car), the single nominal car
(``Braking-v0``) through :func:`car_substeps_compiled` (:func:`car_substeps` compiled on floats), and ``n`` cars on
any :class:`~fricenv.plants.braking_plant.BrakingPlant` one plant substep at a time with the same compiled
accounting (:func:`cars_accounting`). The first two do each car's arithmetic in the same order (tested equal); the
third gives the same episode to about 1e-12 (tested).

Measurement model (an ABS ECU), per control step of ``dt``: wheel speed ``omega + e`` (variance
``OMEGA_NOISE_VAR``, Sui & Johansen Section V); wheel deceleration ``-r (omega_k - omega_{k-1}) / dt + e`` with the
nominal radius ``r`` (the ECU does not know an effective radius); longitudinal acceleration
``(v_k - v_{k-1}) / dt + e``. Wheel lock: ``omega r_eff < lock_speed_ratio v`` above ``v_stop`` for more than
``lock_time`` (the plant's effective rolling radius: the physical test).

Measurement noise (:class:`NoiseBlocks`): each car's standard normals come from its own generator,
:data:`~fricenv.envs.config.NOISE_BLOCK` control steps at a time, and are consumed by index. A car therefore sees
the same noise whether it is simulated alone or in a batch, and whatever the other cars do.
"""

from __future__ import annotations

import math

import numpy as np

from fricenv.envs.config import N_NOISE, NOISE_BLOCK
from fricenv.plants.compiled import compile_array_formula, compile_formula, guard_cache, jit, substep_refined
from fricenv.plants.rosenbrock import REFINE_MIN_STEP, ros2_substep
from fricenv.plants.tire import longitudinal_slip, magic_formula

__all__ = ["ACCOUNTING_ROWS", "CAR_OUTPUTS", "TINY", "NoiseBlocks", "brake_torque", "car_substeps",
           "car_substeps_compiled", "cars_accounting", "cars_substeps_compiled", "clip_float", "lock_count", "measure",
           "start_accounting", "step_reward", "stop_crossing", "substep_accounting"]

TINY = 1e-300  # guard of the crossing interpolations


def clip_float(x: float, lo: float, hi: float) -> float:
    """``x`` clipped to [lo, hi], in floats."""
    return lo if x < lo else (hi if x > hi else x)  # noqa: FURB136 (no builtin calls in the hot path)


def brake_torque(a, torque_prev, config, clip=np.clip):
    """Brake torque [N m] of a (clipped) normalised command: ``(a + 1) t_max / 2`` in torque mode, the previous
    torque plus ``a torque_rate_max dt`` kept in [0, t_max] in torque-rate mode.

    :param a: command in [-1, 1] (float or array).
    :param torque_prev: the torque of the previous control step [N m].
    :param config: the :class:`~fricenv.envs.config.BrakingConfig`.
    :param clip: ``np.clip`` for arrays, a float clip for floats.
    """
    if config.action_mode == "torque":
        return (a + 1.0) * (0.5 * config.t_max)
    return clip(torque_prev + a * (config.torque_rate_max * config.dt), 0.0, config.t_max)


def stop_crossing(v, v_new, v_stop: float):
    """Shares of a substep's distance and time before the speed falls from ``v`` through ``v_stop`` to ``v_new``.

    At constant deceleration over the substep ``v^2`` is linear in distance and ``v`` in time.

    :return: (distance share, time share), each in [0, 1].
    """
    return ((v * v - v_stop * v_stop) / np.maximum(v * v - v_new * v_new, TINY),
            (v - v_stop) / np.maximum(v - v_new, TINY))


def lock_count(count, w, v, r_eff, config):
    """Consecutive control steps with the lock condition ``omega r_eff < lock_speed_ratio v`` above ``v_stop``
    (0 when it does not hold); the wheel is locked while the count exceeds ``config.lock_steps``."""
    return (count + 1) * ((w * r_eff < config.lock_speed_ratio * v) & (v > config.v_stop))


def measure(w, w_start, v, v_start, noise0, noise1, noise2, r: float, dt: float):
    """ECU measurements (wheel speed, wheel deceleration, a_x) from the state at the start and end of the control
    step and the scaled noise draws (see the module docstring)."""
    return w + noise0, (w_start - w) * (r / dt) + noise1, (v - v_start) / dt + noise2


def step_reward(energy, travel, limit, locked, lock_penalty: float):
    """Braking efficiency of the step, ``(energy - travel) / limit`` (<= 0, 0 at the friction peak), minus the lock
    penalty while locked (see ``BrakingEnv``'s docstring)."""
    return (energy - travel) / limit - lock_penalty * locked


class NoiseBlocks:
    """Blocks of standard normals per car (one column per noisy channel), scaled by ``std`` when taken.

    :param n: number of cars.
    :param std: standard deviation of each channel (wheel speed, wheel deceleration, a_x).
    """

    def __init__(self, n: int, std: np.ndarray):
        self.std = np.asarray(std, dtype=float)
        self.sd = tuple(self.std.tolist())
        self.blocks = np.zeros((n, NOISE_BLOCK, N_NOISE))
        self.pos = np.zeros(n, dtype=np.intp)
        self._rows = self.blocks.reshape(n * NOISE_BLOCK, N_NOISE)  # a view of the blocks
        self._row_base = np.arange(n) * NOISE_BLOCK
        self.rngs: list[np.random.Generator | None] = [None] * n

    def start(self, i: int, rng: np.random.Generator) -> None:
        """Car ``i`` starts an episode on generator ``rng``: a fresh block, read from its first row."""
        self.rngs[i] = rng
        self.refill(i)

    def refill(self, i: int) -> None:
        """A new block of standard normals for car ``i`` from its generator, read from its first row."""
        self.blocks[i] = self.rngs[i].standard_normal((NOISE_BLOCK, N_NOISE))
        self.pos[i] = 0

    def take(self, idx: np.ndarray | None = None) -> np.ndarray:
        """The next scaled noise rows of the cars ``idx`` (all if None), one row per channel: (N_NOISE, len);
        refills exhausted blocks."""
        if idx is None:  # every car: gather one row per car from the flat (n * NOISE_BLOCK, N_NOISE) view
            pos = self.pos
            raw = np.take(self._rows, self._row_base + pos, axis=0)
            pos += 1
        else:
            pos = self.pos[idx]
            raw = self.blocks[idx, pos]
            pos += 1
            self.pos[idx] = pos
        out = np.empty((N_NOISE, len(raw)))
        for j, sd in enumerate(self.sd):  # one contiguous row per channel
            np.multiply(raw[:, j], sd, out=out[j])
        if pos.max() >= NOISE_BLOCK:
            for i in np.flatnonzero(self.pos >= NOISE_BLOCK):  # once every NOISE_BLOCK steps per car
                self.refill(i)
        return out

    def take_one(self) -> tuple[float, float, float]:
        """The next scaled noise row of car 0, as floats (the single env's path)."""
        pos = int(self.pos[0])
        blocks, k = self.blocks, pos * N_NOISE  # flat index of the row in car 0's block
        s0, s1, s2 = self.sd
        row = (blocks.item(k) * s0, blocks.item(k + 1) * s1, blocks.item(k + 2) * s2)
        if pos + 1 >= NOISE_BLOCK:
            self.refill(0)
        else:
            self.pos[0] = pos + 1
        return row


def substep_accounting(sub, v, v_new, x, energy, travel, stopped, stop_x, stop_sub, switched, change, h, v_stop,
                       inv_2g_mu, inv_2g_mu_b):
    """The accounting of one physics substep of one car from ``v`` to ``v_new``: distance (trapezoid), braking
    energy and travel above ``v_stop``, the stop located inside the substep, the friction change point.

    :param sub: index of the substep in the control step.
    :param v: speed before and :param v_new: after the substep [m/s]; :param x: distance before it [m].
    :param energy: braking energy [m] and :param travel: travel [m] of the control step so far.
    :param stopped: the car has stopped; :param stop_x: :param stop_sub: the stop's distance and substep position
        if the first stop happened in this control step (NaN otherwise).
    :param switched: the change point was passed in this control step; :param change: its distance [m] (inf once
        passed in an earlier step).
    :param h: substep [s]; :param v_stop: stop speed [m/s].
    :param inv_2g_mu: ``1 / (2 g mu_max)`` of the road in use at the start of the step; :param inv_2g_mu_b: the
        same after the change.
    :return: (x, energy, travel, stopped, stop_x, stop_sub, switched) after the substep.
    """
    inv = inv_2g_mu_b if switched else inv_2g_mu
    dx = (0.5 * h) * (v + v_new)
    if v > v_stop:
        if v_new <= v_stop:
            frac, tfrac = stop_crossing(v, v_new, v_stop)
            if not stopped:
                stop_x, stop_sub = x + frac * dx, sub + tfrac
            stopped = True
            energy += (v * v - v_stop * v_stop) * inv
            travel += frac * dx
        else:
            energy += (v - v_new) * (v + v_new) * inv
            travel += dx
    x += dx
    return x, energy, travel, stopped, stop_x, stop_sub, switched or x >= change


def car_substeps(v, w, x, Tb, roads, change, stopped, substeps, h, v_stop, inv_2g_mu, inv_2g_mu_b, r, m, J, Fz):
    """The physics substeps of one control step of one nominal car with their accounting
    (:func:`substep_accounting`), on floats.

    :param v: speed [m/s]; :param w: wheel speed [rad/s]; :param x: distance [m] at the start of the step.
    :param Tb: brake torque [N m] over the step.
    :param roads: (2, 5) array, rows (B, C, E, theta, mu(1)) of the road in use and of the road after the change
        point.
    :param change: distance of the change point [m] (inf once passed); :param stopped: the car has stopped before.
    :param substeps: physics substeps per control step; :param h: substep [s]; :param v_stop: stop speed [m/s].
    :param inv_2g_mu: ``1 / (2 g mu_max)`` of the road in use; :param inv_2g_mu_b: the same after the change.
    :param r: wheel radius [m]; :param m: mass [kg]; :param J: wheel inertia [kg m^2]; :param Fz: tire load [N].
    :return: (v, omega, x, energy [m], travel [m], stopped, stop distance (NaN if not this step), stop substep
        position in [0, substeps] (NaN if not this step), switched, slip, mu) at the end of the step.
    """
    B, C, E, theta, mu1 = roads[0, 0], roads[0, 1], roads[0, 2], roads[0, 3], roads[0, 4]
    energy = travel = 0.0
    stop_x = stop_sub = math.nan
    switched = False
    for sub in range(substeps):
        v_new, w_new, broken = ros2_substep(v, w, Tb, B, C, E, theta, mu1, h, r, m, J, Fz)  # the common case
        if broken and h > REFINE_MIN_STEP:  # rare: the refinement (recursive, so called, not inlined)
            v_new, w_new = substep_refined(v, w, Tb, B, C, E, theta, mu1, h, r, m, J, Fz)
        passed = switched
        x, energy, travel, stopped, stop_x, stop_sub, switched = substep_accounting(
            sub, v, v_new, x, energy, travel, stopped, stop_x, stop_sub, switched, change, h, v_stop, inv_2g_mu,
            inv_2g_mu_b)
        v, w = v_new, w_new
        if switched and not passed:  # the road after the change point from the next substep on
            B, C, E, theta, mu1 = roads[1, 0], roads[1, 1], roads[1, 2], roads[1, 3], roads[1, 4]
    lam = longitudinal_slip(v, w, r)
    return v, w, x, energy, travel, stopped, stop_x, stop_sub, switched, lam, magic_formula(lam, B, C, E, theta)


_car_substeps = compile_formula(car_substeps)
_substep_accounting = compile_formula(substep_accounting)
# the same formulas compiled on arrays: numba runs each statement as one loop over the cars
_ros2_cars = compile_array_formula(ros2_substep)
_slip_cars = compile_array_formula(longitudinal_slip)
_mf_cars = compile_array_formula(magic_formula)


@jit
def car_substeps_compiled(v, w, x, Tb, roads, change, stopped, substeps, h, v_stop, inv_2g_mu, inv_2g_mu_b, r, m,
                          J, Fz):
    """:func:`car_substeps` compiled (numba, cached on disk)."""
    return _car_substeps(v, w, x, Tb, roads, change, stopped, substeps, h, v_stop, inv_2g_mu, inv_2g_mu_b, r, m, J,
                         Fz)


# the rows of :func:`cars_substeps_compiled`'s output, the values :func:`car_substeps` returns
CAR_OUTPUTS = ("v", "omega", "x", "energy", "travel", "stopped", "stop_x", "stop_sub", "switched", "slip", "mu")


# the rows of :func:`cars_accounting`'s ``acc`` array (0.0 / 1.0 for the flags)
ACCOUNTING_ROWS = ("x", "energy", "travel", "stopped", "stop_x", "stop_sub", "switched")


@jit
def cars_accounting(sub, v, v_new, acc, change, h, v_stop, inv_2g_mu):
    """:func:`substep_accounting` of one substep of ``n`` cars, car by car, in place.

    :param sub: index of the substep in the control step.
    :param v: speeds before and :param v_new: after the substep, (n,).
    :param acc: (len(ACCOUNTING_ROWS), n) float array, the accounting so far (:data:`ACCOUNTING_ROWS`), updated.
    :param change: (n,) change points (inf once passed); :param h: substep [s]; :param v_stop: stop speed [m/s].
    :param inv_2g_mu: (n, 2), each car's ``inv_2g_mu`` and ``inv_2g_mu_b`` of :func:`car_substeps`.
    """
    for i in range(v.shape[0]):
        acc[0, i], acc[1, i], acc[2, i], acc[3, i], acc[4, i], acc[5, i], acc[6, i] = _substep_accounting(
            sub, v[i], v_new[i], acc[0, i], acc[1, i], acc[2, i], acc[3, i] != 0.0, acc[4, i], acc[5, i],
            acc[6, i] != 0.0, change[i], h, v_stop, inv_2g_mu[i, 0], inv_2g_mu[i, 1])


@jit
def start_accounting(x, stopped, acc):
    """The accounting rows of ``n`` cars at the start of a control step (:data:`ACCOUNTING_ROWS`), into ``acc``."""
    for i in range(x.shape[0]):
        acc[0, i], acc[1, i], acc[2, i], acc[3, i] = x[i], 0.0, 0.0, stopped[i]
        acc[4, i], acc[5, i], acc[6, i] = math.nan, math.nan, 0.0


@jit
def cars_substeps_compiled(v, w, x, Tb, roads, change, stopped, inv_2g_mu, substeps, h, v_stop, r, m, J, Fz, out):
    """:func:`car_substeps` of ``n`` cars in one compiled call, the same arithmetic per car: each substep's ROS2
    formula on arrays over the cars (:func:`fricenv.plants.rosenbrock.ros2_substep`), the refinement and
    :func:`cars_accounting` car by car.

    :param v: speeds, (n,); :param w: wheel speeds, (n,); :param x: distances, (n,); :param Tb: brake torques,
        (n,); :param roads: (n, 2, 5), each car's ``roads`` of :func:`car_substeps`; :param change: (n,) change
        points (inf once passed); :param stopped: (n,) bool; :param inv_2g_mu: (n, 2), each car's ``inv_2g_mu``
        and ``inv_2g_mu_b``; the scalars as in :func:`car_substeps`.
    :param out: (len(CAR_OUTPUTS), n) float array: row ``k`` receives the ``k``-th value of :func:`car_substeps`
        (:data:`CAR_OUTPUTS`; the flags as 0.0 / 1.0).
    """
    n = v.shape[0]
    B, C, E = roads[:, 0, 0].copy(), roads[:, 0, 1].copy(), roads[:, 0, 2].copy()
    theta, mu1 = roads[:, 0, 3].copy(), roads[:, 0, 4].copy()
    acc = out[2:9]  # the accounting rows of CAR_OUTPUTS
    start_accounting(x, stopped, acc)
    for sub in range(substeps):
        v_new, w_new, broken = _ros2_cars(v, w, Tb, B, C, E, theta, mu1, h, r, m, J, Fz)
        for i in range(n):
            if broken[i] and h > REFINE_MIN_STEP:
                v_new[i], w_new[i] = substep_refined(v[i], w[i], Tb[i], B[i], C[i], E[i], theta[i], mu1[i], h, r, m,
                                                     J, Fz)
        passed = acc[6] != 0.0
        cars_accounting(sub, v, v_new, acc, change, h, v_stop, inv_2g_mu)
        for i in range(n):
            if acc[6, i] != 0.0 and not passed[i]:  # the road after the change point from the next substep on
                B[i], C[i], E[i] = roads[i, 1, 0], roads[i, 1, 1], roads[i, 1, 2]
                theta[i], mu1[i] = roads[i, 1, 3], roads[i, 1, 4]
        v, w = v_new, w_new
    lam = _slip_cars(v, w, r)
    out[0], out[1], out[9], out[10] = v, w, lam, _mf_cars(lam, B, C, E, theta)


guard_cache(globals(), ("fricenv.envs.episode",))
