"""The paper report (nonholonomic.report): every claim has a computed verdict; a few verdicts are
asserted, misprinted claims among them; changing a formula in the core changes the verdict."""

from __future__ import annotations

import json
import re

import pytest
import sympy as sp

from nonholonomic import bounded
from nonholonomic.hamiltonization import local_forms as lf
from nonholonomic.report import claim_ids, paper_report
from nonholonomic.report.verdict import CORRECTED, FAILS, HOLDS, UNRESOLVED, Check, judge
from nonholonomic.systems import clebsch


@pytest.fixture(scope="module")
def report() -> dict:
    return paper_report()


def rows(report: dict) -> dict[str, dict]:
    return {r["id"]: r for r in report["rows"]}


def test_every_claim_has_a_row_and_nothing_fails(report):
    json.dumps(report)
    assert [r["id"] for r in report["rows"]] == claim_ids() and len(claim_ids()) >= 35
    assert report["complete"] is True
    assert report["summary"]["fails"] == 0, [r for r in report["rows"] if r["verdict"] == FAILS]
    assert sum(report["summary"].values()) == len(report["rows"])
    for row in report["rows"]:
        assert row["claim"] and row["equation"] and row["checks"], row["id"]
        if row["verdict"] == CORRECTED:  # the printed form was checked the same way and failed
            assert row["printed"] and row["corrected"] and row["printed_check"]["passed"] is False, row


@pytest.mark.parametrize("claim,verdict,errata", [
    ("veselova.multiplier", CORRECTED, "ERRATA 1"),
    ("veselova.S", CORRECTED, "ERRATA 2"),
    ("veselova.theorem_2", CORRECTED, "ERRATA 3"),
    ("veselova.clebsch_hamiltonian", CORRECTED, "new (not in ERRATA)"),
    ("ball.H_angles", CORRECTED, "ERRATA 7"),
    ("ball.theorem_3", CORRECTED, "ERRATA 8"),
    ("jacobi.energy", CORRECTED, "ERRATA 11"),
    ("jacobi.measure", CORRECTED, "ERRATA 13"),
    ("ball.bracket", HOLDS, None),
    ("general.monopole", HOLDS, None),
    ("jacobi.chaos", HOLDS, "ERRATA 'Open'"),
])
def test_verdicts_of_selected_claims(report, claim, verdict, errata):
    row = rows(report)[claim]
    assert row["verdict"] == verdict, row
    assert row["errata"] == errata


def test_residuals_and_tolerances_are_reported(report):
    by_id = rows(report)
    multiplier = by_id["veselova.multiplier"]
    assert multiplier["residual"] <= 1e-12 and multiplier["tolerance"] == 1e-12
    assert multiplier["printed_check"]["residual"] >= 0.1  # (omega, gamma) leaves 0 with the printed sign
    theorem_3 = by_id["ball.theorem_3"]
    assert theorem_3["printed_check"]["residual"] > 0.05 and theorem_3["residual"] <= 1e-13


def test_changing_a_formula_in_the_core_changes_the_verdict(monkeypatch):
    before = paper_report(only=["veselova.S", "veselova.clebsch_hamiltonian"])
    assert [r["verdict"] for r in before["rows"]] == [CORRECTED, CORRECTED]
    # Put the printed S (ERRATA 2) and the printed beta part of H into the core:
    monkeypatch.setattr(lf, "veselova_gyroscopic_term", lf.veselova_gyroscopic_term_printed)
    monkeypatch.setattr(clebsch, "hamiltonian_beta", clebsch.printed_hamiltonian_beta)
    after = paper_report(only=["veselova.S", "veselova.clebsch_hamiltonian"])
    assert [r["verdict"] for r in after["rows"]] == [FAILS, FAILS]


def test_a_broken_check_is_an_unresolved_row_not_a_crashed_report(monkeypatch):
    def broken() -> sp.Expr:
        raise ZeroDivisionError("boom")

    monkeypatch.setattr(lf, "veselova_gyroscopic_term", broken)
    (row,) = paper_report(only=["veselova.S"])["rows"]
    assert row["verdict"] == UNRESOLVED and "ZeroDivisionError: boom" in row["checks"][0]["detail"]


def test_a_safety_cap_fails_the_report_and_is_no_row(monkeypatch):
    """A proof past the machine's safety cap is a failure of the run, not a finding about the claim."""
    def capped() -> sp.Expr:
        raise bounded.SafetyCapExceeded("rational_trig_is_zero", 0.05)

    monkeypatch.setattr(lf, "veselova_gyroscopic_term", capped)
    with pytest.raises(bounded.SafetyCapExceeded):
        paper_report(only=["veselova.S"])


def _without_timings(value: object) -> object:
    """``value`` without its timing fields (``seconds``): what must be the same on every run."""
    if isinstance(value, dict):
        return {k: _without_timings(v) for k, v in value.items() if k != "seconds"}
    if isinstance(value, list):
        return [_without_timings(v) for v in value]
    return value


def test_the_same_report_twice_is_the_same_but_for_its_timings(report):
    """Verdicts and details are decided by the question and the code, never by a clock: no detail holds
    a time, and a second run (its proofs cached) gives the same JSON but for the ``seconds`` fields."""
    text = json.dumps(_without_timings(report))
    assert not re.search(r"\d \(?s\)|\d s\b|within the budget|budget exhausted", text), \
        re.findall(r".{60}(?:\d \(?s\)|\d s\b|budget).{20}", text)[:5]
    ids = ["ball.bracket", "ball.S_bar", "general.theorem_1", "veselova.theorem_2", "jacobi.measure"]
    again = paper_report(only=ids)
    assert _without_timings(again["rows"]) == _without_timings([r for r in report["rows"] if r["id"] in ids])


def test_judge():
    ok, bad, undecided = (Check(v, 0.0, 0.0, "m", "") for v in (True, False, None))
    assert judge([ok], None) == HOLDS and judge([ok], ok) == HOLDS
    assert judge([ok], bad) == CORRECTED and judge([ok, bad], bad) == FAILS
    assert judge([ok, undecided], bad) == UNRESOLVED and judge([], None) == UNRESOLVED
    assert judge([undecided, bad], None) == FAILS


def test_progress_can_stop_the_report():
    seen = []
    report = paper_report(lambda f: seen.append(f) or len(seen) < 2, only=claim_ids()[3:8])
    assert report["complete"] is False and len(report["rows"]) == 2
