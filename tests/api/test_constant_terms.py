"""A constant in a Lagrangian is a constant (issue 34, item 3): it shifts the energy and nothing else. Before, a
parameter that only a constant term held was in none of the equations, heyoka counted one parameter fewer than it
was given, and every such job failed after its 202 ("Invalid number of parameter values")."""

from __future__ import annotations

import numpy as np

from tests.support import poll_job

FREE = {"kind": "lagrangian", "coordinates": ["x", "y"], "L": "(x_dot**2 + y_dot**2)/2 + k",
        "parameters": {"k": 2.0}}
STATE = {"q": [0.1, 0.2], "q_dot": [0.3, 0.4]}


def _done(client, path: str, body: dict) -> dict:
    r = client.post(path, json=body)
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"], timeout=300.0)
    assert view["status"] == "succeeded", view.get("error") or view
    return view


def test_a_constant_in_l_shifts_the_energy_and_the_job_the_ensemble_and_the_section_run(client):
    result = _done(client, "/v1/jobs", {"system": FREE, "initial_state": STATE, "t_final": 2.0, "samples": 3,
                                        "poincare": {"surface": "x - 0.4", "coordinates": ["y", "y_dot"]}})["result"]
    # free motion: x = 0.1 + 0.3 t, y = 0.2 + 0.4 t; E = |v|^2/2 - k
    np.testing.assert_allclose(result["final_state"]["q"], [0.7, 1.0], rtol=0, atol=1e-14)
    energy = next(i for i in result["integrals"] if i["name"] == "energy")
    assert energy["initial"] == -2.0 + 0.125 and energy["max_rel_drift"] < 1e-14
    assert result["poincare"]["count"] == 1
    np.testing.assert_allclose(result["poincare"]["points"]["q"][0], [0.4, 0.6], rtol=0, atol=1e-12)
    view = _done(client, "/v1/ensembles", {"system": FREE, "t_final": 2.0,
                                           "members": {"initial_states": [STATE, {"q": [0.0, 0.0],
                                                                                  "q_dot": [1.0, 0.0]}]}})
    members = client.get(f"/v1/ensembles/{view['id']}/members").json()["members"]
    np.testing.assert_allclose(members[1]["final_state"]["q"], [2.0, 0.0], rtol=0, atol=1e-14)


def test_a_constant_in_a_generalized_chaplygin_lagrangian(client):
    system = {"kind": "generalized_chaplygin", "coordinates": ["theta", "phi"], "velocities": ["thetadot", "phidot"],
              "lagrangian": "thetadot**2/2 + phidot**2/2 + k", "a1": "0", "a2": "0", "b": "0",
              "parameters": {"k": 1.5}}
    body = {"system": system, "initial_state": {"q": [0.0, 0.0], "q_dot": [1.0, 2.0]}, "t_final": 1.0, "samples": 2}
    result = _done(client, "/v1/jobs", body)["result"]
    np.testing.assert_allclose(result["final_state"]["q"], [1.0, 2.0], rtol=0, atol=1e-14)
