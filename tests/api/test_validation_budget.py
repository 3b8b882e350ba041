"""Issue 19, items 1, 2, 3 (tolerance) and 12, with issue 31's rule: a request's expressions are refused only
by deterministic measures (the monomials they multiply out to, how deeply their functions nest), read off the
event loop with a clock only as a safety cap (a 503, never a 422), a 503 when the pool is full; the three 500s on
expressions are 422s, tolerances outside [machine epsilon, 1e-3] are refused, and what was accepted only to fail
every time (an unused parameter, a surface whose gradient vanishes at x0) is a 422."""

from __future__ import annotations

import copy

import pytest

from nonholonomic.systems.ball_on_surface import EXAMPLE as SURFACE_JOB
from nonholonomic.systems.generalized_chaplygin import EXAMPLE_JOB as CHAPLYGIN_JOB
from service.admission import SymbolicPool
from tests.api.conftest import BALL, job

#: The audit's bodies (issue 19, item 1): 152 s, 51 s and 16 s to answer on main.
POWER_SURFACE = job(poincare={"surface": "(M1+gamma2+gamma3+1)**64"})
NESTED_PHI = copy.deepcopy(SURFACE_JOB)
NESTED_PHI["system"]["surface"] = {"Phi": "sin(" * 59 + "x1" + ")" * 59, "parameters": {}}  # the plane x1 = 0, bent
NESTED_PHI["initial_state"]["x"] = [0.0, 0.0, 1.0]
_TERMS = [f"gamma1**{i}*gamma2**{j}*gamma3**{k}" for i in range(1, 9) for j in range(1, 9) for k in range(1, 9)]
LONG_SUM = job(system={**BALL, "potential": {"kind": "expression", "U": " + ".join(_TERMS[:62])}})  # 1985 characters
#: The deterministic refusals of the first two (the same words on every machine, at any load).
REFUSED = {"poincare.surface": "expands to up to 47,905 monomials > max 10,000 (MAX_EXPANDED_TERMS)",
           "system.surface.Phi": "nests functions 59 deep > max 12 (MAX_FUNCTION_NESTING)"}


def _errors(r) -> dict[str, str]:
    assert r.status_code == 422, (r.status_code, r.text[:400])
    assert r.headers["content-type"] == "application/problem+json"
    return {e["field"]: e["reason"] for e in r.json()["errors"]}


@pytest.mark.parametrize("body, field", [(POWER_SURFACE, "poincare.surface"), (NESTED_PHI, "system.surface.Phi")],
                         ids=["power-surface", "nested-phi"])
def test_the_audits_expensive_bodies_are_refused_by_a_measure_of_their_work(client, body, field, monkeypatch):
    """Refused before sympy reads them (no child process is started), naming the measure and its limit."""
    import service.validation

    monkeypatch.setattr(service.validation, "run_isolated", lambda *a, **k: (_ for _ in ()).throw(AssertionError))
    errors = _errors(client.post("/v1/jobs", json=body))
    assert list(errors) == [field] and REFUSED[field] in errors[field], errors


def test_a_long_sum_within_the_measures_is_accepted(client):
    """62 distinct monomials: within both measures, read to its end (no clock decides)."""
    assert client.post("/v1/jobs", json={**LONG_SUM, "t_final": 1.0, "samples": 11}).status_code == 202


def test_past_the_safety_cap_the_answer_is_a_503_not_a_refusal(client, monkeypatch):
    """The clock is only a safety cap: a check still running at it is a 503 with Retry-After saying so."""
    monkeypatch.setattr(client.app.state.settings, "validation_safety_cap_s", 1e-3)
    r = client.post("/v1/jobs", json={**LONG_SUM, "t_final": 1.0, "samples": 11})
    assert r.status_code == 503 and int(r.headers["retry-after"]) >= 1, r.text
    assert "safety cap" in r.json()["detail"] and "not a verdict" in r.json()["detail"]


