"""The verdict rule shared by both plants (fricenv.gap.quarter_car.verdict.decide_verdict)."""

from __future__ import annotations

from types import SimpleNamespace

from fricenv.gap.core.verdict import decide_verdict


def _fit(effect: str, closes: bool):
    return SimpleNamespace(effect=effect, closes=closes)


def _decide(significant, fits, joint_wins=False, gap_is_real=True):
    return decide_verdict(significant, fits, lambda f: f.closes, joint_wins, gap_is_real)


def test_a_candidate_that_closes_the_gap_alone_comes_before_a_better_ranked_one_that_needs_a_partner():
    """Combos seed 3903, log 37 (a radius error and a relaxation length): a friction change ranked first by its
    held-out error left 84 % of the robust gap, and was the verdict because its joint fit with the second candidate
    closed it; the radius error alone closed all of it."""
    mu, radius, gain = _fit("mu_change", False), _fit("radius_error", True), _fit("brake_gain", False)
    verdict, chosen, order = _decide([mu, radius], [mu, radius, gain], joint_wins=True)
    assert verdict == "radius_error" and chosen is radius and order == [radius, mu, gain]


def test_the_best_candidate_stays_the_verdict_when_it_closes_the_gap_or_only_the_joint_fit_does():
    a, b = _fit("drag", True), _fit("brake_gain", True)
    assert _decide([a, b], [a, b])[0] == "drag"
    a, b = _fit("drag", False), _fit("brake_gain", False)
    assert _decide([a, b], [a, b], joint_wins=True)[0] == "drag"
    assert _decide([a, b], [a, b], joint_wins=False)[0] == "unexplained"
    assert _decide([], [a, b], gap_is_real=False)[0] == "none"
