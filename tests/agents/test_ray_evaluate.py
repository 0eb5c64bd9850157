"""``fricenv evaluate`` / ``compare`` on Ray: the same episodes give the same rows from the local
process pool, in this process and on a local Ray instance (2 CPUs, started and shut down by the test)."""

from __future__ import annotations

import pytest

from agents.evaluation import Scenario, evaluate
from tests.gap.test_ray_fleet import local_ray  # noqa: F401 - the fixture: a local 2-CPU Ray instance

ray = pytest.importorskip("ray", reason="ray is a dependency of fricenv (pyproject.toml)")

SCENARIOS = (Scenario("wet", 20.0), Scenario("dry->ice", 20.0))
POLICIES = ("rule-abs", "locked")


@pytest.mark.xdist_group("ray")
@pytest.mark.slow  # Ray workers start and compile in a fresh environment: 80-100 s
def test_rows_identical_in_process_pool_and_on_ray(local_ray):  # noqa: F811 - pytest fixture
    serial = evaluate(POLICIES, scenarios=SCENARIOS, seeds=[3, 8], workers=1, progress=False)
    pool = evaluate(POLICIES, scenarios=SCENARIOS, seeds=[3, 8], workers=2, progress=False)
    on_ray = evaluate(POLICIES, scenarios=SCENARIOS, seeds=[3, 8], progress=False, ray="auto")
    assert local_ray.is_initialized()  # the test's instance was joined and left to its owner
    assert [(r["policy"], r["scenario"], r["episodes"]) for r in on_ray] == [
        (p, s.name, 2) for p in ("rule-abs", "locked") for s in SCENARIOS]
    assert on_ray == pool == serial  # bit-identical floats: the same episodes on either engine
    by_policy = {(r["policy"], r["scenario"]): r for r in on_ray}
    assert by_policy[("locked", "wet@20")]["locks"] == 2  # the rows carry the episodes' real outcomes
    assert by_policy[("rule-abs", "wet@20")]["ratio_mean"] < by_policy[("locked", "wet@20")]["ratio_mean"]


def test_bad_ray_address_is_one_line_error():
    with pytest.raises(ValueError, match="--ray must be 'auto' or a Ray cluster address"):
        evaluate(["rule-abs"], scenarios=SCENARIOS[:1], seeds=1, progress=False, ray="")
