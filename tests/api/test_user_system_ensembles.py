"""Ensembles of systems the request writes itself (``generalized_chaplygin``, ``lagrangian``): refused
before with one misleading "List should have at least 3 items" per member; now each member integrates
in heyoka's batch mode like a catalog kind's, and equals the single job of the same state."""

from __future__ import annotations

import numpy as np

from nonholonomic.systems.generalized_chaplygin import EXAMPLE_JOB as VESELOVA_JOB
from nonholonomic.systems.lagrangian import EXAMPLE_JOB as SLEIGH_JOB
from tests.support import poll_job


def _ensemble(client, body) -> tuple[dict, list[dict]]:
    r = client.post("/v1/ensembles", json=body)
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"], timeout=120.0)
    assert view["status"] == "succeeded" and view["summary"]["failed"] == 0, view
    members = client.get(f"{r.headers['location']}/members", params={"limit": 100}).json()["members"]
    return view, members


def _single(client, body) -> dict:
    r = client.post("/v1/jobs", json=body)
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"], timeout=120.0)
    assert view["status"] == "succeeded", view["error"]
    return view["result"]


def test_an_ensemble_of_a_lagrangian_system_equals_its_single_jobs(client):
    states = [SLEIGH_JOB["initial_state"], {"q": [0.0, 0.0, 1.0], "q_dot": [0.5 * np.cos(1.0), 0.5 * np.sin(1.0), -0.3]}]
    view, members = _ensemble(client, {"system": SLEIGH_JOB["system"], "members": {"initial_states": states},
                                       "t_final": 20.0, "poincare": {"surface": "theta_dot", "coordinates": ["x", "y"],
                                                                     "direction": "both"}})
    assert len(members) == 2 and set(view["summary"]["worst_integral_drift"]) == {"energy", "constraint 1"}
    for member, state in zip(members, states, strict=True):
        single = _single(client, {**SLEIGH_JOB, "initial_state": state})
        for name in ("q", "q_dot"):  # batch mode and a single integration: the same orbit
            np.testing.assert_allclose(member["final_state"][name], single["final_state"][name], rtol=0, atol=1e-9)
        assert all(i["max_rel_drift"] <= 1e-12 for i in member["integrals"])
    assert client.get(f"/v1/ensembles/{view['id']}/poincare", params={"format": "csv"}).status_code == 200
    assert client.get(f"/v1/ensembles/{view['id']}/plots/poincare.png").status_code == 200


def test_a_sweep_of_a_generalized_chaplygin_parameter(client):
    system = VESELOVA_JOB["system"]
    view, members = _ensemble(client, {"system": system, "t_final": 10.0, "members": {"sweep": {
        "parameter": "I2", "values": [1.5, 2.0, 2.5], "initial_state": VESELOVA_JOB["initial_state"]}}})
    assert [m["label"]["value"] for m in members] == [1.5, 2.0, 2.5]
    middle = _single(client, {**VESELOVA_JOB, "t_final": 10.0})  # I2 = 2.0 is the example's own value
    np.testing.assert_allclose(members[1]["final_state"]["q"], middle["final_state"]["q"], rtol=0, atol=1e-9)
    assert members[0]["final_state"]["q"] != members[2]["final_state"]["q"]


def test_wrong_widths_and_unsampled_levels_are_named(client):
    body = {"system": SLEIGH_JOB["system"], "t_final": 5.0,
            "members": {"initial_states": [{"q": [0.0, 0.0], "q_dot": [0.0, 0.0, 0.0]}]}}
    r = client.post("/v1/ensembles", json=body)
    assert r.status_code == 422, r.text
    fields = {e["field"]: e["reason"] for e in r.json()["errors"]}
    assert any(f.startswith("members.initial_states[0]") for f in fields) and "at least 3 items" not in r.text
    r = client.post("/v1/ensembles", json={**body, "members": {"sample": {"count": 4, "level": {"energy": 1.0}}}})
    assert r.status_code == 422 and r.json()["errors"][0]["field"].startswith("members.sample"), r.text
