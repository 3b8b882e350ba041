"""POST /v1/brackets/verify, POST /v1/hamiltonize and the structural job checks, through the API."""

from __future__ import annotations

import secrets

import numpy as np
import pytest
import sympy as sp

from tests.support import poll_job

SO3 = {"variables": ["x", "y", "z"], "matrix": [["0", "z", "-y"], ["-z", "0", "x"], ["y", "-x", "0"]],
       "casimirs": {"norm": "x**2 + y**2 + z**2", "wrong": "x**2"}}


def test_so3_bracket_satisfies_jacobi_and_its_casimir(client):
    r = client.post("/v1/brackets/verify", json=SO3)
    assert r.status_code == 200, r.text
    report = r.json()
    assert report["jacobi"]["passed"] is True and report["dimension"] == 3
    verdicts = {c["name"]: c["passed"] for c in report["casimirs"]}
    assert verdicts == {"norm": True, "wrong": False}
    assert report["rank"]["generic"] == 2


def test_a_bracket_failing_jacobi_is_reported(client):
    body = {**SO3, "matrix": [["0", "z", "-x*y"], ["-z", "0", "x"], ["x*y", "-x", "0"]], "casimirs": {}}
    report = client.post("/v1/brackets/verify", json=body).json()
    assert report["jacobi"]["passed"] is False


@pytest.mark.parametrize("entry,reason", [("__import__('os').system('id')", ""), ("x.__class__", ""),
                                          ("(lambda: 1)()", ""), ("9**9**9", ""), ("open('f')", ""), ("w + 1", "w")])
def test_unsafe_or_unknown_expressions_are_422_with_field_and_position(client, entry, reason):
    body = {**SO3, "matrix": [["0", entry, "-y"], ["-z", "0", "x"], ["y", "-x", "0"]]}
    r = client.post("/v1/brackets/verify", json=body)
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json"
    (error,) = r.json()["errors"]
    assert error["field"] == "matrix[0][1]" and "at character" in error["reason"] and reason in error["reason"]


def test_a_non_square_matrix_is_422(client):
    r = client.post("/v1/brackets/verify", json={**SO3, "matrix": [["0", "z"], ["-z", "0"]]})
    assert r.status_code == 422


def test_hamiltonize_worked_examples_find_the_paper_multipliers(client):
    examples = client.get("/v1/hamiltonize/examples").json()["examples"]
    assert set(examples) == {"veselova", "chaplygin_ball"}
    for name, example in examples.items():
        r = client.post("/v1/hamiltonize", json=example)
        assert r.status_code == 200, (name, r.text)
        result = r.json()
        assert result["measure_exists"] is True, (name, result)
        assert result["verification"]["passed"] is True, (name, result["verification"])
        assert result["reducing_multiplier"] and result["S_bar"] is not None


def test_hamiltonize_refuses_unknown_names_and_non_quadratic_lagrangians(client):
    base = {"L": "(q1dot**2 + q2dot**2)/2", "coordinates": ["q1", "q2"], "velocities": ["q1dot", "q2dot"],
            "a1": "0", "a2": "0", "b": "sin(q1)"}
    r = client.post("/v1/hamiltonize", json={**base, "b": "sin(q3)"})
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "b"
    r = client.post("/v1/hamiltonize", json={**base, "L": "q1dot**4"})
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "L"


BALL_VALUES = {"I1": 1.0, "I2": 1.4, "I3": 2.1, "D": 0.6}


