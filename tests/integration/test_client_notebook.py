"""The client as a researcher uses it in a notebook: results as xarray and pandas objects equal to the
JSON bit for bit, a progress bar in simulated time (the client installed alone, running the tutorials:
tests/integration/test_tutorials.py).

One embedded API process for the module (no Redis).
"""

from __future__ import annotations

import json
from collections.abc import Iterator

import numpy as np
import pytest

from nonholonomic_client import Client
from tests.support import embedded_api

pytestmark = pytest.mark.integration

#: A section and a spectrum of the ball in a linear potential (docs/sections-ensembles.md), shortened.
JOB = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7,
                  "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}},
       "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 100.0, "samples": 501,
       "poincare": {"surface": "gamma3", "value": 0.0, "direction": "increasing", "coordinates": ["gamma1", "M3"]},
       "lyapunov": {"interval": 1.0}}
ENSEMBLE = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
            "members": {"sample": {"count": 5, "seed": 3, "level": {"energy": 1.0, "area": 0.0}}},
            "t_final": 60.0, "poincare": {"surface": "gamma3", "coordinates": ["M1", "M2"]},
            "lyapunov": {"count": 2}}

@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Iterator[str]:
    with embedded_api(tmp_path_factory.mktemp("notebook-api")) as url:
        yield url


@pytest.fixture(scope="module")
def api(base) -> Iterator[Client]:
    with Client(base, timeout=60) as client:
        yield client


@pytest.fixture(scope="module")
def job(api) -> str:
    job_id = api.submit(JOB)
    api.wait(job_id, timeout=180, poll=0.05, trajectory=False)
    return job_id


@pytest.fixture(scope="module")
def ensemble(api) -> str:
    ensemble_id = api.submit_ensemble(ENSEMBLE)
    api.wait_ensemble(ensemble_id, timeout=180, poll=0.05)
    return ensemble_id


def test_a_trajectory_as_an_xarray_dataset_equals_the_json_bit_for_bit(api, job):
    samples = api.trajectory(job)  # the JSON
    ds = api.trajectory(job, format="xarray")
    assert ds.sizes == {"t": 501} and np.array_equal(ds["t"].values, np.asarray(samples["t"]))
    assert np.array_equal(ds["tau"].values, np.asarray(samples["tau"]))
    for vector in ("M", "gamma", "omega"):
        values = np.asarray(samples[vector])
        for k in range(3):
            assert np.array_equal(ds[f"{vector}{k + 1}"].values, values[:, k]), f"{vector}{k + 1}"
            assert ds[f"{vector}{k + 1}"].attrs["units"] == samples["units"][vector]
    assert ds["t"].attrs["units"] == "s" and ds["tau"].attrs["units"] == samples["units"]["tau"]
    assert json.loads(ds.attrs["request"])["t_final"] == 100.0 and ds.attrs["job"] == job
    evidence = json.loads(ds.attrs["evidence"])
    assert evidence["integrals"]["energy"]["passed"] and evidence["integrals"]["energy"]["max_rel_drift"] < 1e-13
    assert "heyoka" in json.loads(ds.attrs["versions"])
    # The invariants hold in the arrays themselves: |gamma| = 1 to round-off at every sample.
    norm = np.sqrt(ds["gamma1"] ** 2 + ds["gamma2"] ** 2 + ds["gamma3"] ** 2)
    assert float(abs(norm - 1).max()) < 1e-13


def test_a_trajectory_as_a_dataframe_indexed_by_t(api, job):
    samples = api.trajectory(job)
    frame = api.trajectory(job, format="pandas")
    assert frame.index.name == "t" and list(frame.columns[:4]) == ["tau", "M1", "M2", "M3"]
    assert np.array_equal(frame.index.to_numpy(), np.asarray(samples["t"]))
    assert np.array_equal(frame["gamma3"].to_numpy(), np.asarray(samples["gamma"])[:, 2])
    assert frame.attrs["units"]["M"] == samples["units"]["M"]


def test_the_netcdf_files_read_back_to_the_same_numbers_as_the_arrays(api, job, ensemble):
    import xarray as xr

    ds = api.trajectory(job, format="xarray")
    stored = xr.open_dataset(api.trajectory(job, format="netcdf"), engine="netcdf4").load()
    assert stored.attrs["Conventions"].startswith("CF-") and stored["M1"].attrs["units"] == ds["M1"].attrs["units"]
    for name in ("tau", "M1", "gamma3", "omega2"):
        assert np.array_equal(stored[name].values, ds[name].values), name
    section = api.section(job, format="pandas")
    crossings = xr.open_dataset(api.section(job, format="netcdf"), engine="netcdf4").load()
    assert np.array_equal(crossings["t"].values, section["t"].to_numpy())
    assert np.array_equal(crossings["M3"].values, section["M3"].to_numpy())
    members = api.section(ensemble, format="pandas")
    every = xr.open_dataset(api.section(ensemble, format="netcdf", of="ensemble"), engine="netcdf4").load()
    assert np.array_equal(every["member"].values, members["member"].to_numpy())
    assert np.array_equal(every["M2"].values, members["M2"].to_numpy())


