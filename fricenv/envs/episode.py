"""One braking episode over a plant: the actuator, the substep accounting (stop and friction change located inside
the substep), the wheel-lock counter, the ECU measurement, the reward, written once.

The model is a handful of pure functions below (:func:`brake_torque`, :func:`stop_crossing`, :func:`lock_count`,
:func:`measure`, :func:`step_reward`): plain arithmetic, so the same function serves Python floats (one car) and
arrays over ``n`` cars. :class:`EpisodeSteps` is the control step of :class:`fricenv.envs.braking_sim.BrakingSim`
built from them, in two drivers that differ only in control flow:

* :meth:`EpisodeSteps._step_batch`: ``n`` cars on any :class:`~fricenv.plants.braking_plant.BrakingPlant`
  (the nominal :class:`~fricenv.plants.braking_plant.BatchPlant` or the effect-carrying
  :class:`~fricenv.envs.effect_plant.EffectPlant`), arrays, no Python loop over cars;
* :meth:`EpisodeSteps._step_scalar`: one car on :class:`~fricenv.plants.braking_plant.ScalarPlant` in Python
  floats (``Braking-v0``; numpy's per-call cost on 1-element arrays is larger than the arithmetic).

Both give the same episode to about 1e-12 (``math`` and numpy round transcendentals differently; tested).

Measurement model (an ABS ECU), per control step of ``dt``: wheel speed ``omega + e`` (variance
``OMEGA_NOISE_VAR``, Sui & Johansen Section V); wheel deceleration ``-r (omega_k - omega_{k-1}) / dt + e`` with the
nominal radius ``r`` (the ECU does not know an effective radius); longitudinal acceleration
``(v_k - v_{k-1}) / dt + e``. Wheel lock: ``omega r_eff < lock_speed_ratio v`` above ``v_stop`` for more than
``lock_time`` (the plant's effective rolling radius: the physical test).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["TINY", "EpisodeSteps", "brake_torque", "lock_count", "measure", "step_reward", "stop_crossing"]

TINY = 1e-300  # guard of the crossing interpolations


def _clip_float(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else (hi if x > hi else x)  # noqa: FURB136 (no builtin calls in the hot path)


def brake_torque(a, torque_prev, config, clip=np.clip):
    """Brake torque [N m] of a (clipped) normalised command: ``(a + 1) t_max / 2`` in torque mode, the previous
    torque plus ``a torque_rate_max dt`` kept in [0, t_max] in torque-rate mode.

    :param a: command in [-1, 1] (float or array).
    :param torque_prev: the torque of the previous control step [N m].
    :param config: the :class:`~fricenv.envs.braking_core.BrakingConfig`.
    :param clip: ``np.clip`` for arrays, a float clip for floats.
    """
    if config.action_mode == "torque":
        return (a + 1.0) * (0.5 * config.t_max)
    return clip(torque_prev + a * (config.torque_rate_max * config.dt), 0.0, config.t_max)


def stop_crossing(v, v_new, v_stop: float, maximum=np.maximum):
    """Shares of a substep's distance and time before the speed falls from ``v`` through ``v_stop`` to ``v_new``.

    At constant deceleration over the substep ``v^2`` is linear in distance and ``v`` in time.

    :return: (distance share, time share), each in [0, 1].
    """
    return ((v * v - v_stop * v_stop) / maximum(v * v - v_new * v_new, TINY),
            (v - v_stop) / maximum(v - v_new, TINY))


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


class EpisodeSteps:
    """The control step of :class:`~fricenv.envs.braking_sim.BrakingSim` (a mixin: it uses the sim's state)."""

    def _check_action(self, action) -> np.ndarray:
        a = np.asarray(action, dtype=float)
        if a.shape != (self.n,):
            if a.shape == (self.n, 1):
                a = a[:, 0]
            else:
                raise ValueError(f"action must have shape ({self.n},) (one command per car), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action contains NaN or inf: {a[~np.isfinite(a)][:5].tolist()}")
        return np.clip(a, -1.0, 1.0)

    def _step_batch(self, action) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`step` of ``n`` cars on arrays."""
        a = self._check_action(action)
        c, p, plant = self.config, self._p, self.plant
        self.torque = brake_torque(a, self.torque, c)
        plant.set_torque(self.torque)
        v_start, w_start = self.v, self.omega
        energy, travel = self._substeps_batch()
        v, w = self.v, self.omega = plant.v.copy(), plant.omega.copy()
        self.t += 1
        self.slip = plant.slip()
        self.mu = plant.friction(self.slip)
        self.lock_count = lock_count(self.lock_count, w, v, plant.r_eff, c)
        self.locked = self.lock_count > c.lock_steps
        self.lock_seen |= self.locked
        noise = self._take_noise()
        self.meas[:, 0], self.meas[:, 1], self.meas[:, 2] = measure(
            w, w_start, v, v_start, noise[:, 0], noise[:, 1], noise[:, 2], p.r, c.dt)
        self.reward = step_reward(energy, travel, self.limit, self.locked, c.lock_penalty)
        self.terminated = self.stopped.copy()
        self.truncated = (self.t >= self._max_steps) & ~self.terminated
        return self.observe(), self.reward, self.terminated, self.truncated

    def _substeps_batch(self) -> tuple[np.ndarray, np.ndarray]:
        """The physics substeps of one control step: distance, stop crossing, road switch, braking energy.

        Substep sums (scaled once at the end): ssum = sum of (v_k + v_k+1), so x = x0 + h/2 ssum (trapezoid: the
        speed is nearly linear over a substep); esum = sum of (v_k^2 - v_k+1^2) and tsum = sum of (v_k + v_k+1)
        while above v_stop, so the braking energy is esum / (2 g mu_peak) and the travel h/2 tsum.

        :return: (energy, travel) [m] of the step per car.
        """
        c, plant, n, v_stop = self.config, self.plant, self.n, self.config.v_stop
        half_h = 0.5 * self._h
        v, x0 = self.v, self.x
        ssum, esum, tsum, energy = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
        inv_2g_mu = 1.0 / (2.0 * self._p.g * self.mu_peak)
        # Road switches are checked only if some car can reach its change point in this step.
        check_switch = float((self._next_change - x0).min()) <= c.dt * (float(v.max()) + self._reach_slack)
        v_above = v.min() > v_stop  # every car above the stop speed at the start of the substep
        for sub in range(c.substeps):
            v_new = plant.substep()[0]
            s = v + v_new
            d = (v - v_new) * s  # v_k^2 - v_k+1^2
            new_above = v_new.min() > v_stop
            if not (v_above and new_above):  # some car at or below the stop speed: mask it, locate crossings
                active = v > v_stop
                d *= active
                s_act = s * active
                cross = np.flatnonzero(active & (v_new <= v_stop))
                if cross.size:
                    d[cross], s_act[cross] = self._stop_in_substep(cross, sub, v, v_new, s, x0 + half_h * ssum)
                s_tot = s_act
            else:
                s_tot = s
            esum += d
            tsum += s_tot
            ssum += s
            v, v_above = v_new, new_above
            if check_switch:
                switch = np.flatnonzero(x0 + half_h * ssum >= self._next_change)
                if switch.size:
                    energy[switch] += esum[switch] * inv_2g_mu[switch]  # close the energy segment on road a
                    esum[switch] = 0.0
                    self._switch_road(switch)
                    inv_2g_mu = 1.0 / (2.0 * self._p.g * self.mu_peak)
        energy += esum * inv_2g_mu  # sum of (v^2 drop) / (2 g mu_peak) over substeps [m]
        self.x = x0 + ssum * half_h
        return energy, tsum * half_h

    def _stop_in_substep(self, cross, sub: int, v, v_new, s, x_start) -> tuple[np.ndarray, np.ndarray]:
        """Record the stop of the cars ``cross`` that fall through ``v_stop`` in substep ``sub`` (first time only);
        return their ``v^2`` drop and speed sum down to ``v_stop``."""
        v_stop = self.config.v_stop
        vc, vn = v[cross], v_new[cross]
        frac, tfrac = stop_crossing(vc, vn, v_stop)
        first = ~self.stopped[cross]  # cars stopping for the first time this episode
        idx = cross[first]
        self.stop_distance[idx] = (x_start[cross] + frac * (0.5 * self._h * s[cross]))[first]
        self.stop_time[idx] = ((self.t[cross] + (sub + tfrac) / self.config.substeps) * self.config.dt)[first]
        self.stopped[cross] = True
        return vc * vc - v_stop * v_stop, frac * s[cross]

    def _switch_road(self, idx) -> None:
        """Cars ``idx`` pass their friction-change point: road b from now on."""
        self.road[idx] = self.road_b[idx]
        self.plant.set_road(idx, self.road[idx])
        self.mu_peak[idx] = self.mu_peak_b[idx]
        self.switched[idx] = True
        self._next_change[idx] = np.inf

    def _step_scalar(self, action) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`step` of one car on :class:`~fricenv.plants.braking_plant.ScalarPlant`, in Python floats."""
        a = np.asarray(action, dtype=float)
        if a.shape not in ((1,), (1, 1)):
            raise ValueError(f"action must have shape (1,) (one command per car), got {a.shape}")
        a = a.item(0)
        if not math.isfinite(a):
            raise ValueError(f"action contains NaN or inf: {[a]}")
        c, p, plant = self.config, self._p, self.plant
        Tb = brake_torque(_clip_float(a, -1.0, 1.0), self.torque.item(0), c, _clip_float)
        plant.set_torque(Tb)
        v_start, w_start = plant.v, plant.omega
        energy, travel = self._substeps_scalar()
        v, w = plant.v, plant.omega
        self.v[0], self.omega[0], self.torque[0] = v, w, Tb
        self.t[0] = steps = self.t.item(0) + 1
        slip = plant.slip()
        self.slip[0], self.mu[0] = slip, plant.friction(slip)
        count = lock_count(self.lock_count.item(0), w, v, plant.r_eff.item(0), c)
        self.lock_count[0] = count
        locked = count > self._lock_steps
        self.locked[0] = locked
        if locked:
            self.lock_seen[0] = True
        n0, n1, n2 = self._take_noise_scalar()
        m0, m1, m2 = measure(w, w_start, v, v_start, n0, n1, n2, p.r, c.dt)
        self.meas[0, 0], self.meas[0, 1], self.meas[0, 2] = m0, m1, m2
        stopped = self.stopped.item(0)
        self.reward[0] = step_reward(energy, travel, self.limit.item(0), locked, c.lock_penalty)
        self.terminated[0] = stopped
        self.truncated[0] = steps >= self._max_steps and not stopped
        return self._observe_scalar(m0, m1, Tb, m2, v, slip, self.mu.item(0)), self.reward, \
            self.terminated, self.truncated

    def _substeps_scalar(self) -> tuple[float, float]:
        """:meth:`_substeps_batch` of the one car in floats; returns (energy, travel) [m]."""
        c, plant, v_stop, half_h = self.config, self.plant, self.config.v_stop, 0.5 * self._h
        advance = plant.advance  # the substep as a pure function: the state stays local until the end
        v, w = plant.v, plant.omega
        x = self.x.item(0)
        energy = travel = 0.0
        stopped = self.stopped.item(0)
        change = self._next_change.item(0)
        inv_2g_mu = 1.0 / (2.0 * self._p.g * self.mu_peak.item(0))
        for sub in range(self._substeps):
            v_new, w = advance(v, w)
            dx = half_h * (v + v_new)
            if v > v_stop:
                if v_new <= v_stop:
                    frac, tfrac = stop_crossing(v, v_new, v_stop, max)
                    if not stopped:
                        self.stop_distance[0] = x + frac * dx
                        self.stop_time[0] = (self.t.item(0) + (sub + tfrac) / self._substeps) * c.dt
                    stopped = True
                    energy += (v * v - v_stop * v_stop) * inv_2g_mu
                    travel += frac * dx
                else:
                    energy += (v - v_new) * (v + v_new) * inv_2g_mu
                    travel += dx
            x += dx
            v = v_new
            if x >= change:
                self._switch_road([0])
                advance = plant.advance
                change = np.inf
                inv_2g_mu = 1.0 / (2.0 * self._p.g * self.mu_peak.item(0))
        plant.v, plant.omega = v, w
        self.x[0] = x
        self.stopped[0] = stopped
        return energy, travel

    def _take_noise_scalar(self) -> tuple[float, float, float]:
        """The next scaled noise row of the one car (the block scheme of ``_take_noise``), as floats."""
        pos = self._noise_idx.item(0)
        noise, k = self._noise, pos * 3  # flat index of the row in car 0's block
        s0, s1, s2 = self._noise_sd
        row = (noise.item(k) * s0, noise.item(k + 1) * s1, noise.item(k + 2) * s2)
        pos += 1
        if pos >= noise.shape[1]:
            self._refill_noise(0)
            pos = 0
        self._noise_idx[0] = pos
        return row