@pytest.mark.parametrize("c", [0.35, 0.0])
def test_the_ball_gyroscopic_form_is_a_monopole_of_charge_c(client, c):
    """Text after eq. 2704-9: for c != 0 no global canonical form. The smooth form integrates to
    -4 pi c k / sqrt(I1 I2 I3), k = N / rho_mu (N is found up to a constant factor)."""
    example = client.get("/v1/hamiltonize/examples").json()["examples"]["chaplygin_ball"]
    assert example["monopole"] == {"domain": [["0", "pi"], ["0", "2*pi"]], "shift": ["0", "c*N*cos(theta)"]}
    r = client.post("/v1/hamiltonize", json={**example, "symbols": [], "parameters": {**BALL_VALUES, "c": c}})
    assert r.status_code == 200, r.text
    result = r.json()
    monopole = result["monopole"]
    I1, I2, I3, D = (BALL_VALUES[k] for k in ("I1", "I2", "I3", "D"))
    at_pole = sp.sympify(result["reducing_multiplier"]).subs(
        {"theta": 0, "phi": 0, "I1": I1, "I2": I2, "I3": I3, "D": D})
    k = float(at_pole) * np.sqrt(I3 * (D + I1) * (D + I2))  # rho_mu = (I3 (D+I1)(D+I2))^(-1/2) at gamma = e3
    expected = -4 * np.pi * c * k / np.sqrt(I1 * I2 * I3)
    assert abs(monopole["integral"] - expected) <= 1e-9 * max(abs(expected), 1e-300) + 1e-13, (monopole, expected)
    assert monopole["exact"] is (c == 0.0)
    assert "monopole" in monopole["detail"] or c == 0.0
    if c:
        # the chart integral of S_bar alone is neither 0 nor the charge: p_phi is not a smooth fibre coordinate
        assert abs(monopole["integral_S_bar"] - expected) > 0.1 * abs(expected)


@pytest.mark.parametrize("monopole,field", [
    ({"domain": [["0", "pi"], ["0", "theta"]]}, "monopole.domain[1][1]"),
    ({"domain": [["pi", "0"], ["0", "2*pi"]]}, "monopole.domain[0]"),
    ({"domain": [["0", "pi"], ["0", "2*pi"]], "shift": ["0", "thetadot*cos(theta)"]}, "monopole.shift[1]"),
    ({"domain": [["0", "pi"], ["0", "2*pi", "3"]]}, "monopole.domain[1]"),
])
def test_hamiltonize_refuses_bad_monopole_charts(client, monopole, field):
    example = client.get("/v1/hamiltonize/examples").json()["examples"]["chaplygin_ball"]
    r = client.post("/v1/hamiltonize", json={**example, "monopole": monopole})
    assert r.status_code == 422, r.text
    assert r.json()["errors"][0]["field"] == field, r.json()


def test_the_name_n_is_reserved_in_a_shift(client):
    body = {"L": "(q1dot**2 + N*q2dot**2)/2", "coordinates": ["q1", "q2"], "velocities": ["q1dot", "q2dot"],
            "a1": "0", "a2": "0", "b": "sin(q1)", "symbols": ["N"],
            "monopole": {"domain": [["0", "1"], ["0", "1"]], "shift": ["0", "N"]}}
    r = client.post("/v1/hamiltonize", json=body)
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "monopole.shift", r.text


@pytest.mark.parametrize("kind,state", [("chaplygin_ball", None), ("veselova", None)])
def test_bracket_and_euler_angle_checks_pass_on_a_job(client, kind, state):
    from nonholonomic.systems import SYSTEMS

    body = SYSTEMS[kind].EXAMPLE | {"t_final": 20.0, "samples": 21, "checks": ["integrals", "bracket", "euler_angles"]}
    view = poll_job(client, client.post("/v1/jobs", json=body).headers["location"], timeout=300)
    assert view["status"] == "succeeded", view["error"]
    checks = view["result"]["checks"]
    names = {c["name"] for c in checks}
    assert {"hamiltonian_flow", "hamiltonian_flow_control", "jacobi_identity"} <= names
    assert all(c["passed"] is not False for c in checks), [c for c in checks if c["passed"] is False]
    flow = [c for c in checks if c["name"] == "hamiltonian_flow" and c["method"] == "pointwise"]
    assert flow and flow[0]["residual"] <= 1e-10


