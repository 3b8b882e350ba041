"""A potential of the user's own through the API: a job and an ensemble with it run and keep their
energy; a bad U, a bad parameter name and a U singular at the initial state are 422 problems naming
the field; the catalog says which names a U may use."""

from __future__ import annotations

import math

from tests.api.conftest import BALL, job
from tests.support import poll_job

USER = {"kind": "expression", "U": "q*gamma3**2 + r*sin(gamma1)", "parameters": {"q": 0.4, "r": -0.3}}


def test_a_job_with_the_users_potential_runs_and_keeps_its_energy(client):
    r = client.post("/v1/jobs", json=job(system={**BALL, "potential": USER}))
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"])
    assert view["status"] == "succeeded", view["error"]
    result = view["result"]
    assert result["system"]["potential"] == "expression"
    assert result["system"]["potential_formula"] == f"U = {USER['U']}"
    integrals = {i["name"]: i for i in result["integrals"]}
    assert set(integrals) == {"energy", "geometric", "area"}  # F = (M, M) holds only for U = 0
    assert integrals["energy"]["passed"] and integrals["energy"]["max_rel_drift"] < 1e-12
    assert all(c["passed"] for c in result["checks"])
    assert view["request"]["system"]["potential"] == USER
    assert client.get(f"{r.headers['location']}/page").status_code == 200
    assert client.get(f"{r.headers['location']}/plots/integrals.png").status_code == 200


def test_an_ensemble_with_the_users_potential(client):
    body = {"system": {**BALL, "potential": USER}, "t_final": 10.0,
            "members": {"sample": {"count": 4, "seed": 2, "level": {"energy": 1.0}}}}
    r = client.post("/v1/ensembles", json=body)
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"])
    assert view["status"] == "succeeded" and view["members_done"] == 4
    members = client.get(f"{r.headers['location']}/members").json()["members"]
    assert all(m["status"] == "succeeded" for m in members)
    energies = [{i["name"]: i for i in m["integrals"]}["energy"]["initial"] for m in members]
    assert all(abs(e - 1.0) < 1e-9 for e in energies), energies  # the level set of H = T + U with the user's U


def _problem(client, potential, **state):
    body = job(system={**BALL, "potential": potential})
    if state:
        body["initial_state"] = state
    r = client.post("/v1/jobs", json=body)
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json", r.text
    return {e["field"]: e["reason"] for e in r.json()["errors"]}


def test_a_bad_users_potential_is_a_422_naming_the_field(client):
    errors = _problem(client, {**USER, "U": "q*gamma3**2 + r*M1"})
    assert "unknown name 'M1'" in errors["system.potential.U"] and "character 16" in errors["system.potential.U"]
    errors = _problem(client, {**USER, "parameters": {"q": 1.0, "r": 1.0, "D": 2.0}})  # D: the ball's own name
    assert "D: already a name of chaplygin_ball" in errors["system.potential.parameters"]
    errors = _problem(client, {**USER, "U": "q*abs(gamma1)"})
    assert "abs() is not smooth" in errors["system.potential.U"]
    errors = _problem(client, {**USER, "U": "q/gamma1"})  # gamma1 = 0 at the initial state
    assert "not finite at the initial state" in errors["system.potential.U"]
    errors = _problem(client, {**USER, "parameters": {"q": float("1e300"), "r": 0.0}})
    assert "system.potential.parameters.q" in errors


def test_the_catalog_says_what_a_potential_may_use(client):
    catalog = {s["kind"]: s for s in client.get("/v1/systems").json()["systems"]}
    assert catalog["ball_on_quadric"]["potential_expression"]["variables"] == ["x1", "x2", "x3"]
    assert catalog["chaplygin_ball_veselova"]["potential_expression"]["variables"] == [
        "gamma1", "gamma2", "gamma3", "E1", "E2", "E3"]
    example = catalog["clebsch"]["potential_expression"]["example"]
    body = {**catalog["clebsch"]["example"], "t_final": 5.0}
    body["system"] = {**body["system"], "potential": example}
    r = client.post("/v1/jobs", json=body)
    assert r.status_code == 202, r.text
    assert poll_job(client, r.headers["location"])["status"] == "succeeded"


def test_claims_come_back_with_their_evidence_and_a_bad_one_is_a_422(client):
    body = job(claims=[{"name": "area", "expression": "M1*gamma1 + M2*gamma2 + M3*gamma3"}])
    view = poll_job(client, client.post("/v1/jobs", json=body).headers["location"])
    (claim,) = view["result"]["claims"]
    assert claim["name"] == "area" and claim["passed"] and claim["symbolic"]["identically_conserved"] is True
    r = client.post("/v1/jobs", json=job(claims=[{"name": "x", "expression": "M1 +* 2"}]))
    assert r.status_code == 422 and "claims[0].expression" in {e["field"] for e in r.json()["errors"]}
    r = client.post("/v1/jobs", json=job(claims=[{"name": "x", "expression": "M1"}] * 11))
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "claims"


def test_a_claim_not_finite_at_the_initial_state_is_a_422_and_one_that_ends_not_finite_is_reported(client):
    """Issue 34, item 3: a claim with no finite real value at the initial state would fail every job (its
    evidence is non-finite from the first sample): refused at submission naming it. One finite there that
    leaves the reals along the orbit no longer fails the job: its evidence says where it is not finite."""
    # M2 = -0.2 at the conftest's initial state: a negative number to a non-integer power is not real
    r = client.post("/v1/jobs", json=job(claims=[{"name": "bad", "expression": "M2**M3"}]))
    assert r.status_code == 422, r.text
    (error,) = r.json()["errors"]
    assert error["field"] == "claims[0].expression" and "value at the initial state is" in error["reason"]
    r = client.post("/v1/jobs", json=job(claims=[{"name": "huge", "expression": "exp(exp(exp(exp(M1 + 3))))"}]))
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "claims[0].expression", r.text
    # log(gamma3): finite at gamma3 = 0.8, not real once gamma3 < 0 along this orbit (it reaches about -0.97)
    body = job(t_final=20.0, claims=[{"name": "leaves", "expression": "log(gamma3)"}])
    view = poll_job(client, client.post("/v1/jobs", json=body).headers["location"])
    assert view["status"] == "succeeded", view["error"]
    (claim,) = view["result"]["claims"]
    assert claim["initial"] is not None and abs(claim["initial"] - math.log(0.8)) < 1e-12
    assert claim["not_finite_points"] > 0 and claim["max_rel_drift"] is None and claim["passed"] is False
