"""The ball on a surface of the user's own through the API: the catalog's example runs with its
evidence, page and plot; an x off the surface is a 422 or is projected on request; a bad Φ and clashing
names are 422 problems naming the field; an ensemble of given members runs and a level is refused."""

from __future__ import annotations

import copy

from nonholonomic.systems import ball_on_surface as bs
from tests.support import poll_job

SPHERE = {"Phi": "x1**2 + x2**2 + x3**2 - rho**2", "parameters": {"rho": 2.0}}


def _body(**changes):
    body = copy.deepcopy(bs.EXAMPLE) | {"t_final": 20.0, "samples": 41}
    body["system"].update(changes)
    return body


def test_the_catalog_example_runs_with_its_evidence_page_and_plot(client):
    catalog = {s["kind"]: s for s in client.get("/v1/systems").json()["systems"]}
    entry = catalog["ball_on_surface"]
    assert entry["surface_expression"]["variables"] == ["x1", "x2", "x3"]
    assert "D0" in entry["surface_expression"]["reserved_names"]
    assert catalog["ball_on_quadric"]["surface_expression"] is None
    r = client.post("/v1/jobs", json=_body())
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"])
    assert view["status"] == "succeeded", view["error"]
    result = view["result"]
    integrals = {i["name"]: i for i in result["integrals"]}
    assert set(integrals) == {"surface", "energy"}
    assert integrals["surface"]["formula"] == f"Phi(x) = {bs.TORUS} = 0"
    assert integrals["energy"]["max_rel_drift"] < 1e-12 and integrals["surface"]["passed"]
    measure = {c["method"]: c for c in result["checks"] if c["name"] == "invariant_measure"}
    assert measure["symbolic"]["passed"] is True and measure["pointwise"]["residual"] < 1e-12
    assert result["system"]["parameters"]["a0"] == 2.0
    page = client.get(f"{r.headers['location']}/page")
    assert page.status_code == 200 and "Phi(x) =" in page.text
    plot = client.get(f"{r.headers['location']}/plots/trajectory.png")
    assert plot.status_code == 200 and plot.headers["content-type"] == "image/png"


def _problems(client, body):
    r = client.post("/v1/jobs", json=body)
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json", r.text
    return {e["field"]: e["reason"] for e in r.json()["errors"]}


def test_an_x_off_the_surface_is_a_422_or_is_projected(client):
    body = _body(surface=SPHERE)
    body["initial_state"] = {"x": [1.0, 1.0, 1.5], "omega": [0.5, 2.0, 0.3]}  # |x| = 2.06, not 2
    errors = _problems(client, body)
    assert "x1**2 + x2**2 + x3**2 - rho**2" in errors["initial_state.x"]
    assert "project_initial_state" in errors["initial_state.x"]
    r = client.post("/v1/jobs", json=body | {"project_initial_state": True})
    assert r.status_code == 202, r.text
    result = poll_job(client, r.headers["location"])["result"]
    x0 = result["initial_state"]["x"]
    assert abs(sum(c * c for c in x0) - 4.0) < 1e-12
    assert result["projections"][0]["field"] == "initial_state.x"


def test_a_bad_surface_and_clashing_names_are_422s_naming_the_field(client):
    errors = _problems(client, _body(surface={"Phi": "x1^2 + x2**2 - 1"}))
    assert "use ** for powers" in errors["system.surface.Phi"]
    errors = _problems(client, _body(surface={"Phi": "x1**2 + x2**2 - m", "parameters": {"m": 1.0}}))
    assert "m: already a name of ball_on_surface" in errors["system.surface.parameters"]
    errors = _problems(client, _body(surface={"Phi": "q", "parameters": {"q": 1.0}}))
    assert "does not depend on x1, x2, x3" in errors["system.surface.Phi"]
    body = _body(potential={"kind": "expression", "U": "a0*x3", "parameters": {"a0": 1.0}})
    assert "a parameter of the surface too" in _problems(client, body)["system.potential"]
    body = _body()
    del body["system"]["surface"]
    assert "system.surface" in _problems(client, body)


def test_an_ensemble_of_given_members_runs_and_a_level_is_refused(client):
    system = _body(surface=SPHERE)["system"]
    members = [{"x": [0.0, 0.0, 2.0], "omega": [1.0, 0.0, w]} for w in (0.0, 0.5, 1.0)]
    r = client.post("/v1/ensembles", json={"system": system, "t_final": 5.0, "members": {"initial_states": members}})
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"])
    assert view["status"] == "succeeded" and view["members_done"] == 3
    r = client.post("/v1/ensembles", json={"system": system, "t_final": 5.0,
                                           "members": {"sample": {"count": 2, "level": {"energy": 1.0}}}})
    assert r.status_code == 422, r.text
    assert "initial states" in r.text
