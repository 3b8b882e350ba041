"""A job's ``periodic_orbit`` through the API: the orbit, its continuation, its page and plot, and the 422s."""

from __future__ import annotations

import numpy as np
import pytest

from tests.api.conftest import BALL, job
from tests.support import poll_job

LINEAR = {**BALL, "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}}
#: On H = 2, (M, gamma) = 0, gamma3 = 0 at (gamma1, M3) = (-0.2, 0): near the centre of an island.
SEED = {"M": [-3.436852983, -0.7015446800, 0.0], "gamma": [-0.2, 0.9797958971, 0.0]}


def _run(client, **block) -> dict:
    body = job(system=LINEAR, initial_state=SEED, t_final=50.0, samples=11, project_initial_state=True,
               periodic_orbit={"surface": "gamma3", "coordinates": ["gamma1", "M3"], **block})
    r = client.post("/v1/jobs", json=body)
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"])
    assert view["status"] == "succeeded", view["error"]
    return view


def test_the_island_centre_with_its_continuation_through_a_period_doubling(client):
    view = _run(client, sweep={"parameter": "potential.a[2]", "values": [0.7, 0.8, 0.9, 1.0]})
    orbit = view["result"]["periodic_orbit"]
    assert orbit["status"] == "found", orbit["reason"]
    assert orbit["period_t"] == pytest.approx(5.1598, abs=1e-4) and orbit["stability"] == "elliptic"
    assert orbit["coordinate_names"] == ["gamma1", "M3"]
    assert orbit["coordinates"] == pytest.approx([-0.15642933, 0.13491925], abs=1e-7)
    assert {c["name"]: c["passed"] for c in orbit["checks"]} == {
        "trivial_multipliers": True, "multiplier_product": True, "crossings": True, "closes_independently": True}
    assert orbit["residual_independent"] < 1e-12 and orbit["trivial_count"] == 4
    mu = np.array([m["re"] + 1j * m["im"] for m in orbit["multipliers"]])
    assert abs(np.prod(mu) - 1) < 1e-9 and orbit["units"]["period_t"] == "s"
    x0 = np.array(orbit["initial_state"]["gamma"])
    assert abs(np.linalg.norm(x0) - 1) < 1e-12 and abs(x0[2]) < 1e-14
    branch = orbit["continuation"]
    assert ([p["status"] for p in branch["points"]] == ["found"] * 4
            and all(p["checks_passed"] for p in branch["points"]))
    assert [(e["kind"], e["between"]) for e in branch["events"]] == [("period_doubling", [0.8, 0.9])]
    page = client.get(f"/v1/jobs/{view['id']}/page")
    assert page.status_code == 200
    for words in ("Periodic orbit", "elliptic", "period doubling", "closes_independently", "Continuation in"):
        assert words in page.text, words
    # its figure (multipliers and the branch side by side) spans the page, not a half-width card (issue 35, item 6)
    assert '<figure class="wide"><a href="/v1/jobs/' in page.text and "plots/periodic_orbit.svg" in page.text
    image = client.get(f"/v1/jobs/{view['id']}/plots/periodic_orbit.png")
    assert image.status_code == 200 and image.content[:4] == b"\x89PNG"
    assert client.get(f"/v1/jobs/{view['id']}/plots/periodic_orbit.svg").text.lstrip().startswith("<?xml")


def test_a_seed_that_does_not_return_gives_not_found_with_its_reason_and_the_job_succeeds(client):
    body = job(system=LINEAR, initial_state=SEED, t_final=8.0, samples=11, project_initial_state=True,
               periodic_orbit={"surface": "gamma3", "period": 3})
    view = poll_job(client, client.post("/v1/jobs", json=body).headers["location"])
    assert view["status"] == "succeeded", view["error"]
    orbit = view["result"]["periodic_orbit"]
    assert orbit["status"] == "not_found" and "raise t_final" in orbit["reason"]
    assert orbit["period_t"] is None and orbit["multipliers"] == []
    page = client.get(f"/v1/jobs/{view['id']}/page")
    assert "not_found" in page.text
    assert client.get(f"/v1/jobs/{view['id']}/plots/periodic_orbit.png").status_code == 200


@pytest.mark.parametrize("block, field, words", [
    ({"surface": "gamma3 + q"}, "periodic_orbit.surface", ["q"]),
    ({"surface": "gamma3", "period": 0}, "periodic_orbit.period", []),
    ({"surface": "gamma3", "direction": "both"}, "periodic_orbit.direction", []),
    ({"surface": "gamma3", "level": ["energy", "bogus"]}, "periodic_orbit.level[1]", ["bogus", "energy"]),
    ({"surface": "gamma3", "coordinates": ["gamma1", "x"]}, "periodic_orbit.coordinates[1]", ["x"]),
    ({"surface": "gamma3", "sweep": {"parameter": "Q", "values": [1.0]}}, "periodic_orbit.sweep.parameter", ["Q"]),
    ({"surface": "gamma3", "sweep": {"parameter": "D", "values": [-1.0]}}, "periodic_orbit.sweep.values[0]", []),
    ({"surface": "gamma3", "sweep": {"parameter": "D", "values": []}}, "periodic_orbit.sweep.values", []),
    ({"surface": "gamma3", "branch": {"in": "Q", "to": 1.0}}, "periodic_orbit.branch.in", ["Q"]),
    ({"surface": "gamma3", "branch": {"in": "D", "to": -1.0}}, "periodic_orbit.branch.to", []),
    ({"surface": "gamma3", "branch": {"in": "D", "to": 0.7}}, "periodic_orbit.branch.to", ["own D"]),
    ({"surface": "gamma3", "branch": {"in": "energy", "to": 1.0, "step": 0.5, "max_step": 0.2}},
     "periodic_orbit.branch.step", ["max_step"]),
    ({"surface": "gamma3", "branch": {"in": "energy", "to": 1.0, "max_points": 1}}, "periodic_orbit.branch.max_points",
     []),
    ({"surface": "gamma3", "branch": {"in": "energy"}}, "periodic_orbit.branch.to", []),
    ({"surface": "gamma3", "branch": {"in": "energy", "to": 1.0, "bogus": 1}}, "periodic_orbit.branch.bogus", []),
])
def test_bad_periodic_orbit_blocks_are_422_naming_the_field(client, block, field, words):
    r = client.post("/v1/jobs", json=job(periodic_orbit=block))
    assert r.status_code == 422, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    hit = [e for e in r.json()["errors"] if e["field"] == field]
    assert hit, r.json()["errors"]
    for word in words:
        assert word in hit[0]["reason"], hit[0]


def test_periodic_orbit_needs_heyoka(client):
    r = client.post("/v1/jobs", json=job(periodic_orbit={"surface": "gamma3"}, integrator={"engine": "scipy"}))
    assert r.status_code == 422 and any(e["field"] == "integrator.engine" and "periodic_orbit" in e["reason"]
                                        for e in r.json()["errors"])