def test_symbolic_requests_run_in_a_child_process_and_leave_no_threads(client):
    """A sympy step cannot be stopped in a thread; in the child it ends with the process."""
    import threading

    example = client.get("/v1/hamiltonize/examples").json()["examples"]["chaplygin_ball"]
    before = {t.name for t in threading.enumerate() if t.name.startswith("bounded-")}
    r = client.post("/v1/hamiltonize", json=example)
    assert r.status_code == 200, r.text
    after = {t.name for t in threading.enumerate() if t.name.startswith("bounded-")}
    assert after <= before  # nothing was started in the API process


@pytest.mark.parametrize("grace", [0.0, None], ids=["the child killed", "a step past the cap in the child"])
def test_symbolic_work_past_the_safety_cap_is_a_503_not_a_verdict(client, monkeypatch, grace):
    """The clock is only the machine's safety cap: past it, a 503 with Retry-After that says it is no
    verdict (never a 408, never a 422). Either the child's own wait for a step (bounded.SafetyCapExceeded)
    or the parent's hard limit (cap + GRACE_S; GRACE_S = 0 here) ends it."""
    import service.isolated
    from service.routes.symbolic import SAFETY_CAP_ENV

    monkeypatch.setenv(SAFETY_CAP_ENV, "0.3")
    if grace is not None:
        monkeypatch.setattr(service.isolated, "GRACE_S", grace)
    example = client.get("/v1/hamiltonize/examples").json()["examples"]["chaplygin_ball"]
    # a Lagrangian scaled by a factor of this run's (the same motion): its proofs are new to every memo on
    # disk, so the ball's work takes its ~4 s again
    scaled = {**example, "L": f"{secrets.randbelow(10**9) + 2}*({example['L']})"}
    r = client.post("/v1/hamiltonize", json=scaled)
    assert r.status_code == 503 and r.headers["content-type"] == "application/problem+json", r.text
    problem = r.json()
    assert problem["type"] == "/problems/overloaded" and problem["title"] == "Symbolic work past the safety cap"
    assert "not a verdict" in problem["detail"] and SAFETY_CAP_ENV in problem["detail"], problem
    assert int(r.headers["retry-after"]) >= 1


BUDGET_NOTE = ("budget_s is deprecated and ignored: verdicts are bounded by work limits (limits.max_proof_ops, "
               "limits.max_integrate_ops, limits.max_tidy_ops: sympy operation counts), not seconds, so the same body "
               "gets the same answer on every machine; it will be removed")


def test_the_same_body_gets_the_same_answer_and_budget_s_decides_nothing(cached_client):
    """Every answer is deterministic, so every answer is remembered; budget_s, deprecated, only adds a
    note: the smallest budget used to stop the work (a 422 or an undecided verdict), now the answer is
    the same as without it."""
    example = cached_client.get("/v1/hamiltonize/examples").json()["examples"]["veselova"]
    first = cached_client.post("/v1/hamiltonize", json=example)
    assert first.status_code == 200 and first.headers["cache-status"] == "nonholonomic; fwd=miss; stored", first.text
    assert first.json()["deprecations"] == [] and first.json()["measure_exists"] is True
    second = cached_client.post("/v1/hamiltonize", json=example)
    assert second.headers["cache-status"] == "nonholonomic; hit" and second.json() == first.json()
    tiny = cached_client.post("/v1/hamiltonize", json={**example, "budget_s": 1e-6})
    assert tiny.status_code == 200 and tiny.headers["cache-status"] == "nonholonomic; fwd=miss; stored", tiny.text
    assert tiny.json() == {**first.json(), "deprecations": [BUDGET_NOTE]}
    largest = cached_client.post("/v1/hamiltonize", json={**example, "budget_s": 30})  # the same answer: remembered
    assert largest.headers["cache-status"] == "nonholonomic; hit" and largest.json() == tiny.json()
    for bad in (0, 30.5):  # still validated as before
        r = cached_client.post("/v1/hamiltonize", json={**example, "budget_s": bad})
        assert r.status_code == 422 and r.json()["errors"][0]["field"] == "budget_s", r.text


