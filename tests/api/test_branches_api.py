"""A periodic orbit's ``branch`` through the API: the JSON, the table as CSV and NetCDF, the bifurcation diagram, the
page, and the 4xx answers."""

from __future__ import annotations

import csv
import io

import numpy as np
import pytest

from tests.api.conftest import job
from tests.api.test_periodic_orbits_api import _run
from tests.support import poll_job


def branch_job(client) -> dict:
    return _run(client, branch={"in": "potential.a[2]", "to": 0.95, "switch_points": 4})


def test_the_branch_in_the_field_its_table_its_diagram_and_its_page(client):
    """One job (a branch in a3 through the period doubling, 4 points of the period-2 branch), every view of it."""
    view = branch_job(client)
    check_json(view)
    check_table(client, view)
    check_diagram_and_page(client, view)


def check_json(branch_job: dict) -> None:
    assert branch_job["request"]["periodic_orbit"]["branch"]["in"] == "potential.a[2]"  # stored by its alias
    branch = branch_job["result"]["periodic_orbit"]["branch"]
    assert branch["in"] == "potential.a[2]" and branch["status"] == "reached" and branch["period"] == 1
    assert branch["points"][0]["value"] == 0.5 and branch["points"][-1]["value"] == 0.95
    assert branch["units"]["value"] == "kg m^2/s^2" and branch["units"]["period_t"] == "s"
    [pd] = branch["bifurcations"]
    assert pd["kind"] == "period_doubling" and pd["located"] and pd["value"] == pytest.approx(0.85576535, abs=1e-7)
    assert pd["point"]["trace"] == pytest.approx(-2.0, abs=1e-8) and pd["switched"] == 0
    assert pd["point"]["residual_independent"] < 1e-10 and pd["between"][1] == pd["between"][0] + 1
    assert all(p["checks_passed"] for p in branch["points"])
    [doubled] = branch["switched"]
    assert doubled["period"] == 2 and len(doubled["points"]) == 4 and doubled["status"] == "max_points"
    assert doubled["origin"].startswith("period_doubling at potential.a[2] = 0.8557653")


def check_table(client, branch_job: dict) -> None:
    """The CSV and the NetCDF have every point and the bifurcation, the numbers as in the JSON."""
    branch = branch_job["result"]["periodic_orbit"]["branch"]
    r = client.get(f"/v1/jobs/{branch_job['id']}/branch?format=csv")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(r.text)))
    points = len(branch["points"]) + len(branch["switched"][0]["points"])
    assert len(rows) == points + 1  # and the period doubling's own row
    value = "potential.a[2] [kg m^2/s^2]"
    assert list(rows[0])[:5] == ["branch", "period", "kind", "index", value]
    assert "gamma1 [1]" in rows[0] and "period_t [s]" in rows[0] and "multiplier_2_im" in rows[0]
    [pd_row] = [row for row in rows if row["kind"] == "period_doubling"]
    assert float(pd_row[value]) == branch["bifurcations"][0]["value"]  # exactly: floats written by repr
    assert pd_row["located"] == "True" and pd_row["branch"] == "0"
    assert [row[value] for row in rows if row["branch"] == "0" and row["kind"] == "point"] == [
        repr(p["value"]) for p in branch["points"]]
    r = client.get(f"/v1/jobs/{branch_job['id']}/branch?format=netcdf")
    assert r.status_code == 200 and r.content[:4] == b"\x89HDF"
    import xarray

    with xarray.open_dataset(r.content, engine="netcdf4") as ds:
        assert ds.sizes["row"] == points + 1 and ds.attrs["branch_status"] == "reached"
        assert ds["potential_a_2"].attrs["units"] == "kg m^2/s^2"
        assert np.nanmax(ds["residual"].values) < 1e-9
        assert set(np.unique(ds["located"].values)) <= {-1, 1}


def check_diagram_and_page(client, branch_job: dict) -> None:
    image = client.get(f"/v1/jobs/{branch_job['id']}/plots/bifurcation.png")
    assert image.status_code == 200 and image.content[:4] == b"\x89PNG"
    assert client.get(f"/v1/jobs/{branch_job['id']}/plots/bifurcation.svg").text.lstrip().startswith("<?xml")
    page = client.get(f"/v1/jobs/{branch_job['id']}/page").text
    for words in ("Branch in potential.a[2]", 'id="bifurcations"', "period doubling", "plots/bifurcation.svg",
                  "branch?format=csv"):
        assert words in page, words


def test_a_job_without_a_branch_answers_409_and_a_bad_format_422(client):
    view = poll_job(client, client.post("/v1/jobs", json=job(t_final=1.0, samples=3)).headers["location"])
    r = client.get(f"/v1/jobs/{view['id']}/branch")
    assert r.status_code == 409 and "periodic_orbit.branch" in r.json()["detail"]
    assert client.get(f"/v1/jobs/{view['id']}/plots/bifurcation.png").status_code == 409
    r = client.get(f"/v1/jobs/{view['id']}/branch?format=npz")
    assert r.status_code == 422 and any("format" in e["field"] for e in r.json()["errors"])
