"""The driver of ``n`` cars on any :class:`~fricenv.plants.braking_plant.BrakingPlant`: the plant advanced one
substep at a time, the episode accounting of each substep (distance, stop located inside the substep, friction
change, braking energy) on arrays over the cars.

:class:`PlantSubsteps` is a part of :class:`fricenv.envs.braking_sim.BrakingSim` (its state and
``_switch_road`` / ``_finish_step`` are the sim's). The sim's nominal cars take its compiled drivers instead (the
accounting car by car, :func:`fricenv.envs.episode.substep_accounting`); both give the same episode to about 1e-12
(tested).
"""

from __future__ import annotations

import numpy as np

from fricenv.envs.episode import brake_torque, stop_crossing

__all__ = ["PlantSubsteps"]


class PlantSubsteps:
    """The step of a :class:`~fricenv.envs.braking_sim.BrakingSim` whose plant is not the nominal one."""

    def _step_batch(self, action) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`step` of ``n`` cars of any plant on arrays, substep by substep (``action`` checked, clipped)."""
        plant = self.plant
        self.torque = brake_torque(action, self.torque, self.config)
        plant.set_torque(self.torque)
        v_start, w_start = self.v, self.omega
        energy, travel = self._substeps_batch()
        self.v, self.omega = plant.v.copy(), plant.omega.copy()
        self.t += 1
        self.slip = plant.slip()
        self.mu = plant.friction(self.slip)
        return self._finish_step(v_start, w_start, energy, travel)

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
