"""What a named effect may also be, where the log's channels cannot test the other (``where["alternatives"]``).

**A rolling radius read as a brake gain.** Without ``v`` and ``a_x``, the diagnosis sees the car only through the
wheel speed and the brake torque. A plant whose rolling radius is ``r_e`` instead of the model's ``r`` obeys

    J omega' = r_e F - T_b,    m v' = -F,    lambda = 1 - omega r_e / v                      (A1)

With ``u = v r / r_e``, the speed the model's radius reads from the wheel, and ``F_u = F r / r_e``, the force of a
road of ``theta r / r_e``, (A1) multiplied through is

    m u' = -F_u,    J (r / r_e)^2 omega' = r F_u - (r / r_e)^2 T_b,    lambda = 1 - omega r / u      (A2)

the nominal model with a brake gain ``g = (r / r_e)^2`` (the wheel sees ``g T_b``) on a road of ``theta r / r_e``,
but with the wheel inertia ``J (r / r_e)^2`` in place of ``J``. The road is always fitted, so on such a log a radius
error and a brake gain differ in the wheel-inertia term alone (4-10 % for a radius 2-5 % off), which the wheel's
transients carry only faintly: on the logs of the independent simulator's ``--omega-only`` suites (seeds 3000 and
4621) that carry either effect, both fitted, the two fits' held-out z differed by less than 0.5 on 9 of 12. The
library leaves the radius untested there (:func:`fricenv.effects.library._testable_radius`), and a named
``brake_gain`` of ``g`` comes with the radius that gives the same data, ``r_e = r / sqrt(g)``: on the radius-error
logs named ``brake_gain`` (seed 4620 logs 0 and 15; seed 4621 log 3, with the radius tested) that radius is 1.6 %,
0.1 % and 0.3 % from the true one.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from fricenv.plants.quarter_car import QuarterCarParams

__all__ = ["ALTERNATIVES", "alternatives"]


def _radius_from_gain(params: Mapping[str, float], p: QuarterCarParams) -> dict[str, float]:
    """(A2): the rolling radius whose data, without ``v`` and ``a_x``, a brake gain ``g`` reproduces."""
    return {"r_eff": float(p.r / np.sqrt(params["gain"]))}


# (named effect, effect the log could not test) -> (the untested effect's parameters from the named one's, why)
ALTERNATIVES: dict[tuple[str, str], tuple[Callable[[Mapping[str, float], QuarterCarParams], dict], str]] = {
    ("brake_gain", "radius_error"): (
        _radius_from_gain,
        ("without v or a_x a rolling radius r_e gives the data of a brake gain (r/r_e)^2 on a road of theta r/r_e "
         "(they differ in the wheel-inertia term alone): log v or a_x to tell them apart")),
}


def alternatives(effects: list[dict], not_testable: Mapping[str, str], p: QuarterCarParams) -> list[dict]:
    """The untested effects that would give the same data as a named one.

    :param effects: the named effects, ``[{"effect", "params"}, ...]``.
    :param not_testable: the effects the log could not test, with why.
    :param p: nominal vehicle parameters.
    :return: ``[{"effect", "params", "instead_of", "why"}, ...]`` (empty when every alternative was tested).
    """
    out = []
    for named in effects:
        for (effect, untested), (convert, why) in ALTERNATIVES.items():
            if named["effect"] == effect and untested in not_testable:
                out.append({"effect": untested, "params": convert(named["params"], p), "instead_of": effect,
                            "why": why})
    return out
