"""A job's trajectory as JSON, CSV (header with units, t and tau first) and NPZ; 409 before it
succeeded, 422 for an unknown format, 404 for an unknown job."""

from __future__ import annotations

import csv
import io
import json

import numpy as np

from tests.api.conftest import job
from tests.support import poll_job


def _done(client, **overrides) -> str:
    r = client.post("/v1/jobs", json=job(**overrides))
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"])
    assert view["status"] == "succeeded", view["error"]
    return r.headers["location"]


def test_csv_and_npz_hold_the_same_numbers_as_the_json(client):
    location = _done(client, samples=7)
    result = client.get(location).json()["result"]
    r = client.get(f"{location}/trajectory", params={"format": "csv"})
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    rows = list(csv.reader(io.StringIO(r.text)))
    assert rows[0][:3] == ["t [s]", "tau [s (kg m^2)^(-3/2)]", "M1 [kg m^2/s]"]
    assert "gamma3 [1]" in rows[0] and "omega1 [rad/s]" in rows[0]
    assert len(rows) == 8
    table = np.array(rows[1:], dtype=float)
    assert np.array_equal(table[:, 0], result["trajectory"]["t"])
    assert np.array_equal(table[:, 1], result["trajectory"]["tau"])
    assert np.array_equal(table[:, 2:5], result["trajectory"]["M"])  # repr(float) round-trips exactly
    npz = np.load(io.BytesIO(client.get(f"{location}/trajectory", params={"format": "npz"}).content))
    assert np.array_equal(npz["gamma"], result["trajectory"]["gamma"]) and npz["gamma"].shape == (7, 3)
    assert json.loads(str(npz["request_json"]))["system"]["kind"] == "chaplygin_ball"
    assert json.loads(str(npz["versions_json"]))["heyoka"] == result["integration"]["versions"]["heyoka"]
    as_json = client.get(f"{location}/trajectory").json()
    assert as_json["t"] == result["trajectory"]["t"] and as_json["units"]["M"] == "kg m^2/s"


def test_a_job_that_has_not_succeeded_is_409_saying_its_status(client):
    r = client.post("/v1/jobs", json=job(t_final=1e8, samples=2))
    location = r.headers["location"]
    answer = client.get(f"{location}/trajectory", params={"format": "csv"})
    assert answer.status_code == 409 and answer.headers["content-type"].startswith("application/problem+json")
    assert "is queued" in answer.json()["detail"] or "is running" in answer.json()["detail"]
    client.delete(location)


def test_unknown_format_is_422_and_unknown_job_404(client):
    location = _done(client)
    r = client.get(f"{location}/trajectory", params={"format": "xlsx"})
    assert r.status_code == 422 and "format" in r.json()["errors"][0]["field"]
    assert client.get("/v1/jobs/nope/trajectory").status_code == 404
