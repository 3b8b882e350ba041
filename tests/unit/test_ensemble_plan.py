"""Chunk planning and the reduction of member digests (nonholonomic.analysis.ensemble)."""

from __future__ import annotations

import math

import pytest

from nonholonomic.analysis.ensemble import default_chunk_size, plan, summarize
from nonholonomic.analysis.options import SectionOptions, SpectrumOptions
from nonholonomic.systems import get_system


def test_plan_covers_every_member_once_in_order():
    chunks = plan(103, 16)
    assert [c.index for c in chunks] == list(range(7))
    members = [i for c in chunks for i in range(c.start, c.stop)]
    assert members == list(range(103)) and chunks[-1].size == 7


@pytest.mark.parametrize("count, size", [(0, 4), (5, 0)])
def test_plan_refuses_empty_requests(count, size):
    with pytest.raises(ValueError):
        plan(count, size)


def test_default_chunk_size_is_a_multiple_of_the_lanes_and_shrinks_with_the_work():
    ball = get_system("chaplygin_ball", "zero")
    plain = default_chunk_size(ball, 100.0, lanes=4)
    with_section = default_chunk_size(ball, 100.0, poincare=SectionOptions("gamma3"), lanes=4)
    with_exponents = default_chunk_size(ball, 100.0, lyapunov=SpectrumOptions(1), lanes=4)
    longer = default_chunk_size(ball, 1e4, lyapunov=SpectrumOptions(1), lanes=4)
    assert all(s % 4 == 0 for s in (plain, with_section, with_exponents, longer))
    assert plain > with_section > with_exponents > longer == 4
    assert 2000 <= plain <= 4096  # ~3500 trajectories of t = 100 per second


def test_summarize_counts_failures_and_reduces_the_exponents():
    digests = [{"index": 0, "status": "succeeded", "integral_drift": {"energy": 1e-15}, "checks_failed": [],
                "largest_exponent": 0.1, "section_points": 10},
               {"index": 1, "status": "failed", "error": "IntegrationError: non-finite state"},
               {"index": 2, "status": "succeeded", "integral_drift": {"energy": 3e-15}, "checks_failed": ["energy"],
                "largest_exponent": 0.3, "section_points": 4}]
    s = summarize(digests)
    assert (s["members"], s["succeeded"], s["failed"]) == (3, 2, 1)
    assert s["failures"] == [{"index": 1, "error": "IntegrationError: non-finite state"}]
    assert s["worst_integral_drift"] == {"energy": 3e-15} and s["members_with_failed_checks"] == 1
    assert math.isclose(s["largest_exponent"]["mean"], 0.2) and s["largest_exponent"]["max"] == 0.3
    assert s["section_points"] == {"total": 14, "min_per_member": 4, "max_per_member": 10}


def test_summary_is_json_without_nan_or_infinity():
    """A member whose integral or exponent is not finite must not make the summary unserialisable
    (the API answers with allow_nan=False): the worst drift is None, the exponent is counted apart."""
    import json

    digests = [{"index": 0, "status": "succeeded", "integral_drift": {"energy": 1e-15, "area": float("nan")},
                "largest_exponent": 0.1},
               {"index": 1, "status": "succeeded", "integral_drift": {"energy": float("inf"), "area": 2e-15},
                "largest_exponent": float("nan")}]
    s = summarize(digests)
    json.dumps(s, allow_nan=False)
    assert s["worst_integral_drift"] == {"energy": None, "area": None}
    assert s["largest_exponent"]["count"] == 1 and s["largest_exponent"]["non_finite"] == 1
    assert s["largest_exponent"]["max"] == 0.1
