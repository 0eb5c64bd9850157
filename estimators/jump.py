"""Friction jumps seen by the wheel-speed gate: a run of rejected wheel speeds that a road can explain.

The wheel-speed gate of the EKF/RLS (:class:`estimators.speed_reference.WheelSpeedGate`, batched in
:mod:`estimators.batched`) predicts each wheel speed with the wheel equation

    (J1)  omega(k+1) = omega(k) + dt (T(k) / I_w - b(k)),     b = F R_w / I_w (the tire's torque over the inertia)

and rejects a sample whose innovation fails the chi-square test. When the road's friction drops (dry -> ice) the
tire term b collapses within one sample and the braked wheel decelerates at up to ``T / I_w`` (900 rad/s^2 at
dry's peak torque on this car): the next samples fail the test, and before this rule the gate discarded them for
``max_rejections`` (10) samples, 100 ms -- while the wheel locked. Measured on a trained PPO + EKF/RLS policy
(training seed 10, dry->ice at 20 m/s, evaluation seeds 0-2): ten OUTLIER samples from the jump, a negative slip
estimate from the gate's prediction, the true slip 1 for 0.1 s: a lock event on every seed.

The rule. Each rejected sample implies a tire term from the speed before it (the gate's speed after an accepted
sample, the raw sample after a rejected one):

    (J2)  b_implied = (omega_ref + dt T / I_w - omega) / dt

which a road can produce only if ``|b_implied| <= b_bound = JUMP_MU_MAX F_z R_w / I_w`` (a tire force within
``JUMP_MU_MAX`` times the load). A second rejected sample in a row whose innovation has the sign of the first, in a run
whose every sample a road can produce, is a friction jump: the gate restarts from it with b at its implied value
(``Health.REINITIALISED``: 20 ms after the jump, not 100 ms). Any restart of the gate also restarts the EKF/RLS's
memory of the road (:meth:`estimators.ekf_rls.EkfRlsCore.step`: the RLS covariance restarts, and the curve-shape
fit withholds its peak friction until its own jump test restarts its memory, :meth:`estimators.curve_shape.ShapeFit.
restart`), whose own detectors held dry's peak friction for about 0.4 s after the jump (the same trace). An isolated spike passes no such test (the sample
after it agrees with the old prediction and is accepted); a spike of a tenth or ten times the speed, or a drop to
zero at speed, implies a tire force many times the load. A run of equal bad readings at low speed (a dropout to
zero below about 5 m/s) does look like a wheel that locked, and is then taken as one: for a brake controller the
safe reading.

(J3) **A braked wheel at rest stays at rest.** (J2) reads the torque commanded as the torque the brake
applies. While the wheel turns it does; at rest the brake holds the wheel and applies only what the tire
pulls (it never turns the wheel backwards), so a command above what a road can hold implies no tire term
at all. A sample within ``rest_band`` of 0 after one within it, while the torque brakes, is therefore
physical whatever (J2) gives, with the implied term held to the bound. A wheel that a lagging brake holds
locked while the command falls is thus a run of physical samples, restarted at the second; without the
rule the run's third sample broke it and the gate rejected the locked wheel ``max_rejections`` times (80
ms brake lag, dry ABS stop, seed 1: 10 samples). The step into rest is still judged by (J2), so a dropout
to zero at speed stays a spike. ``rest_band`` 0 is the rule off.

:func:`jump_test` is plain Python compiled into the batched gate (:func:`estimators.batched._gate_row`), so the
single and the batched gates run the same rule.
"""

from __future__ import annotations

import numpy as np

from estimators.tuning import JUMP_MU_MAX  # largest friction coefficient a road may show in (J2) [-]

__all__ = ["JUMP_MU_MAX", "jump_test"]



def jump_test(rejected_before: int, armed: bool, prev_sign: float, omega_ref: float, omega: float, torque: float,
              e: float, dt: float, I_w: float, b_bound: float,
              rest_band: float = 0.0) -> tuple[bool, bool, float]:
    """Decide whether a rejected wheel speed is a friction jump, (J2) and the rule of the module docstring.

    :param rejected_before: samples rejected in a row just before this one.
    :param armed: every rejected sample of the run so far implied a tire term a road can produce.
    :param prev_sign: sign of the previous rejected sample's innovation.
    :param omega_ref: wheel speed the implied term is measured from [rad/s].
    :param omega: this sample [rad/s].
    :param torque: torque held since the last sample, traction-positive [N m].
    :param e: this sample's innovation (measured minus predicted) [rad/s].
    :param dt: sample time [s].
    :param I_w: wheel inertia [kg m^2].
    :param b_bound: largest |b| a road can produce [rad/s^2].
    :param rest_band: a braked wheel within this of 0 on this and the reference sample is at rest, (J3)
        [rad/s].
    :return: (a jump, the run up to this sample is physical (the next call's ``armed``), the implied term b
        [rad/s^2]).
    """
    b = (omega_ref + dt * torque / I_w - omega) / dt  # (J2)
    physical = abs(b) <= b_bound
    if rest_band > 0.0 and torque < 0.0 and abs(omega) <= rest_band and abs(omega_ref) <= rest_band:  # (J3)
        physical, b = True, min(max(b, -b_bound), b_bound)
    chain = physical and (rejected_before == 0 or armed)  # every sample of the run so far is physical
    return rejected_before >= 1 and chain and np.sign(e) == prev_sign, chain, b
