"""The Python client and the ``nonholonomic`` command line against a real API process (embedded mode).

One uvicorn process for the module (no Redis, no warm-up); the command line runs as the installed
console script in subprocesses, exactly as a user runs it.
"""

from __future__ import annotations

import csv
import io
import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from nonholonomic_client import ApiError, Client
from tests.support import embedded_api, free_port

pytestmark = pytest.mark.integration

CLI = str(Path(sys.executable).parent / "nonholonomic")
#: The README's first job, shortened (t_final 20, 51 samples).
BALL = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7,
                   "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}},
        "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]},
        "t_final": 20.0, "samples": 51, "checks": ["integrals", "measure"]}
BAD = {**BALL, "system": {**BALL["system"], "inertia": [-1.0, 2.0, 3.0]}}
#: The README's ensemble, 4 members on a shorter horizon.
ENSEMBLE = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
            "members": {"sample": {"count": 4, "seed": 1, "level": {"energy": 1.0, "area": 0.0}}},
            "t_final": 100.0, "poincare": {"surface": "gamma3", "coordinates": ["gamma1", "gamma2"]},
            "lyapunov": {"count": 1}}
#: Two claims of the paper report that take a few seconds in a fresh process.
CLAIMS = ["veselova.multiplier", "ball.theorem_3"]


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Iterator[str]:
    with embedded_api(tmp_path_factory.mktemp("client-api")) as url:
        yield url


@pytest.fixture(scope="module")
def api(base) -> Iterator[Client]:
    with Client(base) as client:
        yield client


@pytest.fixture(scope="module")
def ball_job(api) -> tuple[str, dict, list[tuple[float, str]]]:
    """The ball job, submitted and waited for with a progress callback that records its calls."""
    calls: list[tuple[float, str]] = []
    job_id = api.submit(BALL)
    view = api.wait(job_id, timeout=120, poll=0.05, progress=lambda f, s: calls.append((f, s)))
    return job_id, view, calls


