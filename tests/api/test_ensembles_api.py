"""Ensembles in embedded mode through the API: members from a level set, a sweep and a list; the
section export; validation before anything is queued; a failing member; cancellation."""

from __future__ import annotations

import csv
import io
import json
import time

import numpy as np
import pytest

from tests.api.conftest import BALL, STATE, job
from tests.support import poll_job

SAMPLED = {"system": dict(BALL),
           "members": {"sample": {"count": 6, "seed": 7, "level": {"energy": 1.0, "area": 0.0}}},
           "t_final": 60.0, "samples": 3, "checks": ["integrals", "measure"],
           "poincare": {"surface": "gamma3", "coordinates": ["gamma1", "gamma2"]},
           "lyapunov": {"count": 1, "interval": 1.0}, "chunk_size": 4}


def _members(client, ensemble_id: str) -> list[dict]:
    page = client.get(f"/v1/ensembles/{ensemble_id}/members", params={"limit": 1000}).json()
    return page["members"]


def _strip_times(value):
    if isinstance(value, dict):
        return {k: _strip_times(v) for k, v in value.items() if k not in ("wall_time_s",)}
    if isinstance(value, list):
        return [_strip_times(v) for v in value]
    return value


def test_sampled_ensemble_on_one_level_with_section_and_exponents(client):
    r = client.post("/v1/ensembles", json=SAMPLED)
    assert r.status_code == 202, r.text
    accepted = r.json()
    assert accepted["members"] == 6 and accepted["chunks"] == 2
    assert r.headers["location"] == f"/v1/ensembles/{accepted['id']}"
    view = poll_job(client, r.headers["location"])
    assert view["status"] == "succeeded" and view["progress"] == 1.0 and view["members_done"] == 6
    assert view["chunks"]["done"] == 2 and sum(view["chunks"]["workers"].values()) == 2
    summary = view["summary"]
    assert summary["succeeded"] == 6 and summary["failed"] == 0
    assert summary["worst_integral_drift"]["energy"] < 1e-12
    assert summary["largest_exponent"]["count"] == 6
    members = _members(client, accepted["id"])
    assert [m["index"] for m in members] == list(range(6))
    for m in members:
        energy = next(i for i in m["integrals"] if i["name"] == "energy")
        area = next(i for i in m["integrals"] if i["name"] == "area")
        assert energy["initial"] == pytest.approx(1.0, abs=1e-12) and abs(area["initial"]) < 1e-12
        assert all(c["passed"] for c in m["checks"])
        # U = 0 is integrable: the largest exponent is small and falling (a bound, not zero, at t = 60)
        assert abs(m["lyapunov"]["exponents"][0]) < 0.2
        assert m["poincare"]["count"] >= 1 and m["poincare"]["surface_residual_max"] <= 1e-13
        series = m["lyapunov"]["convergence_t"]  # thinned for members, ending at t_final
        assert len(series) <= 100 and series[-1] == 60.0
    # the export: one row per crossing, the member index first, every state component
    text = client.get(f"/v1/ensembles/{accepted['id']}/poincare", params={"format": "csv"}).text
    rows = list(csv.reader(io.StringIO(text)))
    assert rows[0][:3] == ["member", "t [s]", "tau [s (kg m^2)^(-3/2)]"]
    assert "gamma3 [1]" in rows[0] and "omega1 [rad/s]" in rows[0] and "M1 [kg m^2/s]" in rows[0]
    assert len(rows) - 1 == sum(m["poincare"]["count"] for m in members)
    col = rows[0].index("gamma3 [1]")
    assert max(abs(float(row[col])) for row in rows[1:]) <= 1e-13
    npz = np.load(io.BytesIO(client.get(f"/v1/ensembles/{accepted['id']}/poincare",
                                        params={"format": "npz"}).content))
    assert npz["member"].shape == (len(rows) - 1,) and npz["gamma"].shape == (len(rows) - 1, 3)
    assert np.array_equal(npz["t"], [float(row[1]) for row in rows[1:]])
    # NetCDF-4: dimension crossing, coordinates member, t, tau; the members' numbers bit for bit
    import xarray as xr

    r = client.get(f"/v1/ensembles/{accepted['id']}/poincare", params={"format": "netcdf"})
    assert r.status_code == 200 and r.headers["content-type"] == "application/x-netcdf"
    assert r.headers["content-disposition"].endswith('-poincare.nc"')
    ds = xr.open_dataset(r.content, engine="netcdf4").load()
    assert dict(ds.sizes) == {"crossing": len(rows) - 1} and set(ds.coords) == {"member", "t", "tau"}
    assert np.array_equal(ds["member"].values, npz["member"]) and ds["member"].dtype == np.int64
    assert np.array_equal(ds["t"].values, npz["t"]) and np.array_equal(ds["tau"].values, npz["tau"])
    for m in members:
        mine = ds.where(ds["member"] == m["index"], drop=True)
        assert np.array_equal(mine["gamma2"].values, np.asarray(m["poincare"]["points"]["gamma"])[:, 1])
        assert np.array_equal(mine["omega3"].values, np.asarray(m["poincare"]["points"]["omega"])[:, 2])
    assert ds["M1"].attrs["units"] == "kg m^2/s" and ds["t"].attrs["units"] == "s"
    assert ds.attrs["Conventions"] == "CF-1.10" and ds.attrs["ensemble_id"] == accepted["id"]
    assert json.loads(ds.attrs["request"])["members"]["sample"] == SAMPLED["members"]["sample"]
    assert json.loads(ds.attrs["evidence"])["summary"]["succeeded"] == 6


