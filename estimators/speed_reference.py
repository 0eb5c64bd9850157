"""The EKF/RLS's speed reference (:mod:`estimators.ekf_rls`, step 1): the velocity filter's step and the wheel-speed
gate, and what they do while the torque brakes and while no torque acts.

**While braking, a wheel faster than the car is no reference** (``braking_reference`` of
:class:`~estimators.ekf_rls.EkfRlsConfig`; on in the registry's ``ekf-rls``). Eq. (4) raises the estimate at the
rate R towards a wheel faster than it, which is right in traction but not under a brake: a braked car does not
speed up, and a tire with a relaxation length winds up as the brake applies and spins the wheel past the car's speed
as it releases, while the tire still brakes (ABS stops with sigma 0.6 m, dry and wet, seeds 0-2: slip down to -0.13
to -0.17 above 10 m/s, to -0.45 below). Following that wheel up at about 1 g added 0.2-0.4 m/s per ABS cycle to
the estimate. With the rule, while the torque brakes:

(B1) the estimate never rises (a step of eq. (4) upwards is 0);
(B2) a wheel faster than the estimate by more than its noise margin (``REF_MARGIN_STD`` wheel-speed noise std's,
     the margin of the EKF's reference speed, :mod:`estimators.mismatch`) is not taken as the car's speed:
     the estimate falls at the rate R, as while the wheel slips;
(B3) the wheel-speed gate (:class:`WheelSpeedGate`) predicts a braked wheel at most at the speed estimate plus
     that margin. As the brake releases, the wheel spins up until it meets the car's speed and stops there; the
     gate's tire-torque state carried the spin-up on past the car, read the stop as two outliers and then as a
     friction jump (:mod:`estimators.jump`): up to 1.2 % of a nominal stop's samples were flagged (0.4 % on
     average).

(B4) **A brake that has not followed its command yet** (always on in the gate). The gate predicts the wheel with
     the torque commanded; a hydraulic brake applies it after a lag or a dead time (20-80 ms on real cars), so
     for ``BRAKE_SETTLE_S`` after the command changes, the torque applied lies anywhere between the commands of
     that span (a dead time within it applies one of them; a lag, a mean of them). The first failing sample of a
     run whose innovation such a torque explains, to within the gate's bound, is the brake's lag: the gate's
     prediction moves by the part of the innovation that torque explains (:func:`brake_lag_shift`) and the
     sample is accepted, with the tire term left as it was. While the command holds still the span is one torque
     and the rule changes nothing. Before the rule, the first sample after each step of an open-loop command was
     rejected and the second restarted the gate as a friction jump.

(B5) **A wheel without torque rolls freely and is the car's speed.** When the torque held over the interval has
     a feedforward R_g of at most ``FREE_ROLLING_RATE`` (no brake), the estimate is predicted at the rate R (the
     a_x loop's deceleration: drag, rolling resistance) and moved a share ``dt / FREE_ROLLING_TAU`` of the way to a
     wheel within the noise margin of that prediction; a wheel farther off (one still spinning up from a slip dip)
     leaves eq. (4). Eq. (4) alone moves the estimate by at most R a sample: with the wheel noise far wider than
     its Sat width d, it steps by R towards the wheel's sign each sample, and once the loop has R equal to the
     car's deceleration it cannot close a lag the noise built up. On the gap tool's coasting stops under the
     grid's high drag the estimate ran 0.3 m/s above the car for the whole stop (ABS on snow, seed 0); on nominal
     stops the first wheel sample's noise stayed in the estimate the same way (0.06 m/s, ABS dry, seed 2).

(B6) **A released wheel spins up through the tire's peak** (always on in the gate). As the brake releases from past
     the road's peak, the wheel spins up and its slip passes back through the curve's peak: the tire's force rises
     within a sample by more than the gate's random walk of the tire term follows. The first failing sample of a
     run, after the command fell within the span of (B4), with the wheel faster than predicted, whose innovation a
     tire term within the road's bound (``b_bound`` of :mod:`estimators.jump`) explains is accepted, the tire term
     moved by that part (:func:`release_shift`). A spike past what any road gives stays an outlier. Before the rule,
     the gap tool's open-loop stops whose torque fell from 1,260-1,410 N m to 110-210 N m in one sample read each
     release as an outlier and a friction jump (dry, seed 18: 8 flags, 1.6 % of the stop).

Measured by ``fricenv paper robustness --seeds 3`` (rms speed error after the first 0.5 s over dry, wet and snow,
ABS and open-loop stops): nominal plant 0.15 -> 0.12 m/s, relaxation length 0.3 m 0.75 -> 0.25, 0.6 m 0.94 ->
0.32 (worst sample 2.83 -> 1.29 m/s), the other cells of the effect grid equal or better in the rms but the 4 %
radius error (0.80 -> 0.83); outlier and re-initialisation flags on the worst nominal stop 1.2 -> 0.4 %. The paper's
rows (``fricenv paper ekf-rls``) keep eq. (4) and the gate (with (B4) and (B6), which leave its figures as they
were). With (B5) and (B6) (the same command, the a_x loop at 20 1/s): nominal 0.12 -> 0.08 m/s, drag 0.22 / 0.26
-> 0.10 / 0.10, no flag on any stop outside the relaxation lengths (0.8 % of the worst nominal stop before), the
other cells equal or better but the relaxation lengths (0.18 / 0.23 -> 0.22 / 0.24; worst sample 1.33 -> 1.63
m/s) and the radius errors (0.86 / 0.83 -> 0.82 / 0.83). With the a_x loop on the car's deceleration
(:func:`a_x_loop_step`): the relaxation lengths 0.22 / 0.24 -> 0.13 / 0.14 (worst sample 1.63 -> 0.65 m/s), nominal
0.08 -> 0.09, the other cells within 0.01.
"""

