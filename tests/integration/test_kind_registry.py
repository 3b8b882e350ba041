"""A kind added in one file is served end to end (issue 32, the registry of kinds).

The toy kind (``tests/toy_kind.py``: the Euler–Poisson equations, Chaplygin's ball at D = 0) is declared
under the entry-point group ``nonholonomic.kinds`` by a throwaway distribution (a ``.dist-info`` folder
on the API's ``PYTHONPATH``), exactly as another package would add a kind; no file of the tree names it.
One API process in embedded mode then serves it: the catalog (with its sampling plan), a job (its
integrals, and the same orbit as Chaplygin's ball at D = 0, an independent definition), the job's page,
the NetCDF export, an ensemble sampled on its level set, and a 422 naming a bad field.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest

from tests.support import ROOT, embedded_api, poll_job

pytestmark = pytest.mark.integration

KIND = "toy_euler_poisson"
JOB = {"system": {"kind": KIND, "inertia": [2.0, 3.0, 4.5], "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}},
       "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 20.0, "samples": 21,
       "checks": ["integrals", "measure"]}
#: The same body as Chaplygin's ball at D = 0: I_Q = I, the same equations (eq. 2604-1).
BALL = {**JOB, "system": {**JOB["system"], "kind": "chaplygin_ball", "D": 0.0}}
#: Hang guard (seconds) of each wait: a first job compiles its system; never a result.
GUARD_S = 300.0


def _distribution(folder: Path) -> Path:
    """A distribution that only declares the toy kind's module under the entry-point group."""
    info = folder / "toy_kind-1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: toy-kind\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[nonholonomic.kinds]\ntoy = tests.toy_kind\n")
    return folder


@pytest.fixture(scope="module")
def api(tmp_path_factory) -> Iterator[httpx.Client]:
    site = _distribution(tmp_path_factory.mktemp("site"))
    with embedded_api(tmp_path_factory.mktemp("logs"), {"PYTHONPATH": f"{site}:{ROOT}"}) as url, \
            httpx.Client(base_url=url, timeout=60) as client:
        yield client


def _succeeded(client: httpx.Client, body: dict) -> dict:
    r = client.post("/v1/jobs", json=body)
    assert r.status_code == 202, r.text
    job = poll_job(client, r.headers["location"], timeout=GUARD_S, interval=0.05)
    assert job["status"] == "succeeded", job
    return job


def test_the_catalog_lists_the_kind_with_its_record(api):
    entries = {e["kind"]: e for e in api.get("/v1/systems").json()["systems"]}
    toy = entries[KIND]
    assert toy["title"].startswith("Toy kind") and [p["kind"] for p in toy["potentials"]] == ["zero", "linear"]
    assert toy["potentials"][0]["levels"] == ["energy", "area"]  # the record's sampling plan
    assert "gamma uniform on the sphere" in toy["potentials"][0]["sampling"]
    assert toy["checks"] == entries["chaplygin_ball"]["checks"][:len(toy["checks"])]
    assert "bracket" not in toy["checks"]  # the record claims no Hamiltonian form
    assert api.get(f"/v1/systems/{KIND}").json()["kind"] == KIND


def test_a_job_conserves_its_integrals_and_matches_the_ball_at_D_0(api):
    toy, ball = (_succeeded(api, body)["result"] for body in (JOB, BALL))
    integrals = {i["name"]: i for i in toy["integrals"]}
    assert set(integrals) == {"energy", "geometric", "area"}
    assert all(i["max_rel_drift"] <= 1e-12 for i in integrals.values()), integrals
    # an independent definition of the same equations: the orbits agree to the integrators' tolerance
    for name in ("M", "gamma"):
        assert np.allclose(toy["trajectory"][name], ball["trajectory"][name], rtol=0, atol=1e-10)
    # div(rho f) = 0 with rho = 1, proven symbolically and at the samples
    assert {(c["name"], c["method"], c["passed"]) for c in toy["checks"]} == {
        ("invariant_measure", "symbolic", True), ("invariant_measure", "pointwise", True)}


def test_its_page_and_netcdf_export(api):
    job_id = _succeeded(api, JOB)["id"]
    page = api.get(f"/v1/jobs/{job_id}/page")
    assert page.status_code == 200 and "Toy kind: a rigid body about a fixed point" in page.text
    assert "U = (a, gamma)" in page.text
    import xarray as xr

    r = api.get(f"/v1/jobs/{job_id}/trajectory", params={"format": "netcdf"})
    assert r.status_code == 200, r.text
    ds = xr.open_dataset(r.content, engine="netcdf4").load()
    assert ds.sizes["t"] == 21 and ds["M1"].attrs["units"] == "kg m^2/s"
    assert ds["gamma3"].attrs["long_name"].startswith("unit vertical in the body frame")
    norm = np.sqrt(sum(ds[f"gamma{i}"].values ** 2 for i in (1, 2, 3)))
    assert np.max(np.abs(norm - 1.0)) <= 1e-12


def test_an_ensemble_sampled_on_its_level_set(api):
    body = {"system": JOB["system"], "members": {"sample": {"count": 3, "seed": 5, "level": {"energy": 1.5,
                                                                                               "area": 0.2}}},
            "t_final": 5.0, "samples": 2}
    r = api.post("/v1/ensembles", json=body)
    assert r.status_code == 202, r.text
    view = poll_job(api, r.headers["location"], timeout=GUARD_S, interval=0.05)
    assert view["status"] == "succeeded" and view["summary"]["succeeded"] == 3, view
    members = api.get(f"/v1/ensembles/{view['id']}/members").json()["members"]
    for member in members:
        level = {i["name"]: i["initial"] for i in member["integrals"]}
        assert level["energy"] == pytest.approx(1.5, abs=1e-12) and level["area"] == pytest.approx(0.2, abs=1e-12)


def test_bad_input_is_refused_naming_the_field(api):
    r = api.post("/v1/jobs", json={**JOB, "system": {**JOB["system"], "inertia": [-1.0, 2.0, 3.0]}})
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json"
    assert any(e["field"].startswith("system.inertia") for e in r.json()["errors"]), r.json()
    r = api.post("/v1/jobs", json={**JOB, "system": {**JOB["system"], "D": 0.7}})
    assert r.status_code == 422 and "system.D" in r.text