def test_a_jobs_section_as_a_table_one_row_per_crossing(api, job):
    section = api.section(job, format="json")
    frame = api.section(job, format="pandas")
    assert len(frame) == section["count"] > 5 and "member" not in frame.columns
    assert np.array_equal(frame["t"].to_numpy(), np.asarray(section["t"]))
    assert np.array_equal(frame["M3"].to_numpy(), np.asarray(section["points"]["M"])[:, 2])
    assert float(frame["gamma3"].abs().max()) <= 1e-13  # on the surface gamma3 = 0
    assert frame.attrs["surface"] == "gamma3" and frame.attrs["units"]["t"] == "s"


def test_an_ensembles_section_members_and_exponents_as_tables(api, ensemble):
    members = api.members(ensemble, format="pandas")
    assert list(members.index) == [0, 1, 2, 3, 4] and set(members["status"]) == {"succeeded"}
    assert members["drift_energy"].max() < 1e-12 and {"exponent_1", "exponent_2"} <= set(members.columns)
    pages = api.members(ensemble, limit=5)["members"]
    for m in pages:
        assert members.loc[m["index"], "final_M2"] == m["final_state"]["M"][1]
        assert members.loc[m["index"], "exponent_1"] == m["lyapunov"]["exponents"][0]
    section = api.section(ensemble, format="pandas")
    assert list(section.columns[:3]) == ["member", "t", "tau"]
    assert len(section) == sum(m["poincare"]["count"] for m in pages)
    for m in pages:  # the NPZ's numbers are the members' JSON numbers
        rows = section[section["member"] == m["index"]]
        assert np.array_equal(rows["t"].to_numpy(), np.asarray(m["poincare"]["t"]))
        assert np.array_equal(rows["M1"].to_numpy(), np.asarray(m["poincare"]["points"]["M"])[:, 0])
    exponents = api.exponents(ensemble)
    assert list(exponents.columns) == ["status", "exponent_1", "exponent_2"]
    assert (exponents["exponent_1"] >= exponents["exponent_2"]).all()


def test_a_chaos_map_as_an_xarray_dataset_equals_the_json_bit_for_bit(api):
    body = {"system": JOB["system"], "t_final": 100.0, "indicators": ["megno", "lyapunov"],
            "members": {"grid": {"surface": "gamma3", "coordinates": ["gamma1", "M3"],
                                 "level": {"energy": 2.0, "area": 0.0}, "shape": [9, 7]}}}
    ensemble_id = api.submit_ensemble(body)
    api.wait_ensemble(ensemble_id, timeout=180, poll=0.05)
    data = api.chaos_map(ensemble_id, format="json")
    ds = api.chaos_map(ensemble_id)
    assert ds["megno"].dims == ("gamma1", "M3") and ds.sizes == {"gamma1": 9, "M3": 7}
    assert ds["M3"].attrs["units"] == "kg m^2/s"
    megno = np.array([[np.nan if v is None else v for v in row] for row in data["indicators"]["megno"]])
    assert np.array_equal(ds["megno"].values, megno, equal_nan=True)
    assert ds["status"].values.tolist() == data["status"]
    assert json.loads(ds.attrs["summary"]) == data["summary"] and ds.attrs["chaotic_fraction"] == \
        data["summary"]["chaotic_fraction"]
    assert api.chaos_map(ensemble_id, format="csv").startswith(b"i,j,gamma1 [1],M3 [kg m^2/s],status")


def test_a_jobs_spectrum_and_its_convergence(api, job):
    lyapunov = api.exponents(job, format="json")
    spectrum = api.exponents(job)
    assert np.array_equal(spectrum["exponent"].to_numpy(), np.asarray(lyapunov["all_exponents"]))
    assert spectrum["expected_zero"].sum() == lyapunov["zero_count"]
    # The measure: the spectrum sums to the time average of div f (the test of eq. 2604-3 in numbers).
    assert abs(spectrum["exponent"].sum() - lyapunov["divergence_average"]) < 1e-6
    running = api.convergence(job)
    assert running.index.name == "t" and running.shape == (len(lyapunov["convergence_t"]), 6)
    assert np.array_equal(running.iloc[-1].to_numpy(), np.asarray(lyapunov["convergence"][-1]))


def test_wait_with_progress_draws_a_bar_in_simulated_seconds(api, capsys):
    job_id = api.submit({**JOB, "t_final": 50.0, "poincare": None, "lyapunov": None})
    view = api.wait(job_id, progress=True, timeout=120, poll=0.05, trajectory=False)
    assert view["status"] == "succeeded"
    err = capsys.readouterr().err
    last = err.replace("\r", "\n").strip().splitlines()[-1]
    assert job_id[:8] in last and "50/50 s" in last and "succeeded" in last, err[-500:]
