"""A spike or a model that is off: the quarter-car filters' wheel-speed gate with a mismatch rule and a reference
speed.

The outlier gate (:mod:`estimators.outliers`) rejects a wheel speed whose NIS fails the chi-square bound. A spike
is one such sample; a plant whose brake lags, whose gain, radius or drag differ from the model's gives a run of
them, all of one sign, each a wheel speed a road can produce. Rejecting that run sample after sample blinds the
filter until the re-initialisation, which then took the speed from a wheel that may sit in an ABS slip dip. Rules:

(M1) **Persistent innovation.** A failing sample that follows a failing sample with an innovation of the same sign,
     each implying a tire torque a road can produce from the last wheel speed the filter used (eq. (J2) of
     :mod:`estimators.jump`, friction within ``JUMP_MU_MAX`` times the load), and whose innovation moved from the last sample's by no more
     than the gate allows for the difference of two samples (``(e - e_prev)^2 <= 2 S bound``: a model error grows,
     a spike jumps), and whose NIS is below ``MISMATCH_NIS_MAX`` bounds (a model error grows into the gate: the
     brake-lag stops' failing samples have NIS 20-250; two x0.5 spikes in a row at 40 rad/s about 1900), is not an
     outlier: the model is off. The filter raises its process noise on (v, slip) for this sample just enough that
     the sample sits on the gate's bound,
     ``H (P + c Q_vs) H^T + R = e^2 / bound``, and updates with it (``Verdict.MISMATCH``; the estimate's health
     stays the filter's own, its info carries ``mismatch``, the factor c). An isolated spike passes no such test
     (the sample after it agrees with the prediction); a spike of a tenth or ten times the speed, or a dropout to
     zero at speed, implies a tire force many times the load: it stays an outlier and joins no run (the run goes
     on from the last physical sample).
(M2) **Reference speed.** As an ABS ECU builds its reference: the fastest plausible wheel, with bounded deceleration,
     ``v_ref(k) = max(omega(k) r - margin, v_ref(k-1) - A_REF dt)``, the wheel term only for a sample the gate
     used (a rejected sample is not plausible); while braking it is a lower bound of the car's speed that the wheel
     touches whenever it rolls freely. A re-initialisation takes the speed from it, ``v = max(v_ref, omega r)``
     (the filter's own speed after a run of rejections is not to be trusted), and the slip that makes eq. (7) hold
     at that speed (a locked wheel or a dropout to zero: slip 1): never the speed of a wheel that may be slipping.
     The reference less its margin once more also bounds every posterior speed from below
     (:meth:`WheelSpeedGuard.bound_posterior`, which also keeps an update from raising the speed above both its
     prediction and the wheel): at a locked wheel the measurement is flat in v, and a linearised update
     can take the speed to 0, where the stiff model step diverges (the four-parameter filters, 20 ms brake delay,
     dry ABS stop: 4482 m/s off without it). So does the reference's deceleration bound over one sample: an
     update on a wheel faster than its prediction lowers the speed below the prediction by at most ``A_REF dt``.
     Such a wheel pulls the speed down only through the speed's correlation with the friction: a wheel locked by
     a brake the model does not time builds it (the friction read low while the car decelerates at the peak), and
     as the wheel spun up one update raised the friction and took 1.6 m/s off the speed (60 ms brake delay, dry
     ABS stop of the stand-in, seed 2: 2.04 m/s off at the worst sample without the bound, 0.30 with it). A wheel
     slower than its prediction lowers the speed as the update has it.
(M2') **Speed from the accelerometer.** A model whose speed follows the measured ``a_x``
     (``AugmentedModel.speed_from_a_x``) takes neither bound of (M2) nor its speed at a re-initialisation: its speed
     is the integrated ``a_x``, which no slip or tire transient moves, while the fastest wheel is no lower bound of a
     car whose tire winds up under a relaxation length (the wheel spins past the car as the brake releases). A
     re-initialisation restarts the slip only, from the wheel at the filter's speed, and a persistent innovation
     (M1) raises the slip's process noise only. As such a sample cannot move the speed, (M1) takes more samples as
     a run: its first failing sample, when the passing sample just before it had an innovation of the same sign
     whose NIS reached ``MISMATCH_TREND_NIS`` gate bounds (a model error grows into the gate; the sample before a
     spike agrees with the prediction), and a sample whose innovation falls back towards zero with its sign kept
     by more than two samples' spread (a wheel oscillating against the model, the tire wound up as a spring
     against the wheel's inertia, turns back faster than it grew; a spike does not make an error smaller). A
     model whose speed is the tire model's keeps (M1) as it is: each sample so taken moves its speed.
(M3) **Start.** The state after a reset is a guess (19 m/s a priori): a first sample that fails against it is no
     outlier; the filter starts from it as from a re-initialisation (``Verdict.START``) and keeps its own health.
(M4) **A braked wheel below the car falls no faster than the brake pulls it.** While the tire's slip is positive
     its force spins the wheel up, so the wheel decelerates at most at ``T_b / J``. A sample below the last wheel
     speed the filter used, less ``T_b / J`` times the samples since, by more than the gate allows for the noise of
     the two (``sqrt(2 bound)`` noise std's), cannot be true whatever its NIS (``T_b`` the strongest brake torque
     held over ``BRAKE_SETTLE_S``, as rule (B4) of :mod:`estimators.speed_reference` reads a lagging brake): it is
     an outlier and joins no run. The rule waits until the wheel speeds the filter used have been below its speed
     for that span: a tire wound up under a relaxation length spins the wheel past the car and pulls it back below
     faster than the brake (without the wait, 3 samples of the open-loop dry stop of seed 1 at 0.6 m were flagged
     so). The gate of the filters whose slip
     takes a random walk (``ekf-ax``, ``mhe-ax``) is wide in a slip dip (about 3 m/s at the wheel's surface at 25
     m/s): a wheel speed halved there passed it, and the sample after it failed against the prediction it had
     moved.
(M5) **A wheel spinning up shows the road's friction.** A brake only opposes a turning wheel, so whatever speeds
     the wheel up is the tire: ``J domega/dt <= r F_x <= r F_z theta`` (``|mu| <= theta``). A sample the filter
     uses whose wheel rose from the last one it used, by more than the gate allows for the noise of the two
     (``sqrt(2 bound)`` noise std's, as (M4)), shows a peak friction of at least
     ``J (omega - omega_used - sqrt(2 bound) sigma) / (span r F_z)``; the posterior ``theta`` is raised to it
     (:meth:`WheelSpeedGuard.bound_posterior`), never lowered. No torque that drives the wheel (negative brake
     torque) may act over the span. A wheel slower than its prediction reads as friction the road lacks: a brake
     the model does not time (a 60 ms delay of an over-peak pulse on the stand-in's open-loop dry stop of seed
     12) locked the wheel against the released command, one mismatch update took ``theta`` from 0.88 to its
     bound 0, and with no friction the model's car no longer decelerated; ``theta`` recovered at its random walk
     while the speed drifted 2.9 m/s high (1.34 m/s rms). The wheel's spin-up as the delayed pulse ended showed a
     friction of 0.62 at least: 0.11 m/s rms with the rule. Not for a model whose speed follows ``a_x`` (M2'):
     its speed does not follow the friction.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from estimators.outliers import GateParams, Verdict, gate, nis
from estimators.tuning import (
    A_REF,
    JUMP_MU_MAX,
    MISMATCH_NIS_MAX,
    MISMATCH_TREND_NIS,
    REF_MARGIN_STD,
    SLIP_PRIOR,
    brake_settle_samples,
)

__all__ = ["WheelSpeedGuard"]


@dataclass
class _State:
    rejected: int = 0  # failing samples in a row before this one
    run: int = 0  # physical failing samples of one sign in a row (spikes excluded)
    sign: float = 0.0  # sign of the run's innovations
    omega_used: float = np.nan  # the last wheel speed the filter used [rad/s]
    since: int = 1  # samples since it
    v_ref: float = np.nan  # reference speed [m/s]
    e_prev: float = np.nan  # the run's last innovation [rad/s]
    e_passed: float = np.nan  # the innovation of the sample before this one if it passed the gate [rad/s]
    nis_passed: float = 0.0  # its NIS [-]
    brakes: deque = field(default_factory=deque)  # the brake torques held over the last BRAKE_SETTLE_S, newest last
    below: int = 0  # samples in a row whose wheel speed the filter used lay below the car's speed [-]
    faster: bool = False  # the wheel reads faster than its prediction, and a sample before it was used
    mu_floor: float = 0.0  # the least peak friction this sample's wheel shows, (M5) [-]


class WheelSpeedGuard:
    """The gate of the EKF and of the MHE's arrival filter on one wheel speed, with rules (M1)-(M5).

    :param model: the filter's augmented quarter-car model (r, J, F_z, dt).
    :param params: the outlier gate; None trusts every sample (no gate, no rule).
    :param noise_std: wheel-speed noise standard deviation [rad/s].
    """

    def __init__(self, model, params: GateParams | None, noise_std: float):
        self.model = model
        self.params = params
        self.noise_std = float(noise_std)
        p = model.p
        self.b_bound = JUMP_MU_MAX * p.Fz * p.r / p.J
        self.settle = brake_settle_samples(model.dt)  # brake torques (M4) reads
        self.reset()

    def reset(self) -> None:
        self.s = _State(brakes=deque(maxlen=self.settle))

    @property
    def rejected(self) -> int:
        """Failing samples in a row so far."""
        return self.s.rejected

    def _reference(self, omega: float | None) -> None:
        """(M2) once per sample: fall at the bounded deceleration, rise to a wheel speed the filter used
        (``omega`` None for a rejected sample)."""
        r, dt = self.model.p.r, self.model.dt
        fallen = self.s.v_ref - A_REF * dt if np.isfinite(self.s.v_ref) else -np.inf
        wheel = -np.inf if omega is None else omega * r - REF_MARGIN_STD * self.noise_std * r
        self.s.v_ref = max(fallen, wheel)

    def _below_brake_floor(self, omega: float) -> bool:
        """(M4): a braked wheel below the car falls no faster than the strongest brake torque of the settling span
        pulls it, from the last wheel speed the filter used (both samples' noise within the gate's bound)."""
        s, p, dt = self.s, self.model.p, self.model.dt
        if not (s.brakes and s.brakes[-1] > 0.0 and np.isfinite(s.omega_used)) or s.below < self.settle:
            return False
        fastest = s.omega_used - s.since * dt * max(s.brakes) / p.J
        return omega < fastest - np.sqrt(2.0 * self.params.bound) * self.noise_std

    def _friction_shown(self, omega: float) -> float:
        """(M5): the least peak friction that the wheel's rise from the last wheel speed the filter used shows, less
        the noise of the two samples within the gate's bound (``sqrt(2 bound)`` noise std's); 0 for a wheel that
        did not rise beyond its noise, before a sample was used, or when a torque of the span drove the wheel."""
        s, p = self.s, self.model.p
        spanned = list(s.brakes)[-s.since:]
        if not np.isfinite(s.omega_used) or min(spanned) < 0.0:
            return 0.0
        rise = omega - s.omega_used - np.sqrt(2.0 * self.params.bound) * self.noise_std
        return max(0.0, p.J * rise / (s.since * self.model.dt) / (p.r * p.Fz))  # (M5)

    def bound_posterior(self, x: np.ndarray, v_prior: float, omega: float) -> np.ndarray:
        """(M5) as a lower bound of the posterior peak friction ``theta`` (where it is estimated), and (M2) as
        bounds on the posterior speed. Below: the reference speed less its margin once more (the reference
        is a lower bound of the car's speed while braking; at a locked wheel the measurement is flat in v and a
        linearised update can take the speed to 0), and, for a wheel faster than its prediction once a sample was
        used, the prediction less ``A_REF dt`` (such a wheel lowers the speed no faster than the reference falls).
        Above, for a model that carries the brake gain ``k_T``: a
        braked car's speed rises above its prediction only as far as the wheel shows (the wheel speed plus the
        reference's margin). With a free brake gain the torque no longer pins the slip, and an update beyond both
        is the model's mismatch read as speed (80 ms brake lag, dry ABS stop, seed 1: 0.42 m/s rms without the
        bound, 0.25 with it). The paper's model (no ``k_T``) is not bounded above.

        :param x: posterior state; :param v_prior: the prior speed [m/s]; :param omega: the sample's wheel speed.
        """
        if self.model.speed_from_a_x:  # (M2'), (M5)
            return x
        margin = REF_MARGIN_STD * self.noise_std * self.model.p.r
        floor = self.s.v_ref - margin
        if self.s.faster:  # the reference's deceleration bound over one sample (fmax: no reference yet is NaN)
            floor = float(np.fmax(floor, float(v_prior) - A_REF * self.model.dt))
        ceiling = max(float(v_prior), float(omega) * self.model.p.r + margin)
        v = float(x[0])
        if np.isfinite(floor) and v < floor:
            v = floor
        if "k_T" in self.model.extras and v > ceiling:
            v = max(ceiling, floor) if np.isfinite(floor) else ceiling
        lift = "theta" in self.model.estimated and float(x[2]) < self.s.mu_floor  # (M5)
        if v != x[0] or lift:
            x = x.copy()
            x[0] = v
            if lift:
                x[2] = self.s.mu_floor
        return x

    def reinit(self, x: np.ndarray, P: np.ndarray, P0: np.ndarray, omega: float) -> tuple[np.ndarray, np.ndarray]:
        """(M2): re-initialise (v, slip) from the reference speed and the wheel speed (before a reference: the
        filter's speed).

        The (v, slip) covariance goes back to its initial block of ``P0``; their correlations with the parameters
        are dropped.
        """
        r = self.model.p.r
        wheel = max(float(omega) * r, 0.0)
        started = np.isfinite(self.s.omega_used)
        if self.model.speed_from_a_x and started:  # (M2'): the slip only, at the filter's speed
            v, block = float(x[0]), slice(1, 2)
        else:
            v, block = max(self.s.v_ref if np.isfinite(self.s.v_ref) else float(x[0]), wheel), slice(0, 2)
        slip = 1.0 - wheel / v if v > 0 else SLIP_PRIOR
        x = x.copy()
        x[0], x[1] = v, float(np.clip(slip, 0.0, 1.0))
        P = P.copy()
        P[block, :] = 0.0
        P[:, block] = 0.0
        P[block, block] = P0[block, block]
        return x, P

    def check(self, x: np.ndarray, P: np.ndarray, P0: np.ndarray, R: np.ndarray, Q: np.ndarray, y: np.ndarray,
              brake_torque: float):
        """Gate wheel speed ``y`` against the prior (x, P).

        :param x: prior state; :param P: its covariance; :param P0: the initial covariance.
        :param R: measurement noise (1, 1); :param Q: the filter's process noise (its (v, slip) block is raised).
        :param y: the wheel speed (1,) [rad/s].
        :param brake_torque: brake torque held since the last sample (brake-positive) [N m].
        :return: (verdict, x, P, inflation c): ``REINIT`` re-initialised x, P; ``MISMATCH`` the raised P.
        """
        if self.params is None:
            return Verdict.ACCEPT, x, P, 0.0
        omega = float(y[0])
        H = np.atleast_2d(self.model.h_jacobian(x))
        S = float((H @ (P @ H.T) + R)[0, 0])  # as estimators.ekf.innovation_covariance
        e = omega - float(self.model.h(x))
        s = self.s
        s.brakes.append(float(brake_torque))
        floor = self._below_brake_floor(omega)  # (M4)
        value = np.inf if floor else nis(e, S)
        verdict, rejected = gate(value, s.rejected, self.params)
        inflation = 0.0
        if verdict != Verdict.ACCEPT:
            # (J2) of estimators.jump over the samples since the last one used: a tire torque a road can produce?
            span = s.since * self.model.dt
            b_implied = (s.omega_used - omega) / span - float(brake_torque) / self.model.p.J
            physical = bool(np.isfinite(b_implied) and abs(b_implied) <= self.b_bound) and not floor
            sign = float(np.sign(e))
            a_x = self.model.speed_from_a_x  # (M2'): a run may start at the passing sample before, and fall back
            grown = (a_x and s.run == 0 and np.sign(s.e_passed) == sign
                     and s.nis_passed >= MISMATCH_TREND_NIS * self.params.bound)
            e_prev = s.e_passed if grown else s.e_prev  # the run's last innovation
            persistent = physical and (grown or (s.run >= 1 and sign == s.sign))
            grows = (e - e_prev) ** 2 <= 2.0 * S * self.params.bound
            recedes = a_x and np.sign(e_prev) == sign and abs(e) <= abs(e_prev)
            smooth = np.isfinite(e_prev) and (grows or recedes)
            if persistent and smooth and value <= MISMATCH_NIS_MAX * self.params.bound:  # (M1): the model is off
                raised = slice(1, 2) if a_x else slice(0, 2)  # (M2'): not the speed
                Hq = H[0, raised]
                inflation = (e * e / self.params.bound - S) / max(float(Hq @ Q[raised, raised] @ Hq), 1e-300)
                P = P.copy()
                P[raised, raised] += max(inflation, 0.0) * Q[raised, raised]
                verdict, rejected = Verdict.MISMATCH, s.rejected  # a run of mismatches never re-initialises
            if physical:  # a sample no road can produce is a spike: it joins no run
                s.run = s.run + 1 if sign == s.sign else 1
                s.sign, s.e_prev = sign, e
        if verdict != Verdict.ACCEPT and not np.isfinite(s.omega_used):  # (M3): no sample used yet
            verdict, rejected = Verdict.START, 0
        self._reference(None if verdict == Verdict.REJECT else omega)
        if verdict in (Verdict.REINIT, Verdict.START):
            x, P = self.reinit(x, P, P0, omega)
        s.faster = e > 0.0 and np.isfinite(s.omega_used)
        s.mu_floor = self._friction_shown(omega) if verdict in (Verdict.ACCEPT, Verdict.MISMATCH) else 0.0
        if verdict == Verdict.REJECT:
            s.since += 1
        else:
            s.omega_used, s.since = omega, 1
            s.below = s.below + 1 if omega * self.model.p.r < float(x[0]) else 0
        if verdict in (Verdict.ACCEPT, Verdict.REINIT, Verdict.START):
            s.run, s.sign, s.e_prev = 0, 0.0, np.nan
        s.rejected = rejected
        s.e_passed, s.nis_passed = (e, value) if verdict == Verdict.ACCEPT else (np.nan, 0.0)
        return verdict, x, P, inflation