def test_same_request_and_seed_give_the_same_numbers_bit_for_bit(client):
    body = {**SAMPLED, "lyapunov": None}
    ids = [client.post("/v1/ensembles", json=body).json()["id"] for _ in range(2)]
    for i in ids:
        assert poll_job(client, f"/v1/ensembles/{i}")["status"] == "succeeded"
    first, second = (_strip_times(_members(client, i)) for i in ids)
    assert first == second


def test_sweep_members_equal_single_jobs(client):
    body = {"system": dict(BALL), "t_final": 30.0, "samples": 5,
            "members": {"sweep": {"parameter": "D", "values": [0.1, 0.5, 0.9], "initial_state": STATE}}}
    r = client.post("/v1/ensembles", json=body)
    assert r.status_code == 202, r.text
    assert poll_job(client, r.headers["location"])["status"] == "succeeded"
    members = _members(client, r.json()["id"])
    for member, D in zip(members, [0.1, 0.5, 0.9]):
        assert member["label"] == {"parameter": "D", "value": D}
        single = client.post("/v1/jobs", json=job(system={**BALL, "D": D}, t_final=30.0, samples=5))
        view = poll_job(client, single.headers["location"])
        expected = np.array(view["result"]["trajectory"]["M"])
        assert np.allclose(member["trajectory"]["M"], expected, rtol=0, atol=1e-13)


def test_a_member_that_blows_up_fails_alone(client, monkeypatch):
    """A member whose integration fails (heyoka's non-finite state; admissible inputs no longer
    overflow, so the failure is injected into the second lane) fails alone."""
    from nonholonomic.numerics import integration, integration_batch

    huge = {"members": {"initial_states": [STATE, {"M": [1e200, 1e200, 0.0], "gamma": [0.0, 0.6, 0.8]}]},
            "system": dict(BALL), "t_final": 10.0}
    refused = client.post("/v1/ensembles", json=huge)
    assert refused.status_code == 422 and "members.initial_states[1].M[0]" in refused.text
    real = integration_batch.integrate_batch

    def second_lane_blows_up(*args, **kwargs):
        out = real(*args, **kwargs)
        out[1] = integration.IntegrationError("heyoka stopped at t = 0.25 with outcome err_nf_state (non-finite state)")
        return out

    monkeypatch.setattr(integration_batch, "integrate_batch", second_lane_blows_up)
    body = {"system": dict(BALL), "t_final": 10.0, "members": {"initial_states": [STATE, STATE, STATE]}}
    r = client.post("/v1/ensembles", json=body)
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"])
    assert view["status"] == "succeeded"
    assert view["summary"]["succeeded"] == 2 and view["summary"]["failed"] == 1
    members = _members(client, r.json()["id"])
    assert [m["status"] for m in members] == ["succeeded", "failed", "succeeded"]
    assert "non-finite" in members[1]["error"] or "nf_state" in members[1]["error"]


