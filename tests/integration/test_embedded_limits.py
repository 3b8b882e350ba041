"""Poison jobs in embedded mode (issue 19, items 3 and 11), with the API under uvicorn and real jobs:

* a job past its soft time limit fails with ``JobTimeout`` naming the limit and frees the one job
  thread, also when it is the job resumed after the API was killed: a small job submitted then runs;
* a Poincaré surface that is not smooth where the orbit meets it (``sqrt(gamma1)`` crossed at
  γ1 = 0, the audit's body) ends with a clear error instead of running forever;
* a job cancelled inside a long heyoka call (a Lyapunov spectrum whose one QR interval is the whole
  run) stops at once and frees the thread.
"""

from __future__ import annotations

import signal
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.support import free_port, poll_job, start_api, stop, wait_healthy, wait_until

pytestmark = pytest.mark.integration

BODY = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
        "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 20.0, "samples": 11}
#: Thousands of seconds of integration: it ends only by its time limit or a cancellation.
ENDLESS = {**BODY, "t_final": 1e9}
#: Soft and hard limits of these tests (the soft one well above a first job's compile on a busy machine).
SOFT_S, HARD_S = 8, 16
#: Hang guard (seconds) of each wait (an API's start, a small job, a job's first compile): far above the
#: few seconds each needs on a quiet machine, never a result.
GUARD_S = 300.0


class EmbeddedAPI:
    """The API in embedded mode on a SQLite file of its own, started again on the same file."""

    def __init__(self, tmp: Path, limits: dict[str, str]) -> None:
        self.tmp, self.port, self.starts, self.limits = tmp, free_port(), 0, limits
        self.base = f"http://127.0.0.1:{self.port}"
        self.client = httpx.Client(base_url=self.base, timeout=10)
        self.process = None

    def start(self) -> None:
        self.starts += 1
        self.process = start_api(self.port, self.tmp / f"api-{self.starts}.log", {
            "REDIS_URL": "", "NONHOLONOMIC_WARM_UP": "false", "NONHOLONOMIC_MAX_T_FINAL": "1e9",
            "NONHOLONOMIC_DATA_DIR": str(self.tmp / "data"), **self.limits})
        wait_healthy(self.base, timeout=GUARD_S)

    def post(self, body: dict) -> str:
        r = self.client.post("/v1/jobs", json=body)
        assert r.status_code == 202, r.text
        return r.headers["location"]

    def logs(self) -> str:
        return "\n".join(f"--- {p.name}\n{p.read_text()[-3000:]}" for p in sorted(self.tmp.glob("api-*.log")))


@pytest.fixture()
def api(request, tmp_path) -> Iterator[EmbeddedAPI]:
    short = "time_limit" in request.node.name  # the others keep the default limits (minutes)
    a = EmbeddedAPI(tmp_path, {"NONHOLONOMIC_JOB_SOFT_TIME_LIMIT_S": str(SOFT_S),
                               "NONHOLONOMIC_JOB_TIME_LIMIT_S": str(HARD_S)} if short else {})
    a.start()
    try:
        yield a
    except Exception:
        print(a.logs())
        raise
    finally:
        if a.process is not None:
            stop(a.process)
        a.client.close()


def test_a_job_past_its_time_limit_frees_the_thread_also_after_a_restart(api):
    endless = api.post(ENDLESS)
    wait_until(lambda: api.client.get(endless).json()["progress"] > 0, GUARD_S, "the endless job to run (a hang guard)")
    api.process.send_signal(signal.SIGKILL)  # the audit: the poison job is resumed by the next start
    api.process.wait(10)
    api.start()
    small = api.post(BODY)  # behind the resumed job, on the one thread
    view = poll_job(api.client, small, timeout=GUARD_S + SOFT_S)
    assert view["status"] == "succeeded", view["error"]
    poisoned = api.client.get(endless).json()
    assert poisoned["status"] == "failed"
    assert poisoned["error"] == {"type": "JobTimeout", "message": f"the job exceeded its time limit of {SOFT_S} s"}


def test_a_surface_not_smooth_where_the_orbit_meets_it_ends_the_job_clearly(api):
    for surface in ("sqrt(gamma1)", "sqrt(gamma1 + 0.3)"):  # at t = 0 (the audit's body), at t ~ 29.5
        r = api.client.post("/v1/jobs", json={**BODY, "t_final": 100.0, "poincare": {"surface": surface}})
        if r.status_code == 422:  # refused up front is as good (the field named)
            assert any(e["field"] == "poincare.surface" for e in r.json()["errors"]), r.text
            continue
        assert r.status_code == 202, r.text
        view = poll_job(api.client, r.headers["location"], timeout=GUARD_S)
        assert view["status"] == "failed", surface
        assert view["error"]["type"] == "IntegrationError"
        assert "the surface is not finite or not smooth where the orbit meets it" in view["error"]["message"]
    view = poll_job(api.client, api.post(BODY), timeout=GUARD_S)
    assert view["status"] == "succeeded", view["error"]


def test_cancelling_a_job_inside_a_long_heyoka_call_stops_it_and_frees_the_thread(api):
    # One QR interval spanning the whole run: one long propagation, minutes of variational equations.
    body = {**BODY, "t_final": 2e6, "lyapunov": {"interval": 2e6}}
    location = api.post(body)
    # inside the spectrum's propagation: the second half of the job, past 0.5 once its first piece reported
    # (the variational equations compiled)
    wait_until(lambda: api.client.get(location).json()["progress"] > 0.5, GUARD_S,
               "the spectrum's propagation (a hang guard)")
    r = api.client.delete(location)
    assert r.status_code == 202 and r.json()["status"] == "cancelled"
    # The one job thread runs a small job once the cancelled one let go of it. Meanwhile the cancelled
    # job's progress is written at most once more (the report that sees the cancellation), then its thread
    # leaves: it did not run on through the spectrum.
    small = api.post(BODY)
    seen: list[float] = []

    def small_ended() -> bool:
        seen.append(api.client.get(location).json()["progress"])
        assert len(set(seen) - {r.json()["progress"]}) <= 2, seen
        return api.client.get(small).json()["status"] in ("succeeded", "failed", "cancelled")

    wait_until(small_ended, GUARD_S, "the small job behind the cancelled one (a hang guard)", interval=0.01)
    view = api.client.get(small).json()
    assert view["status"] == "succeeded", view["error"]
    assert api.client.get(location).json()["status"] == "cancelled"
