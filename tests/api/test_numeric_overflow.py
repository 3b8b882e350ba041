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
    ("b", f"exp(exp(exp(exp(exp({q1} + {q2})))))"),  # was a 503 after 130 s of sympy: now refused first, in floats
])
def test_a_tower_of_exponentials_is_answered_without_a_500(client, field, text):
    body = {**BASE, "L": EXAMPLE_JOB["system"]["L"], "parameters": EXAMPLE_JOB["system"]["parameters"],
            field: text}
    r = client.post("/v1/hamiltonize", json=body)
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json", r.text
    errors = {e["field"]: e["reason"] for e in r.json()["errors"]}
    # the tower overflows a float at the sample points; 1e300 is refused by the parser already
    assert field in errors and ("overflows the floating-point range" in errors[field] or "too large" in errors[field])


def test_a_numeric_failure_while_checking_a_job_names_the_expression_that_overflows():
    """The validation's net (service/validation.py): the field whose float value overflows is named; when none
    does at the sample points, every expression field is, with the error's type."""
    from nonholonomic.numerics.overflow import numeric_problems

    tower = ("system.potential.U", "exp(exp(exp(exp(exp(gamma1)))))")
    fine = ("claims[0].expression", "M1*gamma2 + sin(M3)")
    named = numeric_problems([tower, fine], OverflowError("math range error"))
    assert [field for field, _ in named] == ["system.potential.U"], named
    assert "overflows the floating-point range" in named[0][1]
    fallback = numeric_problems([fine], MemoryError())
    assert fallback == [("claims[0].expression", fallback[0][1])] and "(MemoryError)" in fallback[0][1]


def test_a_numeric_failure_no_route_caught_is_a_422_not_a_500(client):
    """The app's last net (service/errors.py): OverflowError, MemoryError and FloatingPointError answer a 422
    problem naming ``body``, never a 500."""
    def overflowing() -> None:
        raise OverflowError("(34, 'Numerical result out of range')")

    client.app.add_api_route("/v1/_test_overflow", overflowing, methods=["GET"])
    r = client.get("/v1/_test_overflow")
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json", r.text
    (error,) = r.json()["errors"]
    assert error["field"] == "body" and "(OverflowError)" in error["reason"]