from __future__ import annotations

import numpy as np

from estimators.jump import JUMP_MU_MAX, jump_test
from estimators.outliers import GateParams, Verdict, gate, nis
from estimators.tuning import brake_settle_samples

__all__ = ["WHEEL_B_STD", "WheelSpeedGate", "a_x_loop_step", "brake_lag_shift", "release_shift", "speed_step"]

FREE_ROLLING_TAU = 0.2  # (B5): time constant of the estimate's approach to a free-rolling wheel [s]
FREE_ROLLING_RATE = 0.1  # (B5): a torque whose feedforward R_g is at most this leaves the wheel free [m/s^2]
WHEEL_B_STD = 100.0  # random walk of the tire torque over inertia in the wheel-speed gate, per sample [rad/s^2]


def a_x_loop_step(c: float, a_x: float, R_g: float, gain: float, braked: bool) -> float:
    """The a_x loop of Fig. 2 from one sample to the next: the correction ``c`` of the rate R moves a share ``gain``
    of the way to the measured rate less the torque's feedforward R_g (eq. (5)). The paper's rate is ``|a_x|``, the
    speed of eq. (4)'s approach in traction and in braking alike. With the rules of this module on and no torque
    driving the wheel (``braked``), R is a fall: the estimate never rises under a brake (B1), falls at R past a wheel
    faster than it (B2) and is predicted at R while the wheel rolls freely (B5). The rate is then the car's
    deceleration, ``max(-a_x, 0)`` (``a_x`` is positive forward, docs/contracts.md): a car pushed forward, as a tire
    with a relaxation length unwinds after a release, does not decelerate, and reading its push as braking pulled
    the estimate below the car. Plain arithmetic: the batched estimator compiles it.

    :param c: correction [m/s^2]; :param a_x: longitudinal acceleration, negative when braking [m/s^2].
    :param R_g: feedforward of the torque held [m/s^2]; :param gain: the loop's gain over one sample [-].
    :param braked: the rules are on and the torque brakes or is zero.
    :return: the next correction [m/s^2].
    """
    measured = max(-a_x, 0.0) if braked else abs(a_x)
    return c + gain * (measured - R_g - c)


def speed_step(y: float, x_ref: float, rate: float, dt: float, d: float, braking: bool, margin: float,
               free: bool = False) -> float:
    """The velocity filter from one sample to the next: eq. (4) ``y' = -R Sat(y - x_ref)`` with Sat of eq. (6),
    rules (B1)-(B2) when ``braking`` and (B5) when ``free`` (module docstring). Plain arithmetic: the batched
    estimator compiles it.

    :param y: speed estimate [m/s]; :param x_ref: reference wheel surface speed [m/s]; :param rate: R [m/s^2].
    :param dt: sample time [s]; :param d: Sat width [m/s].
    :param braking: the torque brakes and the rules are on; :param margin: (B2)'s margin [m/s].
    :param free: no torque acts and the rules are on: (B5).
    :return: the next estimate, at least 0 [m/s].
    """
    if free:  # (B5): the prediction at the rate R, moved towards a free-rolling wheel within the margin
        pred = y - dt * rate
        if abs(x_ref - pred) <= margin:
            return max(pred + dt / FREE_ROLLING_TAU * (x_ref - pred), 0.0)
    step = -dt * rate * min(max((y - x_ref) / d, -1.0), 1.0)
    if braking:
        if x_ref > y + margin:  # (B2): a wheel past the car, not a reference
            step = -dt * rate
        elif step > 0.0:  # (B1): a braked car does not speed up
            step = 0.0
    return max(y + step, 0.0)


