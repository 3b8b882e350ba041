"""Ensembles of systems the request writes itself (``generalized_chaplygin``, ``lagrangian``): refused
before with one misleading "List should have at least 3 items" per member; now each member integrates
in heyoka's batch mode like a catalog kind's, and equals the single job of the same state."""

from __future__ import annotations

import json

import numpy as np

from nonholonomic.systems.generalized_chaplygin import EXAMPLE_JOB as VESELOVA_JOB
from nonholonomic.systems.lagrangian import EXAMPLE_JOB as SLEIGH_JOB
from nonholonomic_client import frames
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
    states = [SLEIGH_JOB["initial_state"],
              {"q": [0.0, 0.0, 1.0], "q_dot": [0.5 * np.cos(1.0), 0.5 * np.sin(1.0), -0.3]}]
    view, members = _ensemble(client, {"system": SLEIGH_JOB["system"], "members": {"initial_states": states},
                                       "t_final": 20.0, "poincare": {"surface": "theta_dot", "coordinates": ["x", "y"],
                                                                     "direction": "both"}})
    assert len(members) == 2 and set(view["summary"]["worst_integral_drift"]) == {"energy", "constraint 1"}
    for member, state in zip(members, states, strict=True):
        single = _single(client, {**SLEIGH_JOB, "initial_state": state})
        for name in ("q", "q_dot"):  # batch mode and a single integration: the same orbit
            np.testing.assert_allclose(member["final_state"][name], single["final_state"][name], rtol=0, atol=1e-9)
        assert all(i["max_rel_drift"] <= 1e-12 for i in member["integrals"])
    page = client.get(f"/v1/ensembles/{view['id']}/members", params={"limit": 2}).json()
    assert page["components"] == {"q": ["x", "y", "theta"], "q_dot": ["x_dot", "y_dot", "theta_dot"]}
    table = frames.members_frame(page["members"], page["components"])  # issue 33: not initial_q1 ...
    assert {"initial_x", "initial_theta", "final_theta_dot"} <= set(table.columns)
    assert table.loc[1, "final_theta_dot"] == members[1]["final_state"]["q_dot"][2]
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


def test_a_sweep_of_a_lagrangian_parameter_claims_only_what_holds_for_every_value(client):
    """The particle's ansatz finds y² + ẏ² at k = 1 (ÿ = −k y: an integral only there); members at k = 0.5 and
    2 share the sweep's definition, which claims the energy, the constraint and the measure √(1 + y²) (proven
    with k symbolic), not that integral; every member's claims hold along its orbit."""
    from nonholonomic.systems.lagrangian_classics import CLASSICS

    job = CLASSICS["nonholonomic_particle"]["job"]
    single = _single(client, job)
    assert "F1" in {i["name"] for i in single["integrals"]}
    view, members = _ensemble(client, {"system": job["system"], "t_final": 10.0, "checks": ["integrals", "measure"],
                                       "members": {"sweep": {
        "parameter": "k", "values": [0.5, 1.0, 2.0], "initial_state": job["initial_state"]}}})
    for member in members:
        assert {i["name"] for i in member["integrals"]} == {"energy", "constraint 1"}
        assert all(i["passed"] for i in member["integrals"]), member["integrals"]
        assert all(c["passed"] for c in member["checks"]), member["checks"]
    assert any("sqrt(y**2 + 1)" in c["formula"] for c in members[0]["checks"])


def test_wrong_widths_and_unsampled_levels_are_named(client):
    body = {"system": SLEIGH_JOB["system"], "t_final": 5.0,
            "members": {"initial_states": [{"q": [0.0, 0.0], "q_dot": [0.0, 0.0, 0.0]}]}}
    r = client.post("/v1/ensembles", json=body)
    assert r.status_code == 422, r.text
    fields = {e["field"]: e["reason"] for e in r.json()["errors"]}
    assert any(f.startswith("members.initial_states[0]") for f in fields) and "at least 3 items" not in r.text
    r = client.post("/v1/ensembles", json={**body, "members": {"sample": {"count": 4, "level": {"energy": 1.0}}}})
    assert r.status_code == 422 and r.json()["errors"][0]["field"].startswith("members.sample"), r.text


def test_sections_keep_each_vectors_own_width_with_rows_and_without(client):
    """A generalized Chaplygin system's q has 2 components: its ensemble's NPZ and NetCDF hold (count, 2)
    arrays equal to the members' JSON (before, the NPZ was reshaped to (−1, 3)); a section without a
    crossing keeps the widths too (no phantom third component). The columns and variables are named by the
    system's own coordinates and velocities (issue 33, item 5)."""
    import io

    import xarray as xr

    section = {"surface": "phi", "value": 0.0, "direction": "both", "coordinates": ["theta", "phi"]}
    view, members = _ensemble(client, {"system": VESELOVA_JOB["system"], "t_final": 30.0, "poincare": section,
                                       "members": {"initial_states": [VESELOVA_JOB["initial_state"]] * 2}})
    assert sum(m["poincare"]["count"] for m in members) >= 2
    raw = client.get(f"/v1/ensembles/{view['id']}/poincare", params={"format": "npz"}).content
    with np.load(io.BytesIO(raw)) as arrays:
        expected = np.concatenate([np.asarray(m["poincare"]["points"]["q"]) for m in members])
        assert arrays["q"].shape == (len(expected), 2) and np.array_equal(arrays["q"], expected)
    stored = xr.open_dataset(client.get(f"/v1/ensembles/{view['id']}/poincare", params={"format": "netcdf"}).content,
                             engine="netcdf4").load()
    own = VESELOVA_JOB["system"]["coordinates"] + VESELOVA_JOB["system"]["velocities"]
    assert set(stored.data_vars) == set(own) and np.array_equal(stored[own[1]].values, expected[:, 1])
    assert stored[own[1]].attrs["vector"] == "q" and stored[own[1]].attrs["component"] == 2
    assert json.loads(str(arrays_components(raw)))["q"] == VESELOVA_JOB["system"]["coordinates"]
    r = client.post("/v1/jobs", json={**SLEIGH_JOB, "poincare": {"surface": "theta", "value": 100.0}})
    job = poll_job(client, r.headers["location"], timeout=120.0)
    assert job["status"] == "succeeded" and job["result"]["poincare"]["count"] == 0
    header = client.get(f"{r.headers['location']}/section", params={"format": "csv"}).text.splitlines()[0]
    assert [c.split(" [")[0] for c in header.split(",")] == ["t", "x", "y", "theta", "x_dot", "y_dot", "theta_dot"]
    with np.load(io.BytesIO(client.get(f"{r.headers['location']}/section", params={"format": "npz"}).content)) as a:
        assert a["q"].shape == (0, 3) and a["q_dot"].shape == (0, 3)
    r = client.post("/v1/jobs", json={**VESELOVA_JOB, "poincare": {"surface": "theta", "value": 100.0}})
    assert poll_job(client, r.headers["location"], timeout=120.0)["status"] == "succeeded"
    empty = xr.open_dataset(client.get(f"{r.headers['location']}/section", params={"format": "netcdf"}).content,
                            engine="netcdf4").load()
    assert set(empty.data_vars) == set(own)


def arrays_components(raw: bytes) -> str:
    """The ``components_json`` of an NPZ download."""
    import io

    with np.load(io.BytesIO(raw)) as arrays:
        return str(arrays["components_json"])
