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


# --------------------------------------------------------------------------------------------------
# NetCDF-4, and a single job's Poincare section

#: A ball job whose orbit crosses gamma3 = 0 a dozen times (both directions) by t = 200.
SECTION = {"t_final": 200.0, "samples": 21,
           "poincare": {"surface": "gamma3", "direction": "both", "coordinates": ["gamma1", "gamma2"],
                        "max_points": 50}}
COMPONENTS = [f"{v}{k}" for v in ("M", "gamma", "omega") for k in (1, 2, 3)]


def _netcdf(content: bytes):
    import xarray as xr

    return xr.open_dataset(content, engine="netcdf4").load()


def _assert_provenance(ds, view: dict, location: str) -> None:
    result = view["result"]
    assert ds.attrs["Conventions"] == "CF-1.10" and "Borisov" in ds.attrs["references"]
    assert ds.attrs["job_id"] == location.rsplit("/", 1)[1] and ds.attrs["system_kind"] == "chaplygin_ball"
    assert result["integration"]["versions"]["heyoka"] in ds.attrs["source"]
    assert ds.attrs["history"].startswith(f"{view['created_at']}: job ") and "format=netcdf" in ds.attrs["history"]
    assert json.loads(ds.attrs["request"])["system"]["kind"] == "chaplygin_ball"
    evidence = json.loads(ds.attrs["evidence"])
    assert [i["name"] for i in evidence["integrals"]] == [i["name"] for i in result["integrals"]]
    assert [i["max_rel_drift"] for i in evidence["integrals"]] == [i["max_rel_drift"] for i in result["integrals"]]
    assert [c["passed"] for c in evidence["checks"]] == [c["passed"] for c in result["checks"]]


def test_the_trajectory_as_netcdf_reads_back_to_the_json_bit_for_bit(client):
    location = _done(client, samples=9, checks=["integrals", "measure"])
    view = client.get(location).json()
    result = view["result"]
    r = client.get(f"{location}/trajectory", params={"format": "netcdf"})
    assert r.status_code == 200 and r.headers["content-type"] == "application/x-netcdf"
    assert r.headers["content-disposition"].endswith('-trajectory.nc"') and r.content[:4] == b"\x89HDF"
    ds = _netcdf(r.content)
    samples = result["trajectory"]
    assert dict(ds.sizes) == {"t": 9} and list(ds.data_vars) == COMPONENTS
    assert np.array_equal(ds["t"].values, samples["t"]) and np.array_equal(ds["tau"].values, samples["tau"])
    for name in ("M", "gamma", "omega"):
        for k in range(3):
            var = ds[f"{name}{k + 1}"]
            assert var.dtype == np.float64 and np.array_equal(var.values, np.asarray(samples[name])[:, k])
            assert var.attrs["units"] == result["system"]["units"][name] and var.attrs["long_name"]
    assert ds["t"].attrs["units"] == "s" and ds["tau"].attrs["units"] == "s (kg m^2)^(-3/2)"
    assert "2604-5" in ds["tau"].attrs["long_name"]
    assert "angular momentum" in ds["M1"].attrs["long_name"]
    _assert_provenance(ds, view, location)
    # the same bytes every time (no clock in the file)
    assert client.get(f"{location}/trajectory", params={"format": "netcdf"}).content == r.content