def brake_lag_shift(e: float, torque: float, t_min: float, t_max: float, room: float, dt: float,
                    I_w: float) -> float:
    """Rule (B4): the part of a wheel-speed innovation that a torque within the span's commands explains in place of
    the torque held. Plain arithmetic: the batched gate compiles it.

    :param e: innovation, measured minus predicted [rad/s].
    :param torque: the torque held since the last sample, which the prediction used (traction-positive) [N m].
    :param t_min: the smallest command of the settling span [N m]; :param t_max: the largest [N m].
    :param room: how far the prediction may rise ((B3)'s ceiling less the prediction; inf: no ceiling) [rad/s].
    :param dt: sample time [s]; :param I_w: wheel inertia [kg m^2].
    :return: the explained part, between ``dt (t_min - torque) / I_w`` and ``dt (t_max - torque) / I_w`` [rad/s].
    """
    lo = dt * (t_min - torque) / I_w
    hi = min(dt * (t_max - torque) / I_w, room)
    return min(max(e, lo), max(hi, 0.0))


def release_shift(e: float, b: float, torque: float, t_min: float, dt: float, b_bound: float) -> float:
    """Rule (B6): the part of a wheel-speed innovation that the tire explains as the brake releases. Plain arithmetic:
    the batched gate compiles it.

    :param e: innovation, measured minus predicted [rad/s]; :param b: the gate's tire term [rad/s^2].
    :param torque: the torque held since the last sample (traction-positive) [N m].
    :param t_min: the strongest brake command of the settling span (traction-positive: the smallest) [N m].
    :param dt: sample time [s]; :param b_bound: the largest tire term a road can produce [rad/s^2].
    :return: the explained part, between 0 and what a tire term of ``-b_bound`` gives [rad/s].
    """
    if e <= 0.0 or torque <= t_min:  # the wheel is not faster, or the brake has not released within the span
        return 0.0
    return min(e, max(dt * (b + b_bound), 0.0))


