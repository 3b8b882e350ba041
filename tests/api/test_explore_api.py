"""The section explorer's API (``/v1/explore``) in embedded mode: the plane, a click's orbit streamed in pieces
(equal to one uninterrupted section of the core), the periodic orbit of a shift-click, the refusals, and the
catalog's links to the page."""

from __future__ import annotations

import time

import numpy as np
import pytest

from nonholonomic.analysis.poincare import section
from nonholonomic.numerics.kernels import parameter_vector, state_vector
from nonholonomic.systems import get_system
from service.security import EXPLORE_POLICY

SYSTEM = {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7,
          "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}}
SECTION = {"surface": "gamma3", "coordinates": ["gamma1", "M3"], "level": {"energy": 2.0, "area": 0.0}}


def _poll(client, location: str, timeout: float = 300.0) -> tuple[list[list[float]], dict]:
    points: list[list[float]] = []
    end = time.monotonic() + timeout  # a hang guard (a quiet machine needs seconds: the first compiles)
    while time.monotonic() < end:
        view = client.get(f"{location}?since={len(points)}").json()
        assert view["since"] == len(points)
        points += view["points"]
        if view["done"]:
            return points, view
        time.sleep(0.05)
    raise AssertionError(f"hang guard: the exploration did not finish within {timeout:g} s ({len(points)} points)")


def test_defaults_and_plane_of_the_ball(client):
    d = client.get("/v1/explore/defaults", params={"kind": "chaplygin_ball", "potential": "linear"}).json()
    assert d == {"system": SYSTEM, "section": {**SECTION, "value": 0.0, "direction": "increasing"}}
    plane = client.post("/v1/explore/plane", json={"system": SYSTEM, "section": SECTION})
    assert plane.status_code == 200, plane.text
    (g0, g1), (m0, m1) = plane.json()["ranges"]
    # |gamma1| <= 1 widened by 2 %; M3 within the energy's bound (|M3| < 5.2 on H = 2)
    assert g0 == pytest.approx(-1.04, abs=2e-3) and g1 == pytest.approx(1.04, abs=2e-3)
    assert -5.3 < m0 < -4.9 and 4.9 < m1 < 5.3
    assert plane.json()["units"]["M"] == "kg m^2/s"


def test_a_click_streams_the_crossings_of_one_uninterrupted_section(client):
    r = client.post("/v1/explore/orbits", json={"system": SYSTEM, "section": SECTION, "point": [-0.2, 0.0],
                                                "t_final": 1500.0, "max_points": 700})
    assert r.status_code == 201, r.text
    accepted = r.json()
    assert r.headers["location"] == accepted["location"] and accepted["branches"] == 2
    points, view = _poll(client, accepted["location"])
    assert view["error"] is None and view["coordinate_names"] == ["gamma1", "M3"]
    # in pieces (100, then 500 at a time), each restarted from the last crossing: the same crossings as the
    # core's one section from the completed state
    system = get_system("chaplygin_ball", "linear")
    p = parameter_vector(system, {"inertia": [2.0, 3.0, 4.5], "D": 0.7, "a": [0.3, -0.2, 0.5]})
    x0 = state_vector(system, accepted["initial_state"], p)
    assert x0[5] == 0.0 and x0[3] == pytest.approx(-0.2, abs=1e-8) and x0[2] == pytest.approx(0.0, abs=1e-8)
    whole = section(system, p, x0, 1500.0, "gamma3", coordinates=("gamma1", "M3"), max_points=1000)
    reference = whole.coordinates[whole.t > 1e-9]
    assert len(points) == min(700, len(reference)) and len(points) > 250
    assert np.max(np.abs(np.array(points) - reference[: len(points)])) < 1e-9
    assert view["count"] == len(points)


def test_a_shift_click_finds_the_island_centre(client):
    r = client.post("/v1/explore/periodic-orbit", json={"system": SYSTEM, "section": SECTION, "point": [-0.2, 0.0]})
    assert r.status_code == 200, r.text
    orbit = r.json()
    assert orbit["status"] == "found" and orbit["stability"] == "elliptic"
    assert len(orbit["points"]) == 1 and orbit["points"][0] == pytest.approx([-0.15642933, 0.13491925], abs=1e-7)
    assert all(c["passed"] for c in orbit["checks"])


@pytest.mark.parametrize("body, field, words", [
    ({"point": [1.03, 0.0]}, "point", ["outside the level"]),
    ({"section": {**SECTION, "coordinates": ["gamma1", "Q3"]}}, "section.coordinates[1]", ["Q3"]),
    ({"section": {**SECTION, "level": {"energy": 2.0, "bogus": 1.0}}}, "section.level.bogus", ["energy"]),
    ({"t_final": 1e9}, "t_final", []),
    ({"point": [0.0]}, "point", []),
])
def test_bad_clicks_are_422_naming_the_field(client, body, field, words):
    r = client.post("/v1/explore/orbits", json={"system": SYSTEM, "section": SECTION, "point": [-0.2, 0.0], **body})
    assert r.status_code == 422, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    hit = [e for e in r.json()["errors"] if e["field"] == field]
    assert hit, r.json()["errors"]
    for word in words:
        assert word in hit[0]["reason"]


def test_unknown_runs_and_kinds_are_404(client):
    assert client.get("/v1/explore/orbits/nope").status_code == 404
    assert client.get("/v1/explore/defaults", params={"kind": "lagrangian"}).status_code == 404


def test_the_page_and_the_catalog_s_links(client):
    page = client.get("/explore", params={"kind": "chaplygin_ball", "potential": "zero"})
    assert page.status_code == 200 and page.headers["content-security-policy"] == EXPLORE_POLICY
    assert '<option value="chaplygin_ball|zero" selected>' in page.text and "/static/explore.js" in page.text
    ball = next(s for s in client.get("/v1/systems").json()["systems"] if s["kind"] == "chaplygin_ball")
    assert [p["explore"] for p in ball["potentials"]] == [
        f"/explore?kind=chaplygin_ball&potential={p['kind']}" for p in ball["potentials"]]
    assert client.get("/v1/systems/chaplygin_ball").json()["potentials"][0]["explore"].startswith("/explore?")
    assert client.get(ball["potentials"][1]["explore"]).status_code == 200