@pytest.mark.parametrize("members, field", [
    ({"initial_states": [STATE, {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.9]}]}, "members.initial_states[1].gamma"),
    ({"sample": {"count": 3, "level": {"energy": 1.0, "nonsense": 2.0}}}, "members.sample.level.nonsense"),
    ({"sweep": {"parameter": "Q", "values": [1.0], "initial_state": STATE}}, "members.sweep.parameter"),
    ({"sweep": {"parameter": "D", "values": [0.3, -1.0], "initial_state": STATE}}, "members.sweep.values[1]"),
    ({"sweep": {"parameter": "inertia[3]", "values": [1.0], "initial_state": STATE}}, "members.sweep.parameter"),
    ({"initial_states": [STATE], "sample": {"count": 2, "level": {"energy": 1.0}}}, "members"),
])
def test_members_are_validated_before_anything_is_queued(client, members, field):
    r = client.post("/v1/ensembles", json={"system": dict(BALL), "members": members, "t_final": 10.0})
    assert r.status_code == 422, r.text
    problem = r.json()
    assert r.headers["content-type"].startswith("application/problem+json")
    assert field in [e["field"] for e in problem["errors"]], problem


def test_limits_and_analysis_blocks_are_422s_naming_the_field(client):
    big = {"system": dict(BALL), "t_final": 10.0, "samples": 5001,
           "members": {"sample": {"count": 1000, "level": {"energy": 1.0}}}}
    r = client.post("/v1/ensembles", json=big)
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "samples"
    base = {"system": dict(BALL), "t_final": 10.0, "members": {"initial_states": [STATE]}}
    r = client.post("/v1/ensembles", json={**base, "poincare": {"surface": "gamma3 + zeta"}})
    assert r.status_code == 422
    error = r.json()["errors"][0]
    assert error["field"] == "poincare.surface" and "zeta" in error["reason"] and "position 9" in error["reason"]
    r = client.post("/v1/ensembles", json={**base, "lyapunov": {"count": 7}})
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "lyapunov.count"
    many = {**big, "samples": 2, "poincare": {"surface": "gamma3", "max_points": 100_000},
            "members": {"sample": {"count": 101, "level": {"energy": 1.0}}}}
    r = client.post("/v1/ensembles", json=many)
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "poincare.max_points"


def test_unknown_ensemble_is_404(client):
    for path in ("", "/members", "/poincare"):
        r = client.get(f"/v1/ensembles/nope{path}")
        assert r.status_code == 404 and r.headers["content-type"].startswith("application/problem+json")


def test_cancel_stops_every_chunk(client):
    body = {"system": dict(BALL), "t_final": 3000.0, "chunk_size": 4,
            "members": {"sample": {"count": 40, "seed": 1, "level": {"energy": 1.0}}},
            "lyapunov": {"count": 6}}
    r = client.post("/v1/ensembles", json=body)
    assert r.status_code == 202
    location = r.headers["location"]
    deadline = time.monotonic() + 60
    while client.get(location).json()["status"] == "queued" and time.monotonic() < deadline:
        time.sleep(0.05)
    cancelled = client.delete(location)
    assert cancelled.status_code == 202 and cancelled.json()["status"] == "cancelled"
    time.sleep(1.0)
    done = client.get(location).json()["members_done"]
    time.sleep(1.0)
    after = client.get(location).json()
    assert after["status"] == "cancelled" and after["members_done"] == done < 40
    assert client.delete(location).status_code == 202  # still not finished: cancelling again is harmless


def test_closing_the_app_stops_a_running_ensemble(monkeypatch):
    """Embedded mode: shutting the API down stops running chunks (at their next progress report) instead
    of computing on after the server is gone; they stay pending, for the next start to run again."""
    import threading

    from fastapi.testclient import TestClient

    from schemas.settings import get_settings
    from service.main import create_app

    monkeypatch.delenv("REDIS_URL", raising=False)
    monkeypatch.setenv("NONHOLONOMIC_WARM_UP", "false")
    monkeypatch.setenv("NONHOLONOMIC_MAX_T_FINAL", "1e9")
    get_settings.cache_clear()
    body = {"system": dict(BALL), "members": {"initial_states": [dict(STATE)]}, "t_final": 1e7}
    with TestClient(create_app()) as c:
        location = c.post("/v1/ensembles", json=body).headers["location"]
        deadline = time.monotonic() + 20
        while c.get(location).json()["status"] == "queued" and time.monotonic() < deadline:
            time.sleep(0.02)
        backend = c.app.state.backend
        ensemble_id = location.rsplit("/", 1)[1]
    get_settings.cache_clear()
    record = backend.ensembles.record(ensemble_id)  # stopped, not cancelled: pending for the next start
    assert not record["cancelled"] and record["done"] == set() and record["starts"] == {0: 1}
    deadline = time.monotonic() + 10
    while any(t.name.startswith("nonholonomic-job") for t in threading.enumerate()) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(t.name.startswith("nonholonomic-job") for t in threading.enumerate())