class WheelSpeedGate:
    """The outlier gate on the wheel speeds (:mod:`estimators.outliers`): one small Kalman filter per wheel.

    Per wheel, state (omega, b) with b = F R_w / I_w the tire's torque over the inertia, a random walk, and the
    wheel equation ``omega(k+1) = omega(k) + dt (T(k) / I_w - b(k))`` (the force EKF's eq. (7) row, with the known
    torque), measured with noise ``omega_std``. A wheel speed whose NIS fails the gate is replaced by the
    prediction (the filters run on it as if it had not come) and the covariance is held at its last one-step value
    (the random walk of b would open the gate to a dropout within 7 samples); the ``max_rejections + 1``-th in a row
    restarts that wheel's filter from the measurement, and so does a second rejected sample that a friction jump
    explains (:mod:`estimators.jump`), with b at the tire term it implies.

    :param n: number of wheels.
    :param I_w: wheel inertia [kg m^2].
    :param R_w: wheel radius [m].
    :param Fz: load per wheel [N] (scale of b's initial spread: the tire torque at mu = 1).
    :param dt: sample time [s].
    :param omega_std: wheel-speed noise standard deviation assumed [rad/s].
    :param params: the gate.
    :param rest_band: a braked wheel this close to 0 is at rest, (J3) of :mod:`estimators.jump` (0: the rule
        off) [rad/s].
    """

    def __init__(self, n: int, I_w: float, R_w: float, Fz: np.ndarray, dt: float, omega_std: float,
                 params: GateParams, rest_band: float = 0.0):
        self.n, self.I_w, self.dt = n, float(I_w), float(dt)
        self.params, self.rest_band = params, float(rest_band)
        self.R = float(omega_std) ** 2
        self.b_std0 = np.asarray(Fz, dtype=float) * R_w / I_w  # [rad/s^2]
        self.b_bound = JUMP_MU_MAX * self.b_std0  # largest tire term a road can produce (estimators.jump) [rad/s^2]
        self.settle = brake_settle_samples(self.dt)  # commands the applied torque may still follow, (B4)
        self.Q = np.diag([0.0, WHEEL_B_STD**2])
        self.F = np.array([[1.0, -self.dt], [0.0, 1.0]])
        self.reset()

    def reset(self) -> None:
        self.x: list[np.ndarray] | None = None  # per wheel (omega, b)
        self.P: list[np.ndarray] = []
        self.rejected = [0] * self.n
        self.jump = np.zeros((self.n, 3))  # per wheel: armed, reference speed, sign (estimators.jump)
        self.commands = np.full((self.n, self.settle), np.nan)  # per wheel: the span's torques, newest last (B4)

    def _start(self, i: int, omega: float, b: float = 0.0) -> None:
        self.x[i] = np.array([omega, b])
        self.P[i] = np.diag([self.R, self.b_std0[i] ** 2])

    def __call__(self, omega: np.ndarray, torque_prev: np.ndarray,
                 ceiling: float = np.inf) -> tuple[np.ndarray, list[Verdict]]:
        """Gate this sample's wheel speeds, given the torques held since the last one.

        :param ceiling: the highest wheel speed a braked wheel is predicted at (rule (B3)) [rad/s]; inf: none.

        :return: the wheel speeds to use (predictions in place of rejected ones) and one verdict per wheel.
        """
        if self.x is None:
            self.x, self.P = [None] * self.n, [None] * self.n
            for i in range(self.n):
                self._start(i, float(omega[i]))
            return omega, [Verdict.ACCEPT] * self.n
        used = omega.astype(float).copy()
        verdicts = []
        for i in range(self.n):
            x = self.F @ self.x[i] + np.array([self.dt * torque_prev[i] / self.I_w, 0.0])
            if torque_prev[i] < 0 and x[0] > ceiling:  # (B3)
                x[0] = ceiling
            P = self.F @ self.P[i] @ self.F.T + self.Q
            e = float(omega[i]) - x[0]
            S = P[0, 0] + self.R
            before = self.rejected[i]
            span = self.commands[i]
            span[:-1], span[-1] = span[1:], torque_prev[i]  # in place: this sample's command newest
            if before == 0 and nis(e, S) > self.params.bound:  # (B4): the first failing sample, the brake's lag?
                room = ceiling - x[0] if torque_prev[i] < 0 else np.inf
                t_min, t_max = float(np.nanmin(span)), float(np.nanmax(span))
                shift = brake_lag_shift(e, float(torque_prev[i]), t_min, t_max, room, self.dt, self.I_w)
                if nis(e - shift, S) <= self.params.bound:
                    x[0], e = x[0] + shift, e - shift
                else:  # (B6): a released wheel spinning up through the tire's peak?
                    shift = release_shift(e, float(x[1]), float(torque_prev[i]), t_min, self.dt,
                                          float(self.b_bound[i]))
                    if nis(e - shift, S) <= self.params.bound:
                        x[0], x[1], e = x[0] + shift, x[1] - shift / self.dt, e - shift
            verdict, self.rejected[i] = gate(nis(e, S), before, self.params)
            b_restart = 0.0  # the tire term a restart starts from: 0, or the one a friction jump implies
            if verdict != Verdict.ACCEPT:  # a friction jump (estimators.jump): restart at the implied tire term
                ref = self.x[i][0] if before == 0 else self.jump[i, 1]
                jump, chain, b = jump_test(before, bool(self.jump[i, 0] > 0), self.jump[i, 2], ref, float(omega[i]),
                                           float(torque_prev[i]), e, self.dt, self.I_w,
                                           float(self.b_bound[i]), self.rest_band)
                self.jump[i] = (float(chain), float(omega[i]), np.sign(e))
                if jump:
                    verdict, self.rejected[i], b_restart = Verdict.REINIT, 0, b
            if verdict == Verdict.REJECT:  # the covariance is held: a bad run must not widen the gate to itself
                self.x[i], used[i] = x, x[0]
            elif verdict == Verdict.REINIT:
                self._start(i, float(omega[i]), b_restart)
                self.jump[i, 0] = 0.0
            else:
                K = P[:, 0] / S
                self.x[i] = x + K * e
                self.P[i] = P - np.outer(K, P[0])
            verdicts.append(verdict)
        return used, verdicts