def test_a_jobs_section_in_every_format_holds_the_same_numbers(client):
    location = _done(client, **SECTION)
    view = client.get(location).json()
    result = view["result"]
    section = result["poincare"]
    count = section["count"]
    assert count >= 5
    as_json = client.get(f"{location}/section").json()
    assert as_json == {"units": result["system"]["units"], **section}
    # CSV: one row per crossing, t, tau and every state and derived component
    r = client.get(f"{location}/section", params={"format": "csv"})
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    assert r.headers["content-disposition"].endswith('-section.csv"')
    rows = list(csv.reader(io.StringIO(r.text)))
    assert rows[0] == ["t [s]", "tau [s (kg m^2)^(-3/2)]", *[f"{c} [{u}]" for c, u in zip(
        COMPONENTS, ["kg m^2/s"] * 3 + ["1"] * 3 + ["rad/s"] * 3)]]
    table = np.array(rows[1:], dtype=float)
    assert table.shape == (count, 11)
    assert np.array_equal(table[:, 0], section["t"]) and np.array_equal(table[:, 1], section["tau"])
    assert np.array_equal(table[:, 2:5], section["points"]["M"])
    assert np.array_equal(table[:, 8:11], section["points"]["omega"])
    assert np.abs(table[:, 7]).max() <= 1e-13  # on the surface gamma3 = 0
    # NPZ
    npz = np.load(io.BytesIO(client.get(f"{location}/section", params={"format": "npz"}).content))
    assert np.array_equal(npz["t"], section["t"]) and np.array_equal(npz["gamma"], section["points"]["gamma"])
    assert npz["gamma"].shape == (count, 3) and np.array_equal(npz["coordinates"], section["coordinates"])
    assert json.loads(str(npz["section_json"]))["surface"] == "gamma3"
    assert json.loads(str(npz["units_json"]))["omega"] == "rad/s"
    # NetCDF: dimension crossing, coordinates t and tau
    r = client.get(f"{location}/section", params={"format": "netcdf"})
    assert r.status_code == 200 and r.headers["content-type"] == "application/x-netcdf"
    ds = _netcdf(r.content)
    assert dict(ds.sizes) == {"crossing": count} and list(ds.data_vars) == COMPONENTS
    assert set(ds.coords) == {"t", "tau"}
    assert np.array_equal(ds["t"].values, section["t"]) and np.array_equal(ds["tau"].values, section["tau"])
    for name, values in section["points"].items():
        for k in range(3):
            assert np.array_equal(ds[f"{name}{k + 1}"].values, np.asarray(values)[:, k])
    assert ds.attrs["surface"] == "gamma3" and ds.attrs["direction"] == "both"
    assert ds.attrs["coordinate_names"] == "gamma1 gamma2"
    assert json.loads(ds.attrs["section"])["integral_drift_max"] == section["integral_drift_max"]
    assert json.loads(ds.attrs["evidence"])["poincare"]["surface_residual_max"] == section["surface_residual_max"]
    _assert_provenance(ds, view, location)


def test_a_download_comes_as_octet_stream_when_asked_for_only_that(client):
    location = _done(client, **SECTION)
    for path, fmt in (("trajectory", "csv"), ("section", "netcdf"), ("section", "npz"), ("section", "json")):
        plain = client.get(f"{location}/{path}", params={"format": fmt})
        binary = client.get(f"{location}/{path}", params={"format": fmt},
                            headers={"Accept": "application/octet-stream"})
        assert binary.headers["content-type"] == "application/octet-stream" and binary.content == plain.content
        either = client.get(f"{location}/{path}", params={"format": fmt},
                            headers={"Accept": "application/octet-stream, */*;q=0.1"})
        assert either.headers["content-type"] == plain.headers["content-type"]


def test_a_section_needs_a_job_that_asked_for_one(client):
    location = _done(client, samples=3)
    r = client.get(f"{location}/section", params={"format": "csv"})
    assert r.status_code == 409 and r.headers["content-type"].startswith("application/problem+json")
    assert "no poincare section" in r.json()["detail"]
    assert client.get("/v1/jobs/nope/section").status_code == 404
    assert client.get(f"{location}/section", params={"format": "xlsx"}).status_code == 422
    r = client.post("/v1/jobs", json=job(t_final=1e8, samples=2, poincare={"surface": "gamma3"}))
    pending = client.get(f"{r.headers['location']}/section")
    assert pending.status_code == 409 and "once it succeeded" in pending.json()["detail"]
    client.delete(r.headers["location"])