def test_an_ensemble_surface_is_measured_too(client):
    body = {"system": dict(BALL), "members": {"initial_states": [{"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}]},
            "t_final": 1.0, "poincare": {"surface": "(M1+gamma2+gamma3+1)**64"}}
    errors = _errors(client.post("/v1/ensembles", json=body))
    assert REFUSED["poincare.surface"] in errors["poincare.surface"]


def test_a_full_pool_answers_503_with_retry_after(client):
    pool = SymbolicPool(1, 0)
    pool.running = 1  # its one slot is taken and nothing may wait
    client.app.state.symbolic_pool = pool
    r = client.post("/v1/jobs", json=job(poincare={"surface": "M1*gamma1 + M2*gamma2"}))
    assert r.status_code == 503 and int(r.headers["retry-after"]) >= 1, r.text


def test_requests_without_expressions_are_checked_in_process(client, monkeypatch):
    """No child process for a plain job, nor for a surface that is a bare name (the load benchmark's jobs)."""
    import service.validation

    def no_child(*args, **kwargs):
        raise AssertionError("a child process was started")

    monkeypatch.setattr(service.validation, "run_isolated", no_child)
    assert client.post("/v1/jobs", json=job(t_final=1.0)).status_code == 202
    assert client.post("/v1/jobs", json=job(t_final=1.0, poincare={"surface": "gamma3"})).status_code == 202
    errors = _errors(client.post("/v1/jobs", json=job(t_final=1.0, poincare={"surface": "gamma9"})))
    assert "unknown name 'gamma9'" in errors["poincare.surface"]


def test_cheap_checks_answer_before_any_child(client, monkeypatch):
    """Syntax and names are checked while the body is read (no sympy): a 422 at once."""
    import service.validation

    monkeypatch.setattr(service.validation, "run_isolated", lambda *a, **k: (_ for _ in ()).throw(AssertionError))
    body = job(system={**BALL, "potential": {"kind": "expression", "U": "gamma1 + nope"}})
    assert "unknown name 'nope'" in _errors(client.post("/v1/jobs", json=body))["system.potential.U"]


# --- item 2: the three 500s ------------------------------------------------------------------------

@pytest.mark.parametrize("exponent", ["pi", "E", "sqrt(2)", "(pi/2)"])
def test_an_irrational_exponent_in_a_surface_is_a_422(client, exponent):
    """M1**pi: RecursionError (500) on main."""
    errors = _errors(client.post("/v1/jobs", json=job(poincare={"surface": f"M1**{exponent}"})))
    assert "must be a rational number" in errors["poincare.surface"]


def test_exp_of_pi_log_is_the_same_power_and_refused(client):
    errors = _errors(client.post("/v1/jobs", json=job(poincare={"surface": "exp(pi*log(M1))"})))
    assert "must be a rational number" in errors["poincare.surface"]


def test_sign_in_a_casimir_is_a_422(client):
    """NameError (DiracDelta, 500) on main."""
    body = {"variables": ["x", "y", "z"], "matrix": [["0", "z", "-y"], ["-z", "0", "x"], ["y", "-x", "0"]],
            "casimirs": {"c": "sign(x)*(x**2 + y**2 + z**2)"}}
    errors = _errors(client.post("/v1/brackets/verify", json=body))
    assert "sign() is not smooth" in errors["casimirs.c"]


@pytest.mark.parametrize("field", ["a1", "a2", "L", "potential"])
def test_sign_in_hamiltonize_is_a_422(client, field):
    """NameError (DiracDelta, 500) on main for a1."""
    body = {"L": "(q1dot**2 + q2dot**2)/2", "coordinates": ["q1", "q2"], "velocities": ["q1dot", "q2dot"],
            "a1": "q2", "a2": "0", "b": "0"}
    body[field] = "(1 + sign(q1)/2)*(q1dot**2 + q2dot**2)/2" if field == "L" else "sign(q1 - q2)"
    assert "sign() is not smooth" in _errors(client.post("/v1/hamiltonize", json=body))[field]


def test_abs_still_works_where_one_derivative_is_taken(client):
    body = {"variables": ["x", "y", "z"], "matrix": [["0", "z", "-y"], ["-z", "0", "x"], ["y", "-x", "0"]],
            "casimirs": {"c": "abs(x)"}}
    assert client.post("/v1/brackets/verify", json=body).status_code == 200


# --- item 3: tolerances ----------------------------------------------------------------------------

@pytest.mark.parametrize("tolerance", [5e-324, 1e-17, 2e-16, 2e-3, 1.0])
def test_a_tolerance_outside_machine_epsilon_to_1e_3_is_a_422(client, tolerance):
    """5e-324 was accepted on main, and its job never ended."""
    errors = _errors(client.post("/v1/jobs", json=job(integrator={"tolerance": tolerance})))
    assert "integrator.tolerance" in errors


def test_an_ensembles_tolerance_is_bounded_too(client):
    body = {"system": dict(BALL), "members": {"initial_states": [{"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}]},
            "t_final": 1.0, "integrator": {"tolerance": 5e-324}}
    assert "integrator.tolerance" in _errors(client.post("/v1/ensembles", json=body))


@pytest.mark.parametrize("tolerance", [2.220446049250313e-16, 1e-10, 1e-3])
def test_the_ends_of_the_tolerance_range_are_accepted(client, tolerance):
    assert client.post("/v1/jobs", json=job(t_final=1.0, integrator={"tolerance": tolerance})).status_code == 202


# --- item 12: accepted, then always failing --------------------------------------------------------

def test_a_parameter_no_expression_uses_is_a_422(client):
    """Accepted on main; every job then failed with heyoka's ValueError (0 parameters in the system)."""
    system = {"kind": "generalized_chaplygin", "coordinates": ["q1", "q2"], "velocities": ["u1", "u2"],
              "L": "(u1**2 + u2**2)/2 + k*0", "a1": "q2", "a2": "0", "b": "0", "parameters": {"k": 1.0}}
    body = {"system": system, "initial_state": {"q": [0.1, 0.2], "q_dot": [0.3, 0.1]}, "t_final": 1.0, "samples": 11}
    errors = _errors(client.post("/v1/jobs", json=body))
    assert "not used by any expression" in errors["system.parameters.k"]


def test_the_generalized_chaplygin_example_still_runs(client):
    body = copy.deepcopy(CHAPLYGIN_JOB)
    body.update(t_final=1.0, samples=11)
    assert client.post("/v1/jobs", json=body).status_code == 202


def test_a_surface_whose_gradient_vanishes_at_x0_is_a_422(client):
    """Accepted on main; the job then failed with nan (heyoka err_nf_state)."""
    body = copy.deepcopy(SURFACE_JOB)
    body["system"]["surface"] = {"Phi": "(x1**2 + x2**2 + x3**2 - 9)**2", "parameters": {}}
    body["initial_state"]["x"] = [3.0, 0.0, 0.0]
    errors = _errors(client.post("/v1/jobs", json=body))
    assert "grad Phi vanishes here" in errors["initial_state.x"]
