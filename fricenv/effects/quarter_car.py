"""Unmodelled effects of the quarter-car braking plant (docs/contracts.md).

Each effect is a typed, frozen spec whose name and parameter names are the docs/contracts.md contract; the specs and
their registry entries are in :mod:`fricenv.effects.library` (the table there), the registry in
:mod:`fricenv.effects.registry`. This module re-exports them.

:class:`EffectSimulator` is the one simulator with effects, batched over a leading dimension whose elements may each
carry their own effect parameters (a :class:`ModelBatch`). It layers the effects around the plant of
:mod:`fricenv.plants.quarter_car`:

- actuator effects (delay -> lag -> gain) form the torque seen by the wheel; the delay averages the zero-order-held
  command exactly over each physics substep and the lag uses its exact ZOH solution, so both are continuous in their
  parameters (which the gap tool's fits need);
- the wheel/vehicle dynamics are :func:`fricenv.plants.quarter_car.step` (ROS2), one call per substep, with the road's
  theta switched (and blended within the switching substep) for ``mu_change``, the wheel radius replaced for
  ``radius_error`` (elements grouped by radius, since the plant takes one parameter set per call), and the drag force
  added by Strang splitting (it varies on the vehicle's slow time scale);
- ``relaxation_length`` changes the tire force law (the force depends on a third state, the transient slip), which
  cannot be expressed through ``quarter_car.step``: those elements are integrated by
  :func:`fricenv.effects.relaxation.relaxation_step`;
- a plug-in effect (registered with ``builtin=False``) acts through its registry hooks on the applied torque and
  the road's peak factor.

Three physically real effects that are NOT in the library are built in for the gap tool's validation on withheld
effects (:data:`OUT_OF_LIBRARY`): temperature brake fade, pitch-dynamics wheel-load transfer and friction that falls
with the sliding speed (Burckhardt's velocity factor).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import fields, replace

import numpy as np

from fricenv.effects import registry
from fricenv.effects.batch import ModelBatch
from fricenv.effects.library import (
    BrakeDelay,
    BrakeFade,
    BrakeGain,
    BrakeLag,
    Drag,
    LoadTransfer,
    MuChange,
    RadiusError,
    RelaxationLength,
    SlidingSpeedFriction,
    drag_force,
)
from fricenv.effects.relaxation import RELAX_GAMMA, relaxation_derivatives, relaxation_step
from fricenv.plants import quarter_car as qc
from fricenv.plants.tire import MagicFormula, longitudinal_slip, magic_formula

__all__ = [
    "DEFAULT_SUBSTEPS",
    "EFFECTS",
    "EFFECT_PARAMS",
    "OUT_OF_LIBRARY",
    "RELAX_GAMMA",
    "BrakeDelay",
    "BrakeFade",
    "BrakeGain",
    "BrakeLag",
    "Drag",
    "EffectSimulator",
    "LoadTransfer",
    "ModelBatch",
    "MuChange",
    "RadiusError",
    "RelaxationLength",
    "SlidingSpeedFriction",
    "effect_params",
    "make_effect",
    "relaxation_derivatives",
    "relaxation_step",
    "simulate_with_effects",
]

# Physics substeps per 10 ms sample: the plant's verified setting (< 0.01 % vs Radau).
DEFAULT_SUBSTEPS = 5
# Index rounding guard when locating a delayed sample [samples].
_INDEX_EPS = 1e-9
# Load-transfer pitch mode: natural frequency [rad/s] and damping ratio [-] of a passenger car's pitch.
_PITCH_OMEGA = 2.0 * np.pi * 1.5
_PITCH_ZETA = 0.4


class _RegistryView(Mapping):
    """A live, read-only view of the registry: effect name -> ``value(entry)`` over the entries ``keep`` selects
    (an effect registered later appears in it)."""

    def __init__(self, keep: Callable, value: Callable):
        self._keep, self._value = keep, value

    def _names(self) -> list[str]:
        return [n for n, e in registry.REGISTRY.items() if self._keep(e)]

    def __getitem__(self, name: str):
        entry = registry.REGISTRY.get(name)
        if entry is None or not self._keep(entry):
            raise KeyError(name)
        return self._value(entry)

    def __iter__(self) -> Iterator[str]:
        return iter(self._names())

    def __len__(self) -> int:
        return len(self._names())

    def __repr__(self) -> str:
        return repr(dict(self))


# Library effects (name -> spec class), their parameter names, and the validation-only effects: live views.
EFFECTS: Mapping[str, type] = _RegistryView(lambda e: e.in_library, lambda e: e.spec)
EFFECT_PARAMS: Mapping[str, tuple[str, ...]] = _RegistryView(lambda e: e.in_library, lambda e: e.param_names)
OUT_OF_LIBRARY: Mapping[str, type] = _RegistryView(lambda e: not e.in_library, lambda e: e.spec)


def make_effect(name: str, allow_out_of_library: bool = False, **params: float):
    """An effect spec from its registry name and parameters.

    :param name: effect name, one of :data:`EFFECTS` (or :data:`OUT_OF_LIBRARY` if allowed).
    :param allow_out_of_library: accept the validation-only effects too.
    :param params: the effect's parameters, by their registry names.
    :raises ValueError: unknown name (lists the valid ones), unknown or missing parameter (lists the valid ones).
    """
    return registry.get(name, allow_out_of_library).make(**params)


def effect_params(effect) -> dict[str, float]:
    """The parameters of an effect spec as a plain dict (registry names, SI units)."""
    return {f.name: float(getattr(effect, f.name)) for f in fields(effect)}


# --------------------------------------------------------------------------------------------- simulator
class EffectSimulator:
    """Batched quarter car with effects, advanced one 10 ms sample (zero-order-held command) at a time.

    Elements may start at different sample indices of one shared command log (the gap tool's prediction windows),
    or receive their commands step by step from a controller (the real stand-in's closed loop).

    :param batch: per-element model (road and effect parameters).
    :param dt: sample time [s].
    :param n_samples: length of the command history [samples].
    :param p: quarter-car parameters.
    :param substeps: physics substeps per sample.
    :param t0: log time of sample 0 [s] (``mu_change`` switches on log time).
    :param commands: a preset command log, (n_samples,) shared or (n, n_samples); if None, :meth:`step` records the
        commands it is given.
    """

    def __init__(self, batch: ModelBatch, dt: float, n_samples: int, p: qc.QuarterCarParams = qc.PAPER_PARAMS,
                 substeps: int = DEFAULT_SUBSTEPS, t0: float = 0.0, commands: np.ndarray | None = None):
        if substeps < 1:
            raise ValueError(f"substeps must be >= 1, got {substeps}")
        if dt <= 0:
            raise ValueError(f"dt must be > 0, got {dt}")
        self.batch, self.dt, self.p, self.substeps, self.t0 = batch, float(dt), p, int(substeps), float(t0)
        n = len(batch)
        self.n = n
        if commands is None:
            self._cmd = np.zeros((n, n_samples))
            self._record = True
        else:
            commands = np.asarray(commands, dtype=float)
            self._cmd = commands[None, :] if commands.ndim == 1 else commands
            self._record = False
        self._rows = np.arange(n) if self._cmd.shape[0] == n else np.zeros(n, dtype=int)
        self._derive()
        self.reset(np.zeros(n), np.zeros(n))

    def _derive(self) -> None:
        """The per-element constants and the switches that follow from :attr:`batch`."""
        batch, p, n = self.batch, self.p, self.n
        self._relax = batch.sigma > 0.0
        self._any_relax = bool(np.any(self._relax))
        self._std = ~self._relax
        # elements of one rolling radius share one plant call; their parameters are made once, not per substep
        self._groups = [(float(r), np.flatnonzero((batch.r_eff == r) & self._std)) for r in np.unique(batch.r_eff)]
        self._groups = [(idx, p if r == p.r else replace(p, r=r)) for r, idx in self._groups if idx.size]
        self._single = len(self._groups) == 1 and self._groups[0][0].size == n
        self._any_drag = bool(np.any(batch.c0 != 0.0) or np.any(batch.c2 != 0.0))
        self._any_lag = bool(np.any(batch.tau > 0.0))
        self._any_delay = bool(np.any(batch.delay > 0.0))
        self._any_change = bool(np.any(np.isfinite(batch.t_change)))
        self._any_fade = bool(np.any(batch.fade != 0.0))
        self._any_load = bool(np.any(batch.load != 0.0))
        self._any_slide = bool(np.any(batch.slide != 0.0))
        plugins = [e for e in registry.REGISTRY.values() if not e.builtin and e.param_names[0] in batch.extra]
        self._plugin_params = {e.name: {q: batch.extra[q] for q in e.param_names} for e in plugins}
        self._torque_hooks = [e for e in plugins if e.torque is not None]
        self._theta_hooks = [e for e in plugins if e.theta is not None]
        self._init_actuator()

    def replace_element(self, i: int, element: ModelBatch) -> None:
        """Give element ``i`` the model of the one-element batch ``element`` and start it afresh: state zero, sample
        index 0, no recorded command (a car of a vector env beginning its next episode with new effects).

        :param i: element index.
        :param element: a :class:`ModelBatch` of length 1 (e.g. :meth:`ModelBatch.from_effects`).
        """
        if len(element) != 1:
            raise ValueError(f"replace_element takes a one-element ModelBatch, got {len(element)} elements")
        if not self._record:
            raise ValueError("this simulator replays a preset command log; its elements cannot be replaced")
        self.batch = self.batch.with_element(i, element)
        self._derive()
        self._cmd[i] = 0.0
        self.reset_elements(np.array([i]), 0.0, 0.0)

    def reset_elements(self, idx: np.ndarray, v, omega) -> None:
        """:meth:`reset` of the elements ``idx`` only (sample index 0, lag state 0, transient slip of the state).

        :param idx: element indices; :param v: vehicle speed [m/s]; :param omega: wheel speed [rad/s].
        """
        idx = np.asarray(idx, dtype=int)
        v = np.broadcast_to(np.asarray(v, dtype=float), idx.shape)
        omega = np.broadcast_to(np.asarray(omega, dtype=float), idx.shape)
        self.v[idx], self.omega[idx], self.k[idx] = v, omega, 0
        self.Ta[idx] = 0.0 if self._record else self._cmd[self._rows[idx], 0]  # settled on the first command
        self.lam_t[idx] = longitudinal_slip(v, omega, self.batch.r_eff[idx])
        for state in (self.energy, self.pitch, self.pitch_rate, self.applied):
            state[idx] = 0.0

    def _init_actuator(self) -> None:
        """Per-element constants of the actuator chain over one substep (delay and lag are fixed per element)."""
        h = self.dt / self.substeps
        tau = self.batch.tau
        lagged = tau > 0.0
        safe_tau = np.where(lagged, tau, 1.0)
        e = np.exp(-h / safe_tau)
        # exact lag over a substep of constant input u: T_a+ = u + (T_a - u) keep, mean = u + (T_a - u) spread
        self._lag_keep = np.where(lagged, e, 0.0)
        self._lag_spread = np.where(lagged, safe_tau / h * (1.0 - e), 0.0)
        # delayed sample of substep j of sample k: k + offset[j] (weight frac[j]) and the next one (1 - frac[j])
        width = 1.0 / self.substeps
        self._delay_offset, self._delay_frac = [], []
        for j in range(self.substeps):
            s_a = j * width - self.batch.delay / self.dt
            i0 = np.floor(s_a + _INDEX_EPS).astype(int)
            self._delay_offset.append(i0)
            self._delay_frac.append(np.clip((i0 + 1 - s_a) / width, 0.0, 1.0))

    # -- state
    def reset(self, v, omega, k0=0, Ta=None, lam_t=None) -> None:
        """Set the state: speeds, start sample index per element, lag-filter output and transient slip.

        :param v: vehicle speed [m/s], (n,).
        :param omega: wheel speed [rad/s], (n,).
        :param k0: sample index of the first step, int or (n,).
        :param Ta: lag filter state [N m] (default: the delayed command at k0 times 1, i.e. settled).
        :param lam_t: transient slip [-] (default: the slip of (v, omega)).
        """
        n = self.n
        self.v = np.array(np.broadcast_to(np.asarray(v, dtype=float), (n,)))
        self.omega = np.array(np.broadcast_to(np.asarray(omega, dtype=float), (n,)))
        self.k = np.array(np.broadcast_to(np.asarray(k0, dtype=int), (n,)))
        if Ta is None:
            Ta = self._command_at(self.k) if not self._record else 0.0
        self.Ta = np.array(np.broadcast_to(np.asarray(Ta, dtype=float), (n,)))
        if lam_t is None:
            lam_t = longitudinal_slip(self.v, self.omega, self.batch.r_eff)
        self.lam_t = np.array(np.broadcast_to(np.asarray(lam_t, dtype=float), (n,)))
        self.energy = np.zeros(n)
        self.pitch = np.zeros(n)
        self.pitch_rate = np.zeros(n)
        self.applied = np.zeros(n)

    # -- actuator chain
    def _command_at(self, idx: np.ndarray) -> np.ndarray:
        """Command at sample ``idx`` of each element, held at the ends of the log; a recording simulator (an env)
        starts with the brake released, so before its first sample the command is zero, as the lag's state."""
        cmd = self._cmd[self._rows, np.minimum(np.maximum(idx, 0), self._cmd.shape[1] - 1)]
        return np.where(idx < 0, 0.0, cmd) if self._record else cmd

    def _delayed(self, j: int) -> np.ndarray:
        """Command delayed by ``delay``, averaged exactly over substep ``j`` of the current sample (ZOH input)."""
        idx = self.k + self._delay_offset[j]
        f = self._delay_frac[j]
        return f * self._command_at(idx) + (1.0 - f) * self._command_at(idx + 1)

    def _actuator_substep(self, j: int, held: np.ndarray | None = None) -> np.ndarray:
        """Mean applied torque over substep ``j`` (delay -> lag -> gain [-> fade]); advances the lag state.

        :param held: this sample's command without delay (read here if None; callers pass it once per sample).
        """
        if self._any_delay:
            u = self._delayed(j)
        else:
            u = self._command_at(self.k) if held is None else held
        if self._any_lag:
            offset = self.Ta - u
            mean = u + offset * self._lag_spread
            self.Ta = u + offset * self._lag_keep
        else:
            mean = u
            self.Ta = u
        torque = self.batch.gain * mean
        if self._any_fade:
            torque = torque / (1.0 + self.batch.fade * self.energy)
        for e in self._torque_hooks:
            torque = e.torque(self._plugin_params[e.name], torque)
        return torque

    def actuator_run(self, n_steps: int) -> np.ndarray:
        """Lag-filter state at the start of each of ``n_steps`` samples, actuator only (no plant): (n, n_steps).

        Without delay or fade the lag is driven by the zero-order-held command, and its exact solution over a whole
        sample is the same recursion as over the substeps composed: ``T_a+ = u + (T_a - u) exp(-dt/tau)``; that
        case runs as a linear filter (scipy ``lfilter``) per element instead of a Python loop over substeps.
        """
        if not (self._any_delay or self._any_fade) and self._cmd.shape[0] == 1:
            from scipy.signal import lfilter

            u = self._cmd[0, self.k[0]:self.k[0] + n_steps]
            out = np.empty((self.n, n_steps))
            for i in range(self.n):
                if self.batch.tau[i] > 0:
                    a = np.exp(-self.dt / self.batch.tau[i])
                    # y[k+1] = a y[k] + (1 - a) u[k], y[0] = Ta: filter then shift by one sample
                    y, _ = lfilter([0.0, 1.0 - a], [1.0, -a], u, zi=[self.Ta[i]])
                    out[i] = y
                else:
                    out[i, 0] = self.Ta[i]
                    out[i, 1:] = u[:-1]
            self.k = self.k + n_steps
            self.Ta = out[:, -1].copy()
            return out
        out = np.empty((self.n, n_steps))
        for i in range(n_steps):
            out[:, i] = self.Ta
            for j in range(self.substeps):
                self._actuator_substep(j)
            self.k = self.k + 1
        return out

    # -- road and forces
    def _road_at(self, t_end: np.ndarray, h: float) -> np.ndarray:
        """Road of each element over the substep ending at ``t_end`` (theta blended in the switching substep)."""
        road = self.batch.road
        if not (self._any_change or self._any_load or self._any_slide or self._theta_hooks):
            return road
        road = road.copy()
        if self._any_change:
            frac = np.clip((t_end - self.batch.t_change) / h, 0.0, 1.0)
            frac = np.where(np.isfinite(self.batch.t_change), frac, 0.0)
            road[:, 3] = road[:, 3] + frac * (self.batch.theta_after - road[:, 3])
        if self._any_load:
            road[:, 3] = road[:, 3] * np.maximum(1.0 + self.batch.load * self.pitch, 0.0)
        if self._any_slide:  # at the substep's start state: the factor varies slowly next to the slip dynamics
            sliding = np.maximum(self.v - self.omega * self.batch.r_eff, 0.0)
            road[:, 3] = road[:, 3] * np.exp(-self.batch.slide * sliding)
        for e in self._theta_hooks:
            road[:, 3] = e.theta(self._plugin_params[e.name], road[:, 3], t_end)
        return road

    def tire_force(self) -> np.ndarray:
        """Current longitudinal tire force [N] of each element."""
        t = self.t0 + self.k * self.dt
        road = self._road_at(t, self.dt / self.substeps)
        F = np.empty(self.n)
        if np.any(self._std):
            s = self._std
            lam = longitudinal_slip(self.v[s], self.omega[s], self.batch.r_eff[s])
            F[s] = self.p.Fz * magic_formula(lam, *road[s].T)
        if self._any_relax:
            s = self._relax
            F[s] = np.where(self.v[s] > 0.0, self.p.Fz * magic_formula(self.lam_t[s], *road[s].T), 0.0)
        return F

    def accel(self) -> np.ndarray:
        """Current longitudinal acceleration [m/s^2] (negative when braking), as an accelerometer reads it."""
        return -(self.tire_force() + drag_force(self.v, self.batch.c0, self.batch.c2)) / self.p.m

    def _drag_half(self, h: float) -> None:
        b = self.batch
        s = self._std
        dv = 0.5 * h * drag_force(self.v[s], b.c0[s], b.c2[s]) / self.p.m
        self.v[s] = np.maximum(self.v[s] - dv, 0.0)

    # -- one sample
    def step(self, Tb: np.ndarray | float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Advance every element by one sample under its (commanded) brake torque.

        :param Tb: commanded torque [N m] for this sample, (n,) or scalar; None reads it from the preset log.
        :return: (v, omega) after the sample (views of the state; copy to keep).
        """
        if Tb is not None:
            if not self._record:
                raise ValueError("this simulator replays a preset command log; call step() without Tb")
            col = np.clip(self.k, 0, self._cmd.shape[1] - 1)
            self._cmd[self._rows, col] = np.broadcast_to(np.asarray(Tb, dtype=float), (self.n,))
        h = self.dt / self.substeps
        p = self.p
        held = None if self._any_delay else self._command_at(self.k)
        for j in range(self.substeps):
            torque = self._actuator_substep(j, held)
            t_end = self.t0 + (self.k + (j + 1) / self.substeps) * self.dt
            road = self._road_at(t_end, h)
            if self._any_fade or self._any_load:
                decel = self.tire_force() / p.m
            if self._any_drag:
                self._drag_half(h)
            if self._single:
                self.v, self.omega = qc.step(self.v, self.omega, torque, road, h, self._groups[0][1], 1)
            else:
                for idx, pr in self._groups:
                    self.v[idx], self.omega[idx] = qc.step(self.v[idx], self.omega[idx], torque[idx], road[idx], h,
                                                           pr, 1)
                if self._any_relax:
                    s = self._relax
                    b = self.batch
                    self.v[s], self.omega[s], self.lam_t[s] = relaxation_step(
                        self.v[s], self.omega[s], self.lam_t[s], torque[s], road[s], h, b.r_eff[s], b.sigma[s],
                        b.c0[s], b.c2[s], p)
            if self._any_drag:
                self._drag_half(h)
            if self._any_fade:
                self.energy = self.energy + torque * self.omega * h
            if self._any_load:
                # semi-implicit Euler of the pitch mode driven by the deceleration in g
                acc = _PITCH_OMEGA**2 * (decel / p.g - self.pitch) - 2 * _PITCH_ZETA * _PITCH_OMEGA * self.pitch_rate
                self.pitch_rate = self.pitch_rate + h * acc
                self.pitch = self.pitch + h * self.pitch_rate
            self.applied = torque
        self.k = self.k + 1
        return self.v, self.omega


def simulate_with_effects(effects: Sequence, road: MagicFormula | np.ndarray, torque, v0: float, n_samples: int,
                          dt: float = 0.01, p: qc.QuarterCarParams = qc.PAPER_PARAMS,
                          substeps: int = DEFAULT_SUBSTEPS, t0: float = 0.0,
                          measure: Callable[[np.ndarray], np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """Simulate one quarter car with effects, open loop or under a controller: the policy-level API of the gap tool.

    :param effects: effect specs (:func:`make_effect`); empty for the nominal simulator.
    :param road: Magic Formula road.
    :param torque: commanded torque [N m], an array of ``n_samples`` values, or a controller
        ``torque(k, t, omega_measured) -> float`` called every sample with the measured wheel speed.
    :param v0: initial speed [m/s]; the wheel starts free rolling (``omega r_eff = v0``).
    :param n_samples: number of samples.
    :param dt: sample time [s]; :param p: quarter-car parameters; :param substeps: physics substeps per sample.
    :param t0: log time of the first sample [s].
    :param measure: optional map from true omega to measured omega (e.g. adds noise); identity if None.
    :return: dict with arrays ``t``, ``T_cmd`` (commanded), ``T_applied`` (mean over the last substep), ``v``,
        ``omega`` (true), ``omega_meas``, ``a_x`` (true), each of length ``n_samples`` (values at the sample times,
        the command held over the following interval).
    """
    batch = ModelBatch.from_effects(road, effects, p)
    sim = EffectSimulator(batch, dt, n_samples, p, substeps, t0)
    r0 = float(batch.r_eff[0])
    sim.reset(np.array([v0]), np.array([v0 / r0]))
    out = {name: np.empty(n_samples) for name in ("t", "T_cmd", "T_applied", "v", "omega", "omega_meas", "a_x")}
    controller = torque if callable(torque) else None
    if controller is None:
        torque = np.asarray(torque, dtype=float)
        if torque.shape != (n_samples,):
            raise ValueError(f"torque must have shape ({n_samples},), got {torque.shape}")
    for k in range(n_samples):
        t = t0 + k * dt
        w_meas = measure(sim.omega.copy()) if measure is not None else sim.omega.copy()
        cmd = float(controller(k, t, float(w_meas[0]))) if controller is not None else float(torque[k])
        out["t"][k], out["v"][k], out["omega"][k] = t, sim.v[0], sim.omega[0]
        out["omega_meas"][k], out["a_x"][k], out["T_cmd"][k] = w_meas[0], sim.accel()[0], cmd
        sim.step(np.array([cmd]))
        out["T_applied"][k] = sim.applied[0]
    return out
