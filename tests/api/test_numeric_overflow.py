"""Numeric failure in evaluating a user's expression is never a 500 (issue 34, item 2): a tower of exponentials
in a Hamiltonization request overflowed mpmath (OverflowError) or exhausted memory (MemoryError) inside the
reducing multiplier's numeric check, and the answer was a 500 with the connection dropped."""

from __future__ import annotations

import pytest

from nonholonomic.systems.generalized_chaplygin import EXAMPLE_JOB

BASE = {k: EXAMPLE_JOB["system"][k] for k in ("coordinates", "velocities", "a1", "a2", "b")}
q1, q2 = EXAMPLE_JOB["system"]["coordinates"]


@pytest.mark.parametrize("field,text", [
    ("a1", f"exp(exp(exp(exp(exp({q1})))))"),
    ("a1", f"exp(exp(exp(exp(exp({q2})))))"),
    ("a2", f"exp(exp(exp(exp({q1}))))*1e300"),
])
def test_a_tower_of_exponentials_is_answered_without_a_500(client, field, text):
    body = {**BASE, "L": EXAMPLE_JOB["system"]["L"], "parameters": EXAMPLE_JOB["system"]["parameters"],
            field: text}
    r = client.post("/v1/hamiltonize", json=body)
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json", r.text
    errors = {e["field"]: e["reason"] for e in r.json()["errors"]}
    # the tower overflows a float at the sample points; 1e300 is refused by the parser already
    assert field in errors and ("overflows the floating-point range" in errors[field] or "too large" in errors[field])
