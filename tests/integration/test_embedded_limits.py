"""Poison jobs in embedded mode (issue 19, items 3 and 11), with the API under uvicorn and real jobs:

* a job past its soft time limit fails with ``JobTimeout`` naming the limit and frees the one job
  thread, also when it is the job resumed after the API was killed: a small job submitted then runs;
* a Poincaré surface that is not smooth where the orbit meets it (``sqrt(gamma1)`` crossed at
  γ1 = 0, the audit's body) ends with a clear error instead of running forever;
* a job cancelled inside a long heyoka call (a Lyapunov spectrum whose one QR interval is the whole
  run) stops at once and frees the thread;
* no job holds the others (issue 34, item 4): an admissible but pathological job (M ~ 1e12, minutes of
  tiny steps) moves to the long lane and small jobs sent after it succeed while it runs; SIGKILLed twice
  under it, the service does not run it a third time but fails it as quarantined; a job cancelled while
  its integrator compiles gives its thread's place up within seconds.
"""

from __future__ import annotations

import signal
import time
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
#: The audit's pathological job: admissible, and its integration crawls (progress ~2e-8 a second) until its
#: time limit (600 s by default).
PATHOLOGICAL = {**BODY, "initial_state": {"M": [1e12, -1e12, 1e12], "gamma": [0.0, 0.6, 0.8]}, "t_final": 10.0}
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
    small = api.post(BODY)  # beside the resumed job once it moved to the long lane
    view = poll_job(api.client, small, timeout=GUARD_S + SOFT_S)
    assert view["status"] == "succeeded", view["error"]
    poisoned = poll_job(api.client, endless, timeout=GUARD_S + HARD_S)
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


def _small_job_beside(api: EmbeddedAPI, long_job: str) -> float:
    """Seconds a small job sent now took to succeed, while ``long_job`` ran all along."""
    sent = time.monotonic()
    view = poll_job(api.client, api.post(BODY), timeout=GUARD_S)
    waited = time.monotonic() - sent
    assert view["status"] == "succeeded", view["error"]
    assert api.client.get(long_job).json()["status"] == "running"  # it did not wait for the long job's end
    return waited


def test_a_pathological_job_holds_no_other_and_is_quarantined_after_two_interrupted_runs(api):
    long_job = api.post(PATHOLOGICAL)
    wait_until(lambda: api.client.get(long_job).json()["progress"] > 0, GUARD_S,
               "the pathological job to run (a hang guard)")
    waits = [_small_job_beside(api, long_job)]
    health = api.client.get("/health").json()["workers"]
    assert health["long_lane"]["running"] == 1 and health["long_lane"]["size"] == 2, health
    api.process.send_signal(signal.SIGKILL)
    api.process.wait(10)
    api.start()  # the pathological job is resumed once (its second start) ...
    wait_until(lambda: api.client.get(long_job).json()["progress"] > 0, GUARD_S, "its second run (a hang guard)")
    waits.append(_small_job_beside(api, long_job))
    api.process.send_signal(signal.SIGKILL)
    api.process.wait(10)
    api.start()  # ... and not a third time
    view = poll_job(api.client, long_job, timeout=GUARD_S)
    assert view["status"] == "failed" and view["error"]["type"] == "Quarantined", view
    assert "started 2 times" in view["error"]["message"]
    waits.append(time.monotonic())
    small = poll_job(api.client, api.post(BODY), timeout=GUARD_S)
    assert small["status"] == "succeeded", small["error"]
    print(f"small jobs beside the pathological one succeeded after {waits[0]:.1f} s and {waits[1]:.1f} s "
          f"(embedded_long_after_s 5 s); quarantined at the second restart")


def test_a_job_cancelled_while_its_integrator_compiles_gives_its_place_up(api):
    # a Lyapunov spectrum: its variational equations compile first (seconds of LLVM, no progress reports)
    compiling = api.post({**BODY, "t_final": 2e6, "lyapunov": {"interval": 2e6}})
    wait_until(lambda: api.client.get(compiling).json()["status"] == "running", GUARD_S,
               "the job to start (a hang guard)", interval=0.01)
    cancelled_at = time.monotonic()
    r = api.client.delete(compiling)
    assert r.status_code == 202 and r.json()["status"] == "cancelled"
    small = poll_job(api.client, api.post({**BODY, "t_final": 5.0}), timeout=GUARD_S)
    assert small["status"] == "succeeded", small["error"]
    assert api.client.get(compiling).json()["status"] == "cancelled"
    let_go = api.client.get("/health").json()["workers"]["let_go"]
    print(f"small job succeeded {time.monotonic() - cancelled_at:.1f} s after the cancel; threads let go "
          f"inside a compile: {let_go}")
