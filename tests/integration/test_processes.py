"""The real thing: the API under uvicorn, a Celery worker process, Redis; and embedded mode likewise.

Needs Redis on 127.0.0.1:6379 (the README's test command starts one). Uses Redis DB 13 (emptied before
and after), a queue and a job store of its own, so neither a running deployment nor the other test files
are disturbed.
"""

from __future__ import annotations

import os
import re
import uuid
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest
import redis
from celery import Celery

from tests.reference import ball_reference
from tests.support import (
    free_port,
    poll_job,
    queue_database_url,
    redis_available,
    start_api,
    start_worker,
    stop,
    wait_healthy,
    wait_until,
)

pytestmark = pytest.mark.integration

#: A Redis database of this file's own (it empties it before and after): the other files' stacks share
#: tests.support.TEST_REDIS_URL while they run beside it.
REDIS_URL = os.environ.get("NONHOLONOMIC_TEST_PROCESSES_REDIS_URL", "redis://127.0.0.1:6379/13")

BODY = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7,
                   "potential": {"kind": "brun", "k": 0.4}},
        "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 20.0, "samples": 101}
LIMITS = {"NONHOLONOMIC_MAX_T_FINAL": "1e9"}
#: Hang guard (seconds) of a wait for a small job or a state the worker reaches in a fraction of a second
#: on a quiet machine; never a result.
GUARD_S = 120.0


def _end_of(log: str, job_id: str) -> str | None:
    """How the worker logged the end of job ``job_id``'s task (``ignored``: stopped by its cancellation;
    ``succeeded``: ran to its end), None if it did not."""
    found = re.search(rf"Task nonholonomic\.simulate\[{re.escape(job_id)}\] (ignored|succeeded|raised)", log)
    return found[1] if found else None


def _dump_logs(logs: Path) -> str:
    return "\n".join(f"--- {p.name}\n{p.read_text()[-4000:]}" for p in sorted(logs.glob("*.log")))


@pytest.fixture(scope="module")
def queue_stack(tmp_path_factory) -> Iterator[tuple[httpx.Client, redis.Redis, str]]:
    if not redis_available(REDIS_URL):
        pytest.fail(f"no Redis at {REDIS_URL}: run the README's test command, which starts one")
    store = redis.Redis.from_url(REDIS_URL)
    store.flushdb()
    logs = tmp_path_factory.mktemp("queue-logs")
    queue = f"test-{uuid.uuid4().hex[:8]}"
    port = free_port()
    # The API first, then the worker: with warm caches a worker is warm within a second, so the states
    # before it (no worker; a worker still compiling) are set up here rather than raced for.
    from workers.heartbeat import PREFIX

    api = start_api(port, logs / "api.log", {"REDIS_URL": REDIS_URL, "NONHOLONOMIC_QUEUE": queue, **LIMITS})
    worker = None
    base = f"http://127.0.0.1:{port}"
    try:
        wait_until(lambda: httpx.get(f"{base}/health", timeout=5).status_code in (200, 503), 60, "the API")
        no_worker = httpx.get(f"{base}/health", timeout=5)
        # A worker's heartbeat before its warm-up ends: it consumes the queue with no warm process.
        cold = f"{PREFIX}worker:compiling:1"
        store.set(cold, f'{{"name": "compiling@elsewhere", "queues": ["{queue}"]}}', ex=int(2 * GUARD_S))
        seen: list[httpx.Response] = []  # /health may answer with a check up to 0.25 s old: poll
        wait_until(lambda: "warm-up" in (seen.append(httpx.get(f"{base}/health", timeout=5)) or seen[-1].text),
                   GUARD_S, "/health to see the compiling worker (a hang guard)")
        compiling = seen[-1]
        store.delete(cold)
        worker = start_worker(REDIS_URL, queue, logs / "worker.log", extra_env=LIMITS, warm_up=True)
        wait_healthy(base, timeout=600)  # a hang guard: the worker's warm-up is ~35 s cold on 2 quiet cores
        with httpx.Client(base_url=base, timeout=10) as client:
            client.before_worker = (no_worker, compiling)  # type: ignore[attr-defined]
            client.worker_log = logs / "worker.log"  # type: ignore[attr-defined]
            yield client, store, queue
    except Exception:
        print(_dump_logs(logs))
        raise
    finally:
        stop(api)
        if worker is not None:
            stop(worker)
        store.flushdb()


