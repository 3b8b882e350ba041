"""Jobs over the API (embedded mode): results, every 422, 404, cancellation."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from nonholonomic import get_system, simulate
from tests.api.conftest import BALL, STATE, job
from tests.support import poll_job


def submit(client, body) -> str:
    r = client.post("/v1/jobs", json=body)
    assert r.status_code == 202, r.text
    assert r.headers["location"] == f"/v1/jobs/{r.json()['id']}"
    assert r.json()["status"] == "queued"
    return r.headers["location"]


def test_job_succeeds_with_the_core_numbers_and_the_design_fields(client):
    view = poll_job(client, submit(client, job(
        system={**BALL, "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}})))
    assert view["status"] == "succeeded" and view["progress"] == 1.0 and view["error"] is None
    result = view["result"]
    direct = simulate(get_system("chaplygin_ball", "linear"), {**{k: v for k, v in BALL.items() if k != "kind"},
                                                               "a": [0.3, -0.2, 0.5]}, STATE, 20.0, 51)
    assert np.array_equal(result["final_state"]["M"], direct.state("M")[-1])
    assert set(result["final_state"]) == {"M", "gamma", "omega"}
    assert set(result["trajectory"]) == {"t", "tau", "M", "gamma", "omega"}
    assert len(result["trajectory"]["t"]) == 51 and result["t_final"] == 20.0
    assert result["tau_final"] == pytest.approx(direct.trajectory.tau[-1], abs=0)
    assert {i["name"] for i in result["integrals"]} == {"energy", "geometric", "area"}
    assert all(i["passed"] and i["max_rel_drift"] <= 1e-13 for i in result["integrals"])
    energy = next(i for i in result["integrals"] if i["name"] == "energy")
    assert energy["equation"] == "2604-2" and energy["formula"].startswith("H = (M, omega)/2")
    assert {(c["name"], c["method"], c["passed"]) for c in result["checks"]} == {
        ("invariant_measure", "symbolic", True), ("invariant_measure", "pointwise", True)}
    assert result["integration"]["engine"] == "heyoka"
    assert result["integration"]["tolerance"] == np.finfo(float).eps
    assert result["integration"]["steps"] > 0 and result["warnings"] == []
    assert view["request"]["system"]["potential"] == {"kind": "linear", "a": [0.3, -0.2, 0.5]}


def test_the_summary_view_leaves_the_samples_out_and_says_where_they_are(client):
    location = submit(client, job(samples=2001))
    whole = poll_job(client, location)
    summary = client.get(location, params={"trajectory": "false"})
    assert summary.status_code == 200
    view = summary.json()
    assert "trajectory" not in view["result"] and view["result"]["trajectory_location"] == location + "/trajectory"
    # everything else as in the whole view, number for number
    assert {k: v for k, v in view["result"].items() if k != "trajectory_location"} == {
        k: v for k, v in whole["result"].items() if k != "trajectory"}
    assert len(summary.content) * 10 < len(client.get(location).content)  # 2001 samples stay behind
    samples = client.get(view["result"]["trajectory_location"]).json()
    assert samples["t"] == whole["result"]["trajectory"]["t"] and samples["M"] == whole["result"]["trajectory"]["M"]
    assert client.get(location, params={"trajectory": "maybe"}).status_code == 422


def test_omega_may_replace_M_and_checks_may_be_chosen(client):
    view = poll_job(client, submit(client, job(initial_state={"omega": [0.3, -0.1, 0.2], "gamma": [0, 0.6, 0.8]},
                                               checks=["integrals"])))
    assert view["status"] == "succeeded"
    assert view["result"]["checks"] == [] and len(view["result"]["integrals"]) == 4
    assert np.allclose(view["result"]["trajectory"]["omega"][0], [0.3, -0.1, 0.2], atol=1e-14)


def test_scipy_engine_is_available_as_a_cross_check(client):
    view = poll_job(client, submit(client, job(integrator={"engine": "scipy", "tolerance": 1e-12})))
    heyoka = poll_job(client, submit(client, job()))
    assert view["result"]["integration"]["engine"] == "scipy"
    assert np.allclose(view["result"]["final_state"]["M"], heyoka["result"]["final_state"]["M"], atol=1e-9)


def test_triangle_inequality_violation_runs_with_a_warning(client):
    view = poll_job(client, submit(client, job(system={**BALL, "inertia": [1.0, 2.0, 3.5]})))
    assert view["status"] == "succeeded"
    assert any("triangle inequality" in w and "I1 + I2 >= I3" in w for w in view["result"]["warnings"])


NAN_M = '{"system": {"kind": "chaplygin_ball", "inertia": [2, 3, 4.5], "D": 0.7}, ' \
        '"initial_state": {"M": [NaN, 0, 0], "gamma": [0, 0.6, 0.8]}, "t_final": 1}'
INF_T = '{"system": {"kind": "chaplygin_ball", "inertia": [2, 3, 4.5], "D": 0.7}, ' \
        '"initial_state": {"M": [0, 0, 0], "gamma": [0, 0.6, 0.8]}, "t_final": Infinity}'
INF_D = '{"system": {"kind": "chaplygin_ball", "inertia": [2, 3, 4.5], "D": -Infinity}, ' \
        '"initial_state": {"M": [0, 0, 0], "gamma": [0, 0.6, 0.8]}, "t_final": 1}'

INVALID = [
    ("zero moment", job(system={**BALL, "inertia": [0.0, 3.0, 4.5]}), "system.inertia[0]", "greater than 0"),
    ("negative moment", job(system={**BALL, "inertia": [2.0, -3.0, 4.5]}), "system.inertia[1]", "greater than 0"),
    ("D < 0", job(system={**BALL, "D": -0.1}), "system.D", "greater than or equal to 0"),
    ("|gamma| != 1", job(initial_state={**STATE, "gamma": [0.0, 0.6, 0.8 + 1e-8]}), "initial_state.gamma",
     "|gamma| = 1"),
    ("NaN", NAN_M, "initial_state.M[0]", "finite"),
    ("infinite t_final", INF_T, "t_final", "finite"),
    ("infinite D", INF_D, "system.D", "finite"),
    ("t_final = 0", job(t_final=0.0), "t_final", "greater than 0"),
    ("t_final < 0", job(t_final=-1.0), "t_final", "greater than 0"),
    ("t_final too large", job(t_final=2e9), "t_final", "maximum"),
    ("too many samples", job(samples=5002), "samples", "maximum"),
    ("one sample", job(samples=1), "samples", "greater than or equal to 2"),
    ("unknown kind", job(system={**BALL, "kind": "chaplygin_sled"}), "system.kind", "does not match"),
    ("unknown potential", job(system={**BALL, "potential": {"kind": "coulomb"}}), "system.potential.kind",
     "does not match"),
    ("potential parameter missing", job(system={**BALL, "potential": {"kind": "linear"}}), "system.potential.a",
     "required"),
    ("short vector", job(initial_state={**STATE, "M": [1.0, 2.0]}), "initial_state.M", "needs 3 components, got 2"),
    ("missing gamma", job(initial_state={"M": [0.5, -0.2, 0.1]}), "initial_state.gamma", "missing"),
    ("unknown state", job(initial_state={**STATE, "x": [0, 0, 1]}), "initial_state.x", "not a state variable"),
    ("M and omega", job(initial_state={**STATE, "omega": [0, 0, 1]}), "initial_state.omega", "only one"),
    ("unknown field", {**job(), "tfinal": 3}, "tfinal", "Extra inputs"),
    ("unknown check", job(checks=["lyapunov"]), "checks[0]", "Input should be"),
    ("scipy too tight", job(integrator={"engine": "scipy", "tolerance": 1e-15}), "integrator.tolerance",
     "cannot honour"),
    ("unknown engine", job(integrator={"engine": "rk4"}), "integrator.engine", "Input should be"),
    ("not JSON", "{not json", "body", "not valid JSON"),
]


@pytest.mark.parametrize("body,field,reason", [case[1:] for case in INVALID], ids=[case[0] for case in INVALID])
def test_invalid_requests_get_422_naming_the_field_and_nothing_is_queued(client, monkeypatch, body, field, reason):
    queued = []
    monkeypatch.setattr(client.app.state.backend, "submit", lambda request: queued.append(request))
    if isinstance(body, str):
        r = client.post("/v1/jobs", content=body, headers={"content-type": "application/json"})
    else:
        r = client.post("/v1/jobs", json=body)
    assert r.status_code == 422, r.text
    assert r.headers["content-type"] == "application/problem+json"
    problem = r.json()
    assert (problem["status"] == 422 and problem["type"] == "/problems/invalid-request"
            and problem["instance"] == "/v1/jobs")
    matching = [e for e in problem["errors"] if e["field"] == field]
    assert matching, problem["errors"]
    assert reason in matching[0]["reason"] and field in problem["detail"]
    assert queued == []


def test_unknown_job_is_404_problem(client):
    for method in ("get", "delete"):
        r = getattr(client, method)("/v1/jobs/00000000-0000-0000-0000-000000000000")
        assert r.status_code == 404 and r.headers["content-type"] == "application/problem+json"
        assert r.json()["title"] == "Unknown job"


def test_cancelling_a_finished_job_is_409(client):
    location = submit(client, job(samples=2))
    assert poll_job(client, location)["status"] == "succeeded"
    r = client.delete(location)
    assert r.status_code == 409 and r.json()["status"] == 409


#: Hang guard (seconds) of each wait below: far above what a quiet machine needs (well under a second,
#: the first job's compile a few seconds), never a result.
GUARD_S = 120.0


def _until(predicate, what: str):
    """Poll ``predicate()`` until it returns something true (returned); fail past the hang guard."""
    deadline = time.monotonic() + GUARD_S
    while not (value := predicate()):
        if time.monotonic() > deadline:
            pytest.fail(f"hang guard: {what} not seen within {GUARD_S:g} s")
        time.sleep(0.01)
    return value


def test_progress_moves_and_delete_stops_a_running_job(client):
    location = submit(client, job(t_final=1e8, samples=2))
    view = _until(lambda: (v := client.get(location).json())["progress"] > 0 and v, "progress")
    first = view["progress"]
    second = _until(lambda: (p := client.get(location).json()["progress"]) != first and p, "progress moving")
    assert view["status"] == "running" and 0 < first < second < 1
    r = client.delete(location)
    assert r.status_code == 202 and r.json()["status"] == "cancelled"
    # The single job thread is free again once the cancelled job let go of it: a short job submitted now
    # runs after it. Meanwhile the cancelled job's progress is written at most once more (the report that
    # sees the cancellation), then its thread leaves.
    short = submit(client, job(samples=2))
    seen: list[float] = []

    def short_ended():
        seen.append(client.get(location).json()["progress"])
        assert len(set(seen) - {r.json()["progress"]}) <= 2, seen  # its next report, and once its thread left
        return (v := client.get(short).json())["status"] in ("succeeded", "failed", "cancelled") and v

    assert _until(short_ended, "the short job behind the cancelled one")["status"] == "succeeded"
    stopped = client.get(location).json()["progress"]
    assert client.get(location).json()["progress"] == stopped  # it no longer advances
    assert client.get(location).json()["status"] == "cancelled"
    assert not math.isnan(stopped)


def test_a_job_that_raises_is_reported_failed_with_its_reason(client, monkeypatch):
    import service.backends.embedded as embedded

    def explode(request, progress=None):
        raise RuntimeError("heyoka stopped at t = 3 with outcome err_nf_state")

    monkeypatch.setattr(embedded, "run_job", explode)
    view = poll_job(client, submit(client, job()))
    assert view["status"] == "failed" and view["result"] is None
    assert view["error"] == {"type": "RuntimeError", "message": "heyoka stopped at t = 3 with outcome err_nf_state"}
