"""Chaos maps through the API in embedded mode: Chaplygin's ball regular everywhere for U = 0, its chaotic sea
in a linear field; the map's exports (CSV, JSON, NetCDF, PNG, SVG) equal to the members' numbers; the page;
validation naming the field."""

from __future__ import annotations

import csv
import io

import numpy as np
import pytest

from tests.api.conftest import BALL
from tests.support import poll_job

LINEAR = {**BALL, "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}}
GRID = {"surface": "gamma3", "value": 0.0, "coordinates": ["gamma1", "M3"], "level": {"energy": 2.0, "area": 0.0},
        "shape": [12, 10]}


def chaos_map(system: dict, **overrides) -> dict:
    body = {"system": dict(system), "members": {"grid": dict(GRID)}, "t_final": 200.0, "indicators": ["megno", "fli"]}
    body.update(overrides)
    return body


def run(client, body: dict) -> tuple[dict, list[dict]]:
    r = client.post("/v1/ensembles", json=body)
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"], timeout=120)
    assert view["status"] == "succeeded"
    members = client.get(f"{r.headers['location']}/members", params={"limit": 1000}).json()["members"]
    return view, members


def test_the_integrable_ball_is_regular_in_every_cell(client):
    view, members = run(client, chaos_map(BALL))
    m = view["summary"]["map"]
    assert m["cells"] == 120 and m["chaotic"] == 0 and m["failed"] == 0 and m["chaotic_fraction"] == 0.0
    assert m["regular"] + m["outside"] == 120 and m["regular"] >= 100
    assert m["indicators"]["megno"]["max"] < m["thresholds"]["megno"] == 3.0
    assert m["thresholds"]["fli"] == pytest.approx(np.log(200.0) + 3.0)
    assert m["check"]["cells"] >= 1 and m["check"]["agreement"] == 1.0
    assert view["summary"]["worst_integral_drift"]["energy"] < 1e-13
    ranges = view["request"]["members"]["grid"]["ranges"]  # resolved at submission: the level's extent
    assert ranges[0][0] < -1.0 < 1.0 < ranges[0][1]
    cell = next(c for c in members if c["status"] == "succeeded")
    assert set(cell["cell"]["indicators"]) == {"megno", "fli", "lyapunov"}
    # each cell's integrals against a job's tolerance (1e-10 at machine precision): none failed
    assert view["summary"]["members_with_failed_checks"] == 0
    assert all(c["cell"]["integrals_failed"] == [] for c in members if c["status"] == "succeeded")
    assert cell["initial_state"]["gamma"][2] == 0.0 and set(cell["label"]) == {"cell", "gamma1", "M3", "branches"}



def test_the_pages_cell_table_shows_the_cells_inside_the_level(client):
    """Issue 35, item 6: a map drawn wider than its level began its table with rows of 'outside'."""
    grid = {**GRID, "shape": [10, 8], "ranges": [[-1.5, 1.5], [-12.0, 12.0]]}
    view, members = run(client, chaos_map(BALL, t_final=20.0, members={"grid": grid}))
    assert view["summary"]["map"]["outside"] > 10 and members[0]["cell"]["status"] == "outside"
    page = client.get(f"/v1/ensembles/{view['id']}/page").text
    table = page[page.index('<table id="cells">'):]
    table = table[:table.index("</table>")]
    inside = [c["index"] for c in members if c["cell"]["status"] != "outside"]
    assert table.count('<tr id="member-') == min(50, len(inside)) and 'class="outside"' not in table
    assert f'id="member-{inside[0]}"' in table and "inside the level" in page


def test_the_linear_field_shows_its_chaotic_sea_and_the_exports_carry_the_members_numbers(client):
    view, members = run(client, chaos_map(LINEAR, t_final=300.0))
    m = view["summary"]["map"]
    assert 0.2 < m["chaotic_fraction"] < 0.8, m  # bench/SCIENCE: a sea around a regular island
    assert m["failed"] == 0 and m["indicators"]["megno"]["max"] > 10
    ensemble = view["id"]
    by_cell = {tuple(c["label"]["cell"]): c for c in members}
    # CSV: one row per cell, a header with units
    rows = list(csv.reader(io.StringIO(client.get(f"/v1/ensembles/{ensemble}/map", params={"format": "csv"}).text)))
    assert rows[0][:8] == ["i", "j", "gamma1 [1]", "M3 [kg m^2/s]", "status", "branches", "megno [1]", "fli [1]"]
    assert len(rows) == 121
    for row in rows[1:]:
        c = by_cell[(int(row[0]), int(row[1]))]
        assert row[4] == c["cell"]["status"]
        if c["status"] == "succeeded":
            assert float(row[6]) == c["cell"]["indicators"]["megno"] and float(row[7]) == c["cell"]["indicators"]["fli"]
            assert float(row[2]) == c["label"]["gamma1"] and float(row[3]) == c["label"]["M3"]
        else:
            assert row[6] == ""
    # JSON: 2-D arrays [i][j]
    js = client.get(f"/v1/ensembles/{ensemble}/map", params={"format": "json"}).json()
    assert js["coordinates"] == ["gamma1", "M3"] and len(js["axes"][0]) == 12 and len(js["axes"][1]) == 10
    assert js["summary"] == m
    # NetCDF: dimensions the coordinates, the same numbers bit for bit
    import xarray as xr

    r = client.get(f"/v1/ensembles/{ensemble}/map", params={"format": "netcdf"})
    assert r.status_code == 200 and r.headers["content-type"] == "application/x-netcdf"
    ds = xr.open_dataset(r.content, engine="netcdf4").load()
    assert ds["megno"].dims == ("gamma1", "M3") and ds["M3"].attrs["units"] == "kg m^2/s"
    megno = np.array([[np.nan if v is None else v for v in row] for row in js["indicators"]["megno"]])
    assert np.array_equal(ds["megno"].values, megno, equal_nan=True)
    words = ds["status"].attrs["flag_meanings"].split()
    assert [[words[v] for v in row] for row in ds["status"].values.tolist()] == js["status"]
    # the image and the page
    for fmt, head in (("png", b"\x89PNG"), ("svg", b"<?xml")):
        r = client.get(f"/v1/ensembles/{ensemble}/plots/map.{fmt}")
        assert r.status_code == 200 and r.content.startswith(head)
    page = client.get(f"/v1/ensembles/{ensemble}/page").text
    assert "Chaos map" in page and f"/v1/ensembles/{ensemble}/plots/map.png" in page and "chaotic fraction" in page


@pytest.mark.parametrize("change, field, words", [
    ({"members": {"grid": {**GRID, "coordinates": ["gamma1", "M9"]}}}, "members.grid.coordinates[1]",
     "not a state component"),
    ({"members": {"grid": {**GRID, "coordinates": ["M1", "M2"], "surface": "M3"}}}, "members.grid.coordinates",
     "free components"),
    ({"members": {"grid": {**GRID, "level": {"energy": 2.0, "F": 1.0}}}}, "members.grid.level.F", "a level may fix"),
    ({"members": {"grid": {**GRID, "shape": [600, 10]}}}, "members.grid.shape", "1 .. 512"),
    ({"indicators": None}, "body", "give indicators"),
    ({"indicators": ["megno"], "thresholds": {"fli": 3.0}}, "body", "thresholds for indicators not asked for"),
    ({"lyapunov": {"count": 1}}, "body", "leave out poincare and lyapunov"),
    ({"members": {"grid": {**GRID, "level": {"energy": -5.0, "area": 0.0}}}}, "members.grid.level", "energy"),
    ({"members": {"grid": {**GRID, "sheet": "gamma9 + 1"}}}, "members.grid.sheet", "gamma9"),
])
def test_a_bad_map_is_refused_with_the_field_and_the_reason(client, change, field, words):
    body = chaos_map(BALL)
    body.update(change)
    if body.get("indicators") is None:
        del body["indicators"]
    r = client.post("/v1/ensembles", json=body)
    assert r.status_code == 422, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    errors = r.json()["errors"]
    assert any(e["field"].startswith(field) and words in e["reason"] for e in errors), errors


def test_the_jacobi_problems_map_on_its_two_integrals_with_one_sheet(client):
    """The level (H, K) fixes omega up to the common points of two conics; the sheet a = (omega, n) > 0."""
    body = {"system": {"kind": "ball_on_quadric", "D0": 0.036, "m": 1.0, "R": 0.3, "B": [1.0, 2.0, 3.0]},
            "members": {"grid": {"surface": "x2", "coordinates": ["x3", "omega2"], "level": {"energy": 0.5, "K": 2.0},
                                 "shape": [8, 6], "sheet": "x1*omega1 + x3*omega3/3"}},
            "t_final": 100.0, "indicators": ["megno"]}
    view, members = run(client, body)
    m = view["summary"]["map"]
    assert m["failed"] == 0 and m["regular"] + m["chaotic"] >= 20
    for c in members:
        if c["status"] == "succeeded":
            x, w = np.array(c["initial_state"]["x"]), np.array(c["initial_state"]["omega"])
            assert x[1] == 0.0 and w @ (x / [1.0, 2.0, 3.0]) > 0 and c["label"]["branches"] == 2
            assert c["cell"]["integral_drift"]["K"] < 1e-12


def test_an_ensemble_that_is_not_a_map_has_no_map(client):
    r = client.post("/v1/ensembles", json={"system": dict(BALL), "members": {"sample": {
        "count": 2, "seed": 1, "level": {"energy": 1.0}}}, "t_final": 5.0})
    view = poll_job(client, r.headers["location"], timeout=60)
    r = client.get(f"/v1/ensembles/{view['id']}/map")
    assert r.status_code == 409 and "not a chaos map" in r.json()["detail"]


def test_a_chunk_that_fails_whole_leaves_a_map_with_its_cells_failed(client, monkeypatch):
    """The cells of a chunk that raised are stored as failed members (index, status, error): the summary,
    the exports, the image and the page still answer, with those cells `failed`."""
    import workers.ensembles as chunks

    real = chunks.run_cells

    def broken(system, members, *args, **kwargs):
        if members[0].index == 0:
            raise RuntimeError("a bug in the first chunk")
        return real(system, members, *args, **kwargs)

    monkeypatch.setattr(chunks, "run_cells", broken)
    view, members = run(client, chaos_map(LINEAR, t_final=50.0, chunk_size=30))
    m = view["summary"]["map"]
    assert m["failed"] == 30 and m["regular"] + m["chaotic"] + m["outside"] == 90
    assert view["summary"]["failed"] == 30 and "a bug in the first chunk" in view["summary"]["failures"][0]["error"]
    js = client.get(f"/v1/ensembles/{view['id']}/map", params={"format": "json"}).json()
    assert [row[:10] for row in js["status"][:3]] == [["failed"] * 10] * 3
    for path in ("map?format=csv", "map?format=netcdf", "plots/map.png", "page"):
        assert client.get(f"/v1/ensembles/{view['id']}/{path}").status_code == 200, path