def test_health_reports_broker_and_worker(queue_stack):
    client, _, _ = queue_stack
    health = client.get("/health").json()
    assert health["status"] == "ok" and health["mode"] == "queue" and health["broker"] == "ok"
    assert any(health["queue"] in w["queues"] and w["warm_processes"] >= 1 for w in health["workers"].values())


def test_health_is_503_until_a_worker_process_is_warm(queue_stack):
    """The issue's case: /health said 200 while the worker still compiled for 17 s. Before any worker
    consumes the queue, and while the only one has no warm process, /health is 503 saying why."""
    client, _, queue = queue_stack
    no_worker, compiling = client.before_worker
    for health in (no_worker, compiling):
        assert health.status_code == 503 and health.json()["status"] == "degraded", health.text
    assert f"no worker consumes the queue '{queue}'" in no_worker.json()["detail"]
    assert "warm-up" in compiling.json()["detail"]
    assert compiling.json()["workers"]["compiling@elsewhere"] == {"queues": [queue], "warm_processes": 0}


def test_health_reads_the_heartbeats_and_names_no_host(queue_stack):
    from workers.heartbeat import PREFIX

    client, store, queue = queue_stack
    store.set(f"{PREFIX}worker:elsewhere:1", f'{{"name": "cold@elsewhere", "queues": ["{queue}"]}}',
              ex=int(2 * GUARD_S))
    seen: list[dict] = []  # /health may answer with a check begun before the heartbeat was written: poll
    wait_until(lambda: "cold@elsewhere" in (seen.append(client.get("/health").json()) or seen[-1])["workers"],
               GUARD_S, "/health to read the new heartbeat (a hang guard)")
    health = seen[-1]
    assert health["workers"]["cold@elsewhere"] == {"queues": [queue], "warm_processes": 0}
    warm = [w for name, w in health["workers"].items() if name != "cold@elsewhere"]
    assert health["status"] == "ok" and sum(w["warm_processes"] for w in warm) == 1  # concurrency 1
    store.delete(f"{PREFIX}worker:elsewhere:1")
    assert "127.0.0.1" not in client.get("/health").text and "redis://" not in client.get("/health").text


def test_job_runs_on_the_worker_and_matches_an_independent_reference(queue_stack):
    client, store, queue = queue_stack
    r = client.post("/v1/jobs", json=BODY)
    assert r.status_code == 202
    # The first job may wait for the worker's warm-up (every system compiled: ~35 s with a cold
    # heyoka cache on 2 cores), hence the generous limit.
    view = poll_job(client, r.headers["location"], timeout=300)
    assert view["status"] == "succeeded", view["error"]
    result = view["result"]
    ref = ball_reference([2.0, 3.0, 4.5], 0.7, [0.5, -0.2, 0.1, 0.0, 0.6, 0.8], 20.0, k=0.4)
    final = np.concatenate([result["final_state"]["M"], result["final_state"]["gamma"]])
    assert np.max(np.abs(final - ref)) <= 1e-10
    assert all(i["passed"] and i["max_rel_drift"] <= 1e-13 for i in result["integrals"])
    assert all(c["passed"] for c in result["checks"])
    from store.jobs import JobStore

    stored = JobStore(queue_database_url(queue), 600)
    assert stored.get(view["id"]).result == result  # the job store (PostgreSQL) holds the result ...
    meta = store.get(f"celery-task-meta-{view['id']}")
    assert meta is None or len(meta) < 1000  # ... and Redis, the broker, does not
    stored.close()


