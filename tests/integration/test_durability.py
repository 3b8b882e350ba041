"""Durable jobs in embedded mode: the API killed (SIGKILL) or stopped (SIGTERM) and started again on
the same SQLite file loses no job and no result; jobs it had not finished run again."""

from __future__ import annotations

import signal
from pathlib import Path

import httpx
import pytest

from tests.support import free_port, poll_job, start_api, stop, wait_healthy, wait_until

pytestmark = pytest.mark.integration

BODY = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
        "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 20.0, "samples": 11}
#: About 5 s on one core: running (and one more queued behind it) when the API is stopped.
LONG = {**BODY, "t_final": 2e6}


def _api(port: int, data_dir: Path, log: Path):
    return start_api(port, log, {"REDIS_URL": "", "NONHOLONOMIC_WARM_UP": "false", "NONHOLONOMIC_MAX_T_FINAL": "1e9",
                                 "NONHOLONOMIC_DATA_DIR": str(data_dir)})


@pytest.mark.parametrize("how", [signal.SIGKILL, signal.SIGTERM])
def test_an_api_restart_loses_no_job_and_no_result(tmp_path, how):
    port, data = free_port(), tmp_path / "data"
    base = f"http://127.0.0.1:{port}"
    api = _api(port, data, tmp_path / "api-1.log")
    try:
        wait_healthy(base, timeout=60)
        with httpx.Client(base_url=base, timeout=10) as client:
            done = poll_job(client, client.post("/v1/jobs", json=BODY).headers["location"], timeout=60)
            assert done["status"] == "succeeded"
            running = client.post("/v1/jobs", json=LONG).headers["location"]
            queued = client.post("/v1/jobs", json=LONG).headers["location"]  # one thread: waits behind it
            cancelled = client.post("/v1/jobs", json=LONG).headers["location"]
            assert client.delete(cancelled).status_code == 202
            wait_until(lambda: client.get(running).json()["status"] == "running", 30, "the long job to run")
            assert client.get(queued).json()["status"] == "queued"
        api.send_signal(how)
        api.wait(30)
    finally:
        stop(api)

    api = _api(port, data, tmp_path / "api-2.log")
    try:
        wait_healthy(base, timeout=60)
        with httpx.Client(base_url=base, timeout=10) as client:
            again = client.get(f"/v1/jobs/{done['id']}").json()
            assert again == done  # the same record and result, bit for bit
            for location in (running, queued):  # run again after the restart
                view = poll_job(client, location, timeout=120)
                assert view["status"] == "succeeded", view["error"]
            assert client.get(cancelled).json()["status"] == "cancelled"
            listed = {item["location"] for item in client.get("/v1/jobs").json()["items"]}
            assert {f"/v1/jobs/{done['id']}", running, queued, cancelled} <= listed
    except Exception:
        print((tmp_path / "api-1.log").read_text()[-3000:], (tmp_path / "api-2.log").read_text()[-3000:])
        raise
    finally:
        stop(api)
