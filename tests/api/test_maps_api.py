"""GET /v1/maps, POST /v1/maps/{name} and the job check ``isomorphisms``, through the API."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from nonholonomic.isomorphisms import MAPS
from nonholonomic.systems import SYSTEMS
from tests.support import poll_job

BALL = {"kind": "chaplygin_ball", "inertia": [1.0, 2.0, 3.5], "D": 0.7, "potential": {"kind": "zero"}}
VESELOVA = {"kind": "veselova", "inertia": [1.0, 2.0, 3.5]}


def test_the_map_list_names_source_target_time_and_corrections(client):
    maps = {m["name"]: m for m in client.get("/v1/maps").json()["maps"]}
    assert set(maps) == {"veselova_to_e3", "veselova_to_neumann", "e3_to_clebsch", "chaplygin_ball_to_clebsch",
                         "rubber_ball_to_veselova"}
    ball = maps["chaplygin_ball_to_clebsch"]
    assert ball["source"]["kind"] == "chaplygin_ball" and ball["target"]["kind"] == "clebsch"
    assert "rho_mu" in ball["time"] and any("ERRATA 8" in c for c in ball["corrections"])
    assert "(M, gamma) = 0 (zero constant of areas)" in ball["level_set"]


def test_ball_states_map_to_clebsch_with_the_target_constants(client):
    states = [{"M": [0.5, -0.2, 0.15], "gamma": [0.0, 0.6, 0.8]}, {"M": [0.0, 0.8, -0.6], "gamma": [1.0, 0.0, 0.0]}]
    r = client.post("/v1/maps/chaplygin_ball_to_clebsch", json={"system": BALL, "states": states})
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["push_forward_residual"]["passed"] is True and out["push_forward_residual"]["value"] < 1e-13
    I, D = np.array(BALL["inertia"]), BALL["D"]
    J, B = I + D, I / (I + D)
    for state, entry in zip(states, out["states"]):
        g, M = np.array(state["gamma"]), np.array(state["M"])
        s = np.array(entry["state"]["s"])
        expected = np.sqrt(B) * g / np.sqrt(g @ (B * g))  # ERRATA 8: B^(+1/2)
        assert np.max(np.abs(s - expected)) < 1e-14
        target = entry["target_parameters"]
        assert target["inertia"] == pytest.approx(list(B), rel=1e-14)
        assert target["alpha"] == pytest.approx(np.prod(J) / D, rel=1e-14) and target["beta"] == -target["alpha"]
        assert target["k"] == pytest.approx(np.sqrt(np.prod(B)), rel=1e-14)
        rho = np.linalg.det(np.diag(J) - D * np.outer(g, g)) ** -0.5
        L = rho * M
        assert target["c"] == pytest.approx((L @ L) * (g @ (B * g)) / np.prod(B), rel=1e-13)
        assert entry["time_density"] == pytest.approx(rho, rel=1e-14)
    job = out["target_job_system"]
    assert job["kind"] == "clebsch" and job["potential"] == {"kind": "zero"}


def test_a_state_off_the_level_set_is_422_with_the_condition_and_its_value(client):
    r = client.post("/v1/maps/chaplygin_ball_to_clebsch",
                    json={"system": BALL, "states": [{"M": [0.5, -0.2, 0.15], "gamma": [0, 0.6, 0.8]},
                                                     {"M": [0.5, -0.2, 0.1], "gamma": [0, 0.6, 0.8]}]})
    assert r.status_code == 422
    (error,) = r.json()["errors"]
    assert error["field"] == "states[1].M" and "(M, gamma) = 0" in error["reason"] and "-0.04" in error["reason"]
    r = client.post("/v1/maps/chaplygin_ball_to_clebsch", json={
        "system": BALL, "project": True, "states": [{"M": [0.5, -0.2, 0.1], "gamma": [0, 0.6, 0.8]}]})
    assert r.status_code == 200 and r.json()["states"][0]["projections"][0]["field"] == "states[0]"


@pytest.mark.parametrize("name,body,field", [
    ("veselova_to_neumann", {"system": {**VESELOVA, "potential": {"kind": "linear", "a": [1, 0, 0]}}},
     "system.potential.kind"),
    ("e3_to_clebsch", {"system": VESELOVA}, "system.kind"),
    ("veselova_to_e3", {"system": VESELOVA, "states": [{"omega": [1, 0, 0]}]}, "states[0].gamma"),
    ("veselova_to_e3", {"system": VESELOVA, "states": [{"omega": [1, 0, 0], "gamma": [0, 1, 1e300]}]},
     "states[0].gamma[2]"),
    ("veselova_to_e3", {"system": VESELOVA, "states": []}, "states"),
    ("chaplygin_ball_to_clebsch", {"system": BALL, "inverse": True}, "inverse"),
])
def test_bad_map_requests_are_422_naming_the_field(client, name, body, field):
    body = {"states": [{"omega": [0.5, -0.2, 0.15], "gamma": [0.0, 0.6, 0.8]}]} | body
    if name == "chaplygin_ball_to_clebsch":
        body["states"] = [{"M": [0.5, -0.2, 0.15], "gamma": [0.0, 0.6, 0.8]}]
    r = client.post(f"/v1/maps/{name}", json=body)
    assert r.status_code == 422, r.text
    assert field in {e["field"] for e in r.json()["errors"]}, r.json()


def test_unknown_map_is_404(client):
    r = client.post("/v1/maps/kovalevskaya",
                    json={"system": VESELOVA, "states": [{"omega": [0, 0, 0], "gamma": [0, 0, 1]}]})
    assert r.status_code == 404 and r.headers["content-type"] == "application/problem+json"


def test_veselova_to_e3_and_back(client):
    state = {"omega": [0.5, -0.2, 0.15], "gamma": [0.0, 0.6, 0.8]}
    out = client.post("/v1/maps/veselova_to_e3", json={"system": VESELOVA, "states": [state]}).json()
    image = out["states"][0]["state"]
    I = np.array(VESELOVA["inertia"])
    g, w = np.array(state["gamma"]), np.array(state["omega"])
    rho = np.sqrt(g @ (g / I))
    assert np.max(np.abs(np.array(image["M"]) - rho * np.sqrt(I) * w)) < 1e-14
    assert np.max(np.abs(np.array(image["Gamma"]) - g / (rho * np.sqrt(I)))) < 1e-14
    back = client.post("/v1/maps/veselova_to_e3", json={"system": VESELOVA, "states": [image], "inverse": True}).json()
    assert np.max(np.abs(np.array(back["states"][0]["state"]["omega"]) - w)) < 1e-14
    bad = dict(image, M=[m + 0.3 * G for m, G in zip(image["M"], image["Gamma"])])  # (M, Gamma) != 0
    r = client.post("/v1/maps/veselova_to_e3", json={"system": VESELOVA, "states": [bad], "inverse": True})
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "states[0].omega"


@pytest.mark.parametrize("kind", sorted({entry.source for entry in MAPS.values()}))
def test_isomorphisms_job_check_on_the_catalog_examples(client, kind):
    # the kinds are the maps' sources (read at collection without deriving a system); the catalog offers the check
    assert "isomorphisms" in client.get(f"/v1/systems/{kind}").json()["checks"]
    body = copy.deepcopy(SYSTEMS[kind].EXAMPLE) | {"samples": 51, "t_final": 50.0, "checks": ["isomorphisms"]}
    if kind == "chaplygin_ball":  # Theorem 3 needs (M, gamma) = 0; the example has -0.04
        body["initial_state"]["M"] = [0.5, -0.2, 0.15]
    view = poll_job(client, client.post("/v1/jobs", json=body).headers["location"], timeout=120)
    assert view["status"] == "succeeded", view["error"]
    items = [c for c in view["result"]["checks"] if c["name"].startswith("isomorphism:")]
    assert items and all(c["passed"] is True for c in items), items
    assert {c["method"] for c in items} >= {"pointwise", "trajectory"}
