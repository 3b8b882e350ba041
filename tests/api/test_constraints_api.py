"""Constraints and matrix parameters of the other systems, through the API."""

from __future__ import annotations

import copy

import pytest

from nonholonomic.systems import SYSTEMS
from tests.support import poll_job


def example(kind: str) -> dict:
    return copy.deepcopy(SYSTEMS[kind].EXAMPLE) | {"samples": 5, "t_final": 10.0}


@pytest.mark.parametrize("B,reason", [([[1, 0, 0], [0, -2, 0], [0, 0, 3]], "not positive definite"),
                                      ([[1, 0.5, 0], [0, 2, 0], [0, 0, 3]], "not symmetric"),
                                      ([1.0, 2.0], "")])
def test_quadric_matrix_is_validated(client, B, reason):
    body = example("ball_on_quadric")
    body["system"]["B"] = B
    r = client.post("/v1/jobs", json=body)
    assert r.status_code == 422
    assert any(e["field"].startswith("system.B") and reason in e["reason"] for e in r.json()["errors"]), r.json()


def test_centre_off_the_quadric_is_refused_then_projected(client):
    body = example("ball_on_quadric")
    body["initial_state"]["x"] = [0.5, 0.72, 1.32]
    r = client.post("/v1/jobs", json=body)
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "initial_state.x"
    view = poll_job(client, client.post("/v1/jobs", json=body | {"project_initial_state": True}).headers["location"])
    assert view["status"] == "succeeded", view["error"]
    (projection,) = view["result"]["projections"]
    assert projection["field"] == "initial_state.x" and abs(projection["value_after"]) <= 1e-14
    assert all(i["passed"] for i in view["result"]["integrals"])


def test_space_fixed_axis_must_be_a_unit_vector(client):
    body = example("chaplygin_ball_veselova")
    body["initial_state"]["E"] = [2 * e for e in body["initial_state"]["E"]]
    r = client.post("/v1/jobs", json=body)
    assert r.status_code == 422
    assert "initial_state.E" in {e["field"] for e in r.json()["errors"]}


def test_catalog_marks_the_quadric_parameter_as_B_inverse_in_the_equations(client):
    entry = client.get("/v1/systems/ball_on_quadric").json()
    B = next(p for p in entry["parameters"] if p["name"] == "B")
    assert B["shape"] == "symmetric_matrix" and "positive definite" in B["admissible"]
    assert "B^-1" in B["components_are"]
    assert next(p for p in entry["potentials"] if p["kind"] == "linear")["parameters"][0]["unit"] == "kg m/s^2"
    assert entry["reduced_time"] is None


def test_a_structural_check_the_kind_lacks_is_422(client):
    r = client.post("/v1/jobs", json=example("neumann") | {"checks": ["integrals", "bracket"]})
    assert r.status_code == 422
    (error,) = r.json()["errors"]
    assert error["field"] == "checks[1]" and "not available for neumann" in error["reason"]