def _cli(base: str, *args: str, stdin: str | None = None, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([CLI, "--url", base, *args], input=stdin, capture_output=True, text=True, timeout=120,
                          cwd=cwd, check=False)


def test_health_and_catalog(api):
    assert api.health()["mode"] == "embedded"
    kinds = [s["kind"] for s in api.systems()["systems"]]
    assert "chaplygin_ball" in kinds
    assert api.system("veselova")["kind"] == "veselova"


def test_wait_reports_progress_and_the_result_is_the_job_s(api, ball_job):
    job_id, view, calls = ball_job
    assert view["status"] == "succeeded" and view["id"] == job_id
    assert len(calls) >= 1 and calls[-1] == (1.0, "succeeded")
    assert all(0.0 <= f <= 1.0 for f, _ in calls)
    result = api.result(job_id)
    assert result["final_state"] == view["result"]["final_state"]
    assert result["t_final"] == 20.0 and len(result["trajectory"]["t"]) == 51
    assert all(i["passed"] for i in result["integrals"]) and all(c["passed"] for c in result["checks"])


def test_the_job_list_has_the_job_and_pages_through_the_cursor(api, ball_job):
    job_id, _, _ = ball_job
    first = api.jobs(status="succeeded", limit=1)
    assert len(first["items"]) <= 1
    seen = [item["id"] for item in first["items"]]
    cursor = first["next_cursor"]
    while cursor:
        page = api.jobs(status="succeeded", limit=1, cursor=cursor)
        seen += [item["id"] for item in page["items"]]
        cursor = page["next_cursor"]
    assert job_id in seen and len(seen) == len(set(seen))


def test_csv_npz_and_json_trajectories_end_in_the_final_state(api, ball_job, tmp_path):
    job_id, view, _ = ball_job
    result = view["result"]
    final = result["final_state"]
    text = api.trajectory(job_id, "csv").decode()
    rows = list(csv.reader(io.StringIO(text)))
    header = rows[0]
    assert header[0] == "t [s]" and header[1].startswith("tau [") and len(rows) == 51 + 1
    last = dict(zip([h.split(" [")[0] for h in header], map(float, rows[-1]), strict=True))
    assert abs(last["t"] - result["t_final"]) <= 1e-12 and abs(last["tau"] - result["tau_final"]) <= 1e-12
    for name, vector in final.items():
        assert np.max(np.abs(np.array([last[f"{name}{k}"] for k in (1, 2, 3)]) - vector)) <= 1e-12

    streamed = api.trajectory(job_id, "csv", out=tmp_path / "traj.csv")
    assert streamed == tmp_path / "traj.csv" and streamed.read_text() == text
    assert not list(tmp_path.glob("*.part"))

    path = api.trajectory(job_id, "npz", out=tmp_path / "traj.npz")
    with np.load(path) as npz:
        assert npz["t"].shape == (51,) and npz["t"][-1] == result["t_final"]
        for name, vector in final.items():
            assert np.max(np.abs(npz[name][-1] - vector)) <= 1e-12
    with np.load(io.BytesIO(api.trajectory(job_id, "npz"))) as npz:
        assert np.array_equal(npz["gamma"], result["trajectory"]["gamma"])

    data = api.trajectory(job_id)
    assert data["units"]["t"] == "s" and np.allclose(data["M"][-1], final["M"], rtol=0, atol=1e-12)


def test_an_invalid_request_raises_the_problem(api):
    with pytest.raises(ApiError) as caught:
        api.submit(BAD)
    err = caught.value
    assert err.status == 422 and err.type == "/problems/invalid-request" and err.title == "Invalid request"
    assert [e["field"] for e in err.errors] == ["system.inertia[0]"]
    assert str(err).startswith("422 Invalid request: system.inertia[0]: ")
    assert err.problem["instance"] == "/v1/jobs"


def test_unknown_job_and_conflicts_raise_api_errors(api, ball_job, tmp_path):
    with pytest.raises(ApiError) as caught:
        api.job("no-such-job")
    assert caught.value.status == 404 and caught.value.type == "/problems/not-found"
    with pytest.raises(ApiError) as caught:
        api.trajectory("no-such-job", "csv", out=tmp_path / "never.csv")
    assert caught.value.status == 404 and not list(tmp_path.iterdir())
    with pytest.raises(ApiError) as caught:
        api.cancel(ball_job[0])  # already succeeded
    assert caught.value.status == 409


def test_a_closed_port_is_an_api_error_with_status_0():
    url = f"http://127.0.0.1:{free_port()}"
    with Client(url, timeout=5) as client, pytest.raises(ApiError) as caught:
        client.systems()
    assert caught.value.status == 0 and caught.value.unreachable
    assert caught.value.detail.startswith(f"cannot reach {url}/v1/systems: ")


def test_an_ensemble_of_four_members(api):
    ensemble_id = api.submit_ensemble(ENSEMBLE)
    calls: list[tuple[float, str]] = []
    view = api.wait_ensemble(ensemble_id, timeout=120, progress=lambda f, s: calls.append((f, s)))
    assert view["status"] == "succeeded" and calls[-1] == (1.0, "succeeded")
    assert view["summary"]["succeeded"] == 4 and view["summary"]["largest_exponent"]["count"] == 4
    page = api.members(ensemble_id)
    assert page["total"] == 4 and [m["index"] for m in page["members"]] == [0, 1, 2, 3]
    assert all(m["status"] == "succeeded" for m in page["members"])
    assert len(api.members(ensemble_id, offset=2, limit=1)["members"]) == 1
    rows = list(csv.reader(io.StringIO(api.section(ensemble_id).decode())))
    assert rows[0][0] == "member" and len(rows) - 1 == view["summary"]["section_points"]["total"]


def test_cli_systems_lists_the_kinds(base):
    done = _cli(base, "systems")
    assert done.returncode == 0, done.stderr
    assert "chaplygin_ball" in done.stdout and "M, gamma" in done.stdout
    generalized = [line.split() for line in done.stdout.splitlines() if line.startswith("generalized_chaplygin ")]
    assert generalized and generalized[0][1:3] == ["q,", "q_dot"]  # the user-written kind, its own entry's shape
    raw = _cli(base, "systems", "--json")
    assert raw.returncode == 0 and "chaplygin_ball" in [s["kind"] for s in json.loads(raw.stdout)["systems"]]


def test_cli_ensemble_writes_a_chaos_maps_cells(base, tmp_path):
    spec = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7}, "t_final": 50.0,
            "indicators": ["megno"], "members": {"grid": {"surface": "gamma3", "coordinates": ["gamma1", "M3"],
                                                          "level": {"energy": 2.0, "area": 0.0}, "shape": [6, 5]}}}
    (tmp_path / "map.json").write_text(json.dumps(spec))
    done = _cli(base, "ensemble", "map.json", "--out", "map.csv", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "map 30 cells:" in done.stdout and "chaotic fraction" in done.stdout and "map written to" in done.stdout
    rows = list(csv.reader(io.StringIO((tmp_path / "map.csv").read_text())))
    assert rows[0][:5] == ["i", "j", "gamma1 [1]", "M3 [kg m^2/s]", "status"] and len(rows) == 31
    wrong = _cli(base, "ensemble", "map.json", "--out", "map.npz", cwd=tmp_path)
    assert wrong.returncode == 2 and ".csv, .nc" in wrong.stderr


def test_cli_run_writes_the_trajectory(base, tmp_path):
    (tmp_path / "spec.json").write_text(json.dumps(BALL))
    done = _cli(base, "run", "spec.json", "--out", "traj.csv", "--result", "result.json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "succeeded" in done.stdout and "energy" in done.stdout and "max_rel_drift" in done.stdout
    assert "100%" in done.stderr  # the progress bar (lines, stderr is not a terminal)
    rows = (tmp_path / "traj.csv").read_text().splitlines()
    assert len(rows) == BALL["samples"] + 1 and rows[0].startswith("t [s],tau [")
    result = json.loads((tmp_path / "result.json").read_text())
    assert [float(x) for x in rows[-1].split(",")[2:5]] == result["final_state"]["M"]


def test_cli_run_reads_stdin_without_waiting(base):
    done = _cli(base, "run", "-", stdin=json.dumps(BALL))
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("job ") and f"location {base}/v1/jobs/" in done.stdout


def test_cli_invalid_request_exits_2_naming_the_field(base, tmp_path):
    (tmp_path / "bad.json").write_text(json.dumps(BAD))
    done = _cli(base, "run", str(tmp_path / "bad.json"))
    assert done.returncode == 2
    assert "error: Invalid request\n" in done.stderr and done.stderr.count("system.inertia[0]: ") == 1
    assert "Traceback" not in done.stderr


def test_cli_spec_that_is_not_json_exits_2(base, tmp_path):
    (tmp_path / "broken.json").write_text('{"system": {"kind": "chaplygin_ball",}}')
    done = _cli(base, "run", str(tmp_path / "broken.json"))
    assert done.returncode == 2 and "is not JSON" in done.stderr and "line 1 column 38" in done.stderr
    assert "Traceback" not in done.stderr


def test_cli_unreachable_service_exits_3(tmp_path):
    (tmp_path / "spec.json").write_text(json.dumps(BALL))
    done = _cli(f"http://127.0.0.1:{free_port()}", "run", str(tmp_path / "spec.json"), "--wait")
    assert done.returncode == 3 and "cannot reach http://127.0.0.1:" in done.stderr
    assert "Traceback" not in done.stderr


def test_cli_report_saves_the_page(base, api, tmp_path):
    assert set(CLAIMS) <= set(api.paper_claims())
    done = _cli(base, "report", "--claims", ",".join(CLAIMS), "--out", str(tmp_path / "r.html"))
    assert done.returncode == 0, done.stderr
    assert "holds after correction 2" in done.stdout
    assert "Paper report" in (tmp_path / "r.html").read_text()


def test_the_client_lists_ensembles_and_finds_one_by_its_first_characters(api):
    """Issue 35, item 1: after a crash the progress bar's 8 characters are enough."""
    ensemble_id = api.submit_ensemble(ENSEMBLE)
    api.wait_ensemble(ensemble_id, timeout=120)
    page = api.ensembles(limit=5)
    assert page["items"][0]["id"] == ensemble_id and page["items"][0]["members"] == 4
    assert api.ensemble(ensemble_id[:8])["id"] == ensemble_id
    assert api.members(ensemble_id[:8])["total"] == 4


def test_cli_lists_jobs_and_ensembles_with_whole_ids(base, api, ball_job):
    ensemble_id = api.submit_ensemble(ENSEMBLE)
    api.wait_ensemble(ensemble_id, timeout=120)
    done = _cli(base, "list", "ensembles", "--limit", "3")
    assert done.returncode == 0, done.stderr
    header, first = done.stdout.splitlines()[:2]
    assert header.split()[:3] == ["ID", "STATUS", "MEMBERS"] and first.split()[:3] == [ensemble_id, "succeeded", "4/4"]
    jobs = _cli(base, "list", "jobs", "--status", "succeeded")
    assert jobs.returncode == 0 and ball_job[0] in jobs.stdout, jobs.stdout


def test_a_sweeps_and_a_maps_members_table_carries_what_varies(api):
    """Issue 35, item 2: lambda_1 against D, or a map's cells, straight from the members table (no join)."""
    sweep = api.submit_ensemble({"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
                                 "members": {"sweep": {"parameter": "D", "values": [0.1, 0.4, 0.9],
                                                       "initial_state": {"M": [0.5, -0.2, 0.1],
                                                                         "gamma": [0.0, 0.6, 0.8]}}},
                                 "t_final": 5.0, "samples": 3, "lyapunov": {"count": 1}})
    api.wait_ensemble(sweep, timeout=120)
    table = api.members(sweep, format="pandas")
    assert list(table.columns[:2]) == ["status", "D"] and table["D"].tolist() == [0.1, 0.4, 0.9]
    assert table["exponent_1"].notna().all()
    chaos_map = api.submit_ensemble({"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
                                     "t_final": 5.0, "indicators": ["megno"],
                                     "members": {"grid": {"surface": "gamma3", "coordinates": ["gamma1", "M3"],
                                                          "level": {"energy": 2.0, "area": 0.0}, "shape": [2, 3]}}})
    api.wait_ensemble(chaos_map, timeout=120)
    cells = api.members(chaos_map, format="pandas")
    assert list(cells.columns[1:6]) == ["cell_i", "cell_j", "gamma1", "M3", "branches"]
    assert [(int(i), int(j)) for i, j in zip(cells["cell_i"], cells["cell_j"])] == [(k // 3, k % 3) for k in range(6)]
    assert cells["gamma1"].nunique() == 2 and cells["M3"].nunique() == 3  # two rows of cells, three columns


def test_a_periodic_orbit_and_its_continuation_as_a_table(base, api, ball_job, tmp_path):
    """Issue 35, item 4: the branch through its period doubling, one row per value, flagged where it happened."""
    from tests.api.test_periodic_orbits_api import LINEAR, SEED

    job_id = api.submit({"system": LINEAR, "initial_state": SEED, "t_final": 50.0, "samples": 11,
                         "project_initial_state": True,
                         "periodic_orbit": {"surface": "gamma3", "coordinates": ["gamma1", "M3"],
                                            "sweep": {"parameter": "potential.a[2]", "values": [0.7, 0.8, 0.9, 1.0]},
                                            "branch": {"in": "potential.a[2]", "to": 0.9, "switch_points": 3}}})
    api.wait(job_id, timeout=300)
    branch = api.periodic_orbit(job_id)
    assert branch.index.name == "potential.a[2]" and branch.index.tolist() == [0.7, 0.8, 0.9, 1.0]
    assert branch["status"].tolist() == ["found"] * 4 and branch["checks_passed"].all()
    assert branch["period_doubling"].tolist() == [False, False, True, False] and not branch["fold"].any()
    orbit = api.periodic_orbit(job_id, format="json")
    first = orbit["continuation"]["points"][0]
    assert branch["period_t"].iloc[0] == first["period_t"] and branch["trace"].iloc[0] == first["trace"]
    assert branch["multiplier_1_modulus"].iloc[0] == first["section_multipliers"][0]["modulus"]
    assert branch.attrs["orbit"]["stability"] == "elliptic" and branch.attrs["events"][0]["kind"] == "period_doubling"
    with pytest.raises(ApiError) as caught:
        api.periodic_orbit(ball_job[0])
    assert "asked for no periodic orbit" in caught.value.detail
    # issue 36: the same job's branch (pseudo-arclength) as the server's table, its bifurcation where the sweep saw it
    table = api.branch(job_id)
    value = "potential.a[2] [kg m^2/s^2]"
    [doubling] = table[table.kind == "period_doubling"][value].tolist()
    assert 0.8 < doubling < 0.9 and table.attrs["status"] == "reached" and table.attrs["bifurcations"][0]["located"]
    assert table.loc[table.branch == 1, "period"].eq(2).all() and (table.branch == 1).sum() == 3
    assert table.loc[table.kind == "point", "residual"].max() < 1e-9
    raw = api.branch(job_id, format="json")
    assert table[value].iloc[0] == raw["points"][0]["value"] and raw["switched"][0]["period"] == 2
    with pytest.raises(ApiError) as caught:
        api.branch(ball_job[0])
    assert caught.value.status == 409
    done = _cli(base, "get", job_id[:8], "--what", "branch", "--out", "branch.nc", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    import xarray

    with xarray.open_dataset(tmp_path / "branch.nc", engine="netcdf4") as ds:
        assert ds.sizes["row"] == len(table) and ds.attrs["branch_status"] == "reached"


def test_cli_get_saves_an_existing_jobs_and_ensembles_results(base, api, ball_job, tmp_path):
    """Issue 35, item 3: results fetched again later, by id or its first characters, in the suffix's format."""
    job_id = ball_job[0]
    done = _cli(base, "get", job_id[:8], "--out", "traj.nc", cwd=tmp_path)
    assert done.returncode == 0 and f"job {job_id}: trajectory written to traj.nc" in done.stdout, done.stderr
    assert (tmp_path / "traj.nc").read_bytes()[:4] == b"\x89HDF"  # NetCDF-4 is HDF5
    done = _cli(base, "get", job_id, "--what", "result", "--out", "result.json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "result.json").read_text())["final_state"] == ball_job[1]["result"]["final_state"]
    ensemble_id = api.submit_ensemble(ENSEMBLE)
    api.wait_ensemble(ensemble_id, timeout=120)
    done = _cli(base, "get", ensemble_id, "--out", "section.csv", cwd=tmp_path)
    assert done.returncode == 0 and "section written" in done.stdout, done.stderr
    rows = list(csv.reader(io.StringIO((tmp_path / "section.csv").read_text())))
    assert rows[0][0] == "member" and len(rows) > 1
    wrong = _cli(base, "get", ensemble_id, "--out", "x.json", cwd=tmp_path)
    assert wrong.returncode == 2 and ".csv, .npz, .nc" in wrong.stderr, wrong.stderr
    # the members table (issue 35, item 2): CSV with the same numbers as the client's JSON, and NetCDF
    done = _cli(base, "get", ensemble_id[:8], "--what", "members", "--out", "members.csv", cwd=tmp_path)
    assert done.returncode == 0 and "members written to members.csv" in done.stdout, done.stderr
    table = list(csv.DictReader(io.StringIO((tmp_path / "members.csv").read_text())))
    members = api.members(ensemble_id)["members"]
    assert [int(r["member"]) for r in table] == [m["index"] for m in members]
    column = next(c for c in table[0] if c.startswith("final_M1"))
    assert [float(r[column]) for r in table] == [m["final_state"]["M"][0] for m in members]
    done = _cli(base, "get", ensemble_id, "--what", "members", "--out", "members.nc", cwd=tmp_path)
    assert done.returncode == 0 and (tmp_path / "members.nc").read_bytes()[:4] == b"\x89HDF", done.stderr
