"""Finding what you ran (issue 35, item 1), embedded mode in-process: ``GET /v1/ensembles`` lists the caller's
ensembles newest first, paged, filtered by status, each with what varies across its members; a job or an
ensemble is found by the first characters of its id (the client's progress bar shows 8), a prefix two ids
share is a 409 naming them, and another key's ensemble is neither listed nor found by its prefix."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

from tests.api.conftest import BALL, STATE
from tests.api.test_admission import A, B, _finished, _until_status, app_with, ensemble

__all__ = ["app_with"]  # the fixture, shared with test_admission.py


def _sweep() -> dict:
    return {"system": dict(BALL), "members": {"sweep": {"parameter": "D", "values": [0.1, 0.2],
                                                        "initial_state": dict(STATE)}},
            "t_final": 1.0, "samples": 2}


def test_ensembles_are_listed_newest_first_paged_and_filtered(app_with):
    client = app_with(API_KEYS="alice:alpha-secret,bob:beta-secret")
    posted = []
    for body in (ensemble(2), _sweep(), ensemble(3, sample=True)):
        r = client.post("/v1/ensembles", json=body, headers=A)
        assert r.status_code == 202, r.text
        posted.append(r.json()["id"])
        _finished(client, r.headers["location"])
    listed = client.get("/v1/ensembles", headers=A).json()
    assert [i["id"] for i in listed["items"]] == posted[::-1] and listed["next_cursor"] is None
    newest, sweep, first = listed["items"]
    assert sweep["label"] == "sweep of D" and newest["label"] == "level set" and first["label"] == "list"
    assert all(i["status"] == "succeeded" and i["progress"] == 1.0 and i["kind"] == "chaplygin_ball"
               for i in listed["items"])
    assert [i["members"] for i in listed["items"]] == [3, 2, 2] and sweep["location"] == f"/v1/ensembles/{posted[1]}"
    page = client.get("/v1/ensembles", params={"limit": 2}, headers=A).json()
    assert [i["id"] for i in page["items"]] == posted[:0:-1] and page["next_cursor"]
    rest = client.get("/v1/ensembles", params={"limit": 2, "cursor": page["next_cursor"]}, headers=A).json()
    assert [i["id"] for i in rest["items"]] == posted[:1] and rest["next_cursor"] is None
    assert client.get("/v1/ensembles", params={"status": "cancelled"}, headers=A).json()["items"] == []
    assert client.get("/v1/ensembles", headers=B).json()["items"] == []  # bob sees none of alice's
    for params, field in (({"status": "done"}, "status"), ({"cursor": "nonsense"}, "cursor")):
        r = client.get("/v1/ensembles", params=params, headers=A)
        assert r.status_code == 422 and r.json()["errors"][0]["field"] == field, r.text


def test_a_job_or_an_ensemble_is_found_by_the_first_characters_of_its_id(app_with):
    client = app_with(API_KEYS="alice:alpha-secret,bob:beta-secret")
    r = client.post("/v1/ensembles", json=ensemble(2), headers=A)
    whole = r.json()["id"]
    _finished(client, r.headers["location"])
    shown = client.get(f"/v1/ensembles/{whole[:8]}", headers=A)
    assert shown.status_code == 200 and shown.json()["id"] == whole
    members = client.get(f"/v1/ensembles/{whole[:8]}/members", headers=A).json()
    assert len(members["members"]) == 2
    assert client.get(f"/v1/ensembles/{whole[:8]}", headers=B).status_code == 404  # another key's: unknown
    assert client.get(f"/v1/ensembles/{whole[:5]}", headers=A).status_code == 404  # too short to be a prefix
    job = client.post("/v1/jobs", json={"system": dict(BALL), "initial_state": dict(STATE), "t_final": 1.0,
                                        "samples": 3}, headers=A).json()["id"]
    _until_status(client, f"/v1/jobs/{job}", "succeeded")
    assert client.get(f"/v1/jobs/{job[:8]}", headers=A).json()["id"] == job
    assert client.get(f"/v1/jobs/{job[:8]}/trajectory", params={"format": "csv"}, headers=A).status_code == 200
    store = client.app.state.backend.store
    for twin in ("abcdef00-0000-4000-8000-000000000001", "abcdef00-1111-4000-8000-000000000002"):
        store.create(twin, {"system": dict(BALL)}, "alice")
    ambiguous = client.get("/v1/jobs/abcdef00", headers=A)
    assert ambiguous.status_code == 409 and "2 jobs start with 'abcdef00'" in ambiguous.json()["detail"]
    unique = client.get("/v1/jobs/abcdef00-1", headers=A)
    assert unique.status_code == 200 and unique.json()["id"] == "abcdef00-1111-4000-8000-000000000002"


def test_the_members_csv_carries_the_swept_value_and_the_jsons_numbers(app_with):
    """Issue 35, item 2: the members as one table, the sweep's value in a column named after its parameter."""
    import csv
    import io

    client = app_with()
    r = client.post("/v1/ensembles", json=_sweep())
    _finished_any(client, r.headers["location"])
    table = client.get(f"{r.headers['location']}/members", params={"format": "csv"})
    assert table.status_code == 200 and table.headers["content-type"].startswith("text/csv"), table.text
    rows = list(csv.DictReader(io.StringIO(table.text)))
    swept = next(h for h in rows[0] if h.split(" ")[0] == "D")
    assert [float(row[swept]) for row in rows] == [0.1, 0.2] and [row["member"] for row in rows] == ["0", "1"]
    members = client.get(f"{r.headers['location']}/members").json()["members"]
    for row, member in zip(rows, members, strict=True):
        assert float(row["final_M1 [kg m^2/s]"]) == member["final_state"]["M"][0]  # repr: read back exactly
        assert float(row["drift_energy"]) == member["integrals"][0]["max_rel_drift"]
    assert list(rows[0])[:3] == ["member", "status", swept] and rows[0]["status"] == "succeeded"
    # the same table as NetCDF (dimension member): each column a variable with its units, the numbers bit for bit
    import xarray

    nc = client.get(f"{r.headers['location']}/members", params={"format": "netcdf"})
    assert nc.status_code == 200 and nc.headers["content-type"] == "application/x-netcdf", nc.text[:300]
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "members.nc"
        path.write_bytes(nc.content)
        dataset = xarray.load_dataset(path)
    assert list(dataset["member"].values) == [0, 1] and list(dataset["D"].values) == [0.1, 0.2]
    assert dataset["D"].attrs["long_name"] == swept and dataset["final_M1"].attrs["units"] == "kg m^2/s"
    for k, member in enumerate(members):
        assert float(dataset["final_M1"].values[k]) == member["final_state"]["M"][0]
        assert float(dataset["drift_energy"].values[k]) == member["integrals"][0]["max_rel_drift"]
        assert str(dataset["status"].values[k]) == "succeeded"
        assert int(dataset["checks_passed"].values[k]) == {"": -1, "False": 0, "True": 1}[rows[k]["checks_passed"]]
    assert json.loads(dataset.attrs["request"])["members"]["sweep"]["parameter"] == "D"


def _finished_any(client, location: str) -> None:
    import time

    deadline = time.monotonic() + 300  # a hang guard
    while client.get(location).json()["status"] != "succeeded":
        assert time.monotonic() < deadline, f"hang guard: {location} not succeeded"
        time.sleep(0.01)
