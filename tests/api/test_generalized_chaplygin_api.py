"""A generalized Chaplygin system of the user's own through the API: the job runs in t and tau with its
Hamiltonian form, its page and plots render, bad fields are 422 problems naming them."""

from __future__ import annotations

import copy
import html

from nonholonomic.systems.generalized_chaplygin import EXAMPLE_JOB
from tests.support import poll_job


def test_the_example_job_runs_with_its_hamiltonian_form_page_and_plots(client):
    catalog = client.get("/v1/systems").json()["generalized_chaplygin"]
    assert catalog["example"] == EXAMPLE_JOB and catalog["state"] == ["q", "q_dot"]
    r = client.post("/v1/jobs", json=catalog["example"])
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"])
    assert view["status"] == "succeeded", view["error"]
    result = view["result"]
    assert result["tau_final"] > 0 and result["time"]["tau"].startswith("reduced time, d tau = N dt")
    checks = {(c["name"], c["method"]): c for c in result["checks"]}
    assert checks[("hamiltonian_flow", "symbolic")]["passed"] is True
    assert checks[("hamiltonian_flow", "pointwise")]["residual"] < 1e-12
    assert checks[("jacobi_identity", "symbolic")]["passed"] is True
    assert checks[("invariant_measure", "symbolic")]["passed"] is True
    assert result["integrals"][0]["name"] == "energy" and result["integrals"][0]["max_rel_drift"] < 1e-12
    page = client.get(f"{r.headers['location']}/page")
    assert page.status_code == 200 and "generalized_chaplygin" in page.text
    # what the user wrote: the coordinates and velocities by name, and every expression (HTML-escaped)
    system = EXAMPLE_JOB["system"]
    assert f"<dt>q</dt><dd><code>{', '.join(system['coordinates'])}</code></dd>" in page.text
    assert f"<dt>q_dot</dt><dd><code>{', '.join(system['velocities'])}</code></dd>" in page.text
    for field in ("L", "a1", "a2", "b"):
        assert f"<dt>{field}</dt><dd><code>{html.escape(system[field])}</code></dd>" in page.text
    for name in ("trajectory", "integrals"):
        plot = client.get(f"{r.headers['location']}/plots/{name}.png")
        assert plot.status_code == 200 and plot.headers["content-type"] == "image/png", plot.text


def _errors(client, body) -> dict[str, str]:
    r = client.post("/v1/jobs", json=body)
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json", r.text
    return {e["field"]: e["reason"] for e in r.json()["errors"]}


def test_bad_fields_are_422s_naming_them(client):
    body = copy.deepcopy(EXAMPLE_JOB)
    body["system"]["L"] = "thetadot**3"
    assert "degree 3" in _errors(client, body)["system.L"]
    body = copy.deepcopy(EXAMPLE_JOB)
    body["system"]["a2"] = "I9*phi"
    assert "unknown name 'I9'" in _errors(client, body)["system.a2"]
    body = copy.deepcopy(EXAMPLE_JOB)
    body["initial_state"] = {"q": [0.0, 0.4], "q_dot": [0.1, 0.2]}  # theta = 0: det G = 0
    assert "singular" in _errors(client, body)["initial_state.q"]
    body = copy.deepcopy(EXAMPLE_JOB)
    body["initial_state"] = {"q": [0.7, 0.4], "q_dot": [0.1, 0.2, 0.3]}
    assert "needs 2 components" in _errors(client, body)["initial_state.q_dot"]


def test_the_former_names_lagrangian_and_qdot_are_read_with_a_note(client):
    """One vocabulary (L, q, q_dot) for every system written by the user; the generalized Chaplygin system's
    former names still work, are stored in the new ones and the answer says so."""
    old = copy.deepcopy(EXAMPLE_JOB)
    old["system"]["lagrangian"] = old["system"].pop("L")
    old["initial_state"]["qdot"] = old["initial_state"].pop("q_dot")
    r = client.post("/v1/jobs", json=old)
    assert r.status_code == 202, r.text
    notes = r.json()["deprecations"]
    assert len(notes) == 2 and "system.lagrangian is deprecated: it is now system.L" in notes[0]
    assert "initial_state.qdot is deprecated: it is now initial_state.q_dot" in notes[1]
    stored = client.get(r.headers["location"], params={"trajectory": "false"}).json()["request"]
    assert stored["system"]["L"] == EXAMPLE_JOB["system"]["L"] and "lagrangian" not in stored["system"]
    assert stored["initial_state"] == EXAMPLE_JOB["initial_state"]
    new = client.post("/v1/jobs", json=EXAMPLE_JOB)
    assert new.status_code == 202 and new.json()["deprecations"] == []
    both = copy.deepcopy(EXAMPLE_JOB)
    both["system"]["lagrangian"] = both["system"]["L"]
    r = client.post("/v1/jobs", json=both)
    assert r.status_code == 422 and "send L only" in r.text, r.text
    hamiltonize = {k: EXAMPLE_JOB["system"][k] for k in ("coordinates", "velocities", "a1", "a2", "b")}
    answer = client.post("/v1/hamiltonize", json={**hamiltonize, "lagrangian": EXAMPLE_JOB["system"]["L"],
                                                   "parameters": EXAMPLE_JOB["system"]["parameters"]})
    assert answer.status_code == 200, answer.text
    assert any("lagrangian is deprecated: it is now L" in n for n in answer.json()["deprecations"])
