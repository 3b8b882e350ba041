"""Veselova through the API: constraint violations (422) and projection on request."""

from __future__ import annotations

import numpy as np

from tests.support import poll_job

VESELOVA = {"kind": "veselova", "inertia": [2.0, 3.0, 4.5],
            "potential": {"kind": "quadratic", "K": [[1.0, 0.2, 0.0], [0.2, 2.0, 0.1], [0.0, 0.1, -1.0]]}}
OFF = {"omega": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}  # (ω, γ) = −0.04


def test_off_constraint_state_is_422_naming_the_constraint(client):
    r = client.post("/v1/jobs", json={"system": VESELOVA, "initial_state": OFF, "t_final": 5.0})
    assert r.status_code == 422
    (error,) = r.json()["errors"]
    assert error["field"] == "initial_state.omega" and "(omega, gamma) = 0" in error["reason"]
    assert "project_initial_state" in error["reason"]


def test_projection_on_request_is_reported_and_the_job_runs(client):
    r = client.post("/v1/jobs", json={"system": VESELOVA, "initial_state": OFF, "t_final": 50.0,
                                      "project_initial_state": True})
    view = poll_job(client, r.headers["location"])
    assert view["status"] == "succeeded", view["error"]
    result = view["result"]
    (projection,) = result["projections"]
    assert projection["field"] == "initial_state.omega"
    assert abs(projection["value_before"] - np.dot(OFF["omega"], OFF["gamma"])) <= 1e-16
    assert abs(projection["value_after"]) <= 1e-16 and projection["change"] > 0.01
    w, g = np.array(result["initial_state"]["omega"]), np.array(result["initial_state"]["gamma"])
    assert abs(np.dot(w, g)) <= 1e-16
    integrals = {i["name"]: i for i in result["integrals"]}
    assert set(integrals) == {"energy", "geometric", "constraint"}
    assert all(i["passed"] and i["max_rel_drift"] <= 1e-13 for i in integrals.values())
    assert result["tau_final"] > 0 and "rho_omega" in result["time"]["tau"]
    assert result["system"]["potential_formula"] == "U = 1/2 (gamma, K gamma)"


def test_quadratic_potential_matrix_must_be_symmetric(client):
    bad = {**VESELOVA, "potential": {"kind": "quadratic", "K": [[1, 2, 0], [0, 1, 0], [0, 0, 1]]}}
    r = client.post("/v1/jobs", json={"system": bad, "initial_state": OFF, "t_final": 1.0})
    assert r.status_code == 422
    assert r.json()["errors"][0]["field"] == "system.potential.K" and "not symmetric" in r.json()["errors"][0]["reason"]


def test_catalog_lists_veselova_with_its_notes_and_constraints(client):
    entry = client.get("/v1/systems/veselova").json()
    assert [c["field"] for c in entry["constraints"]] == ["gamma", "omega"]
    assert {p["kind"] for p in entry["potentials"]} == {"zero", "linear", "brun", "quadratic"}
    assert entry["reduced_time"]["equation"] == "2504-10-2" and "ERRATA 1" in entry["notes"][0]
    assert {i["name"]: i["claimed_for_potentials"] for i in entry["integrals"]}["F"] == ["zero"]