def test_too_small_limits_leave_the_verdicts_undecided_naming_the_limit(client):
    # so(3) times f = 1 + x^2 (in three dimensions f times a Poisson bracket of this form is one): its
    # Jacobiator cancels only after expansion, so it needs a proof
    scaled = {"variables": ["x", "y", "z"], "matrix": [["0", "(1 + x**2)*z", "-(1 + x**2)*y"],
                                                       ["-(1 + x**2)*z", "0", "(1 + x**2)*x"],
                                                       ["(1 + x**2)*y", "-(1 + x**2)*x", "0"]]}
    assert client.post("/v1/brackets/verify", json=scaled).json()["jacobi"]["method"] == "symbolic"
    r = client.post("/v1/brackets/verify", json={**scaled, "limits": {"max_proof_ops": 1}, "budget_s": 5})
    assert r.status_code == 200, r.text
    report = r.json()
    assert report["deprecations"] == [BUDGET_NOTE]
    jacobi = report["jacobi"]
    assert jacobi["method"] == "pointwise" and jacobi["passed"] is True  # the pointwise check decides
    assert "not tried: " in jacobi["detail"] and "operations > max 1 (max_proof_ops)" in jacobi["detail"]
    again = client.post("/v1/brackets/verify", json={**scaled, "limits": {"max_proof_ops": 1}})
    assert again.json()["jacobi"] == jacobi
    # A = (q1 (q2^2 + 2 q2 + 1), -(q2 + 1)^3/3): closed, but only after expansion (no normal form: max_tidy_ops 0);
    # the density exp(-q1 (q2 + 1)^3/3) comes from sympy's integrate, checked at points, its proof not tried
    body = {"L": "(q1dot**2 + q2dot**2)/2", "coordinates": ["q1", "q2"], "velocities": ["q1dot", "q2dot"],
            "a1": "q1*(q2**2 + 2*q2 + 1)", "a2": "-(q2 + 1)**3/3", "b": "1"}
    r = client.post("/v1/hamiltonize", json={**body, "limits": {"max_proof_ops": 1, "max_tidy_ops": 0}})
    assert r.status_code == 200, r.text
    result = r.json()
    assert result["measure_exists"] is None and result["reason"].endswith("operations > max 1 (max_proof_ops)")
    assert result["verification"]["symbolic"] is None and result["verification"]["passed"] is True
    decided = client.post("/v1/hamiltonize", json=body).json()  # the default limits prove it
    assert decided["measure_exists"] is True and decided["verification"]["method"] == "symbolic"


@pytest.mark.parametrize("limits,field", [({"max_proof_ops": 200_001}, "limits.max_proof_ops"),
                                          ({"max_integrate_ops": -1}, "limits.max_integrate_ops"),
                                          ({"max_tidy_ops": 20_001}, "limits.max_tidy_ops"),
                                          ({"max_seconds": 1}, "limits.max_seconds")])
def test_limits_outside_their_bounds_are_422(client, limits, field):
    r = client.post("/v1/brackets/verify", json={**SO3, "limits": limits})
    assert r.status_code == 422 and [e["field"] for e in r.json()["errors"]] == [field], r.text


def test_a_repeated_symbolic_request_is_answered_from_the_cache(cached_client):
    first = cached_client.post("/v1/brackets/verify", json=SO3)
    assert first.status_code == 200 and first.headers["cache-status"] == "nonholonomic; fwd=miss; stored"
    second = cached_client.post("/v1/brackets/verify", json=SO3)
    assert second.status_code == 200 and second.headers["cache-status"] == "nonholonomic; hit"
    assert second.json() == first.json() and second.json()["jacobi"]["passed"] is True
    other = cached_client.post("/v1/brackets/verify", json={**SO3, "casimirs": {"norm": "x**2 + y**2 + z**2"}})
    assert other.headers["cache-status"].startswith("nonholonomic; fwd=miss")  # another body: computed
    assert [c["name"] for c in other.json()["casimirs"]] == ["norm"]