def test_a_job_the_worker_refuses_is_reported_failed_with_its_reason(queue_stack):
    # Bypass the API's validation: send an invalid request straight to the queue (the worker records it).
    client, store, queue = queue_stack
    job_id = str(uuid.uuid4())
    bad = {**BODY, "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.0, 3.0]}}
    sender = Celery(broker=REDIS_URL, backend=REDIS_URL)
    sender.send_task("nonholonomic.simulate", args=[bad], task_id=job_id, queue=queue)
    view = poll_job(client, f"/v1/jobs/{job_id}", timeout=GUARD_S)
    assert view["status"] == "failed" and view["result"] is None
    assert view["error"]["type"] == "InvalidJob" and "initial_state.gamma" in view["error"]["message"]


def test_unknown_id_is_404_although_celery_says_pending(queue_stack):
    client, _, _ = queue_stack
    r = client.get(f"/v1/jobs/{uuid.uuid4()}")
    assert r.status_code == 404 and r.headers["content-type"] == "application/problem+json"


def test_invalid_job_is_refused_before_anything_is_queued(queue_stack):
    client, store, queue = queue_stack
    before = client.get("/v1/jobs", params={"limit": 500}).json()["items"]
    r = client.post("/v1/jobs", json={**BODY, "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0, 0, 2]}})
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "initial_state.gamma"
    assert client.get("/v1/jobs", params={"limit": 500}).json()["items"] == before and store.llen(queue) == 0


def test_progress_moves_and_cancel_stops_the_running_job(queue_stack):
    client, _, _ = queue_stack
    location = client.post("/v1/jobs", json={**BODY, "t_final": 1e8, "samples": 2}).headers["location"]
    wait_until(lambda: client.get(location).json()["progress"] > 0, 300, "progress (a hang guard)")
    first = client.get(location).json()
    seen: list[dict] = []  # the next progress write (every 0.2 s of the job's; later on a loaded machine)
    wait_until(lambda: (seen.append(client.get(location).json()) or seen[-1])["progress"] != first["progress"],
               GUARD_S, "progress to move (a hang guard)")
    second = seen[-1]
    assert first["status"] == second["status"] == "running"
    assert 0 < first["progress"] < second["progress"] < 1
    r = client.delete(location)
    assert r.status_code == 202 and r.json()["status"] == "cancelled"
    # With one worker process, a new job can only run once the cancelled one let go of it; the cancelled
    # one stopped at its next progress report (its task ignored), it did not run to its end (succeeded).
    view = poll_job(client, client.post("/v1/jobs", json=BODY).headers["location"], timeout=GUARD_S)
    assert view["status"] == "succeeded", view["error"]
    log = client.worker_log.read_text()
    cancelled_id = location.rsplit("/", 1)[1]
    assert _end_of(log, cancelled_id) == "ignored", log[-3000:]
    assert log.index(f"simulate[{cancelled_id}] ignored") < log.index(f"simulate[{view['id']}] received")
    assert client.get(location).json()["status"] == "cancelled"


def test_paper_report_and_a_map_run_through_the_worker(queue_stack):
    client, _, _ = queue_stack
    r = client.post("/v1/paper/report", json={"claims": ["ball.theorem_3", "veselova.multiplier"]})
    assert r.status_code == 202
    view = poll_job(client, r.headers["location"], timeout=300)
    assert view["status"] == "succeeded", view["error"]
    assert {row["id"]: row["verdict"] for row in view["result"]["rows"]} == {
        "veselova.multiplier": "holds after correction", "ball.theorem_3": "holds after correction"}
    page = client.get(f"/v1/paper/report/{view['id']}")
    assert page.status_code == 200 and "ERRATA 8" in page.text
    job = {**BODY, "system": {**BODY["system"], "potential": {"kind": "zero"}}, "checks": ["isomorphisms"],
           "initial_state": {"M": [0.5, -0.2, 0.15], "gamma": [0.0, 0.6, 0.8]}}  # Theorem 3: U = 0, (M, gamma) = 0
    view = poll_job(client, client.post("/v1/jobs", json=job).headers["location"], timeout=300)
    assert view["status"] == "succeeded", view["error"]
    assert [c["passed"] for c in view["result"]["checks"]] == [True, True]


def test_same_request_gives_the_same_numbers(queue_stack):
    client, _, _ = queue_stack
    results = [poll_job(client, client.post("/v1/jobs", json=BODY).headers["location"])["result"] for _ in range(2)]
    for r in results:
        r["integration"].pop("wall_time_s")
    assert results[0] == results[1]


def test_embedded_mode_serves_the_same_api_without_redis(tmp_path):
    port = free_port()
    api = start_api(port, tmp_path / "api.log", {"REDIS_URL": ""})
    base = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(base, timeout=600)  # a hang guard: the warm-up is ~35 s cold on 2 quiet cores
        with httpx.Client(base_url=base, timeout=10) as client:
            assert client.get("/health").json()["mode"] == "embedded"
            r = client.post("/v1/jobs", json=BODY)
            assert r.status_code == 202
            view = poll_job(client, r.headers["location"], timeout=300)  # may overlap the warm-up
            assert view["status"] == "succeeded", view["error"]
            ref = ball_reference([2.0, 3.0, 4.5], 0.7, [0.5, -0.2, 0.1, 0.0, 0.6, 0.8], 20.0, k=0.4)
            assert np.max(np.abs(np.array(view["result"]["final_state"]["M"]) - ref[:3])) <= 1e-10
    except Exception:
        print((tmp_path / "api.log").read_text())
        raise
    finally:
        stop(api)
