"""Jobs sent straight to the Celery queue by a job-queue client (``send_task``), through the real thing:
the API under uvicorn, a Celery worker process, Redis. Such a job is visible, listed and cancellable
through the HTTP API like a posted one, and computes the same numbers.

Uses Redis DB 14 (``NONHOLONOMIC_TEST_QUEUE_CLIENTS_REDIS_URL``) and a queue of its own.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import uuid
from collections.abc import Iterator
from contextlib import contextmanager

import httpx
import pytest
import redis
from celery import Celery
from sqlalchemy import delete, update

from store.jobs import JobStore
from store.models import JobRow
from tests.support import (
    drop_database,
    free_port,
    fresh_database_url,
    poll_job,
    redis_available,
    start_api,
    start_worker,
    stop,
    wait_healthy,
    wait_until,
)

pytestmark = pytest.mark.integration

REDIS_URL = os.environ.get("NONHOLONOMIC_TEST_QUEUE_CLIENTS_REDIS_URL", "redis://127.0.0.1:6379/14")
#: A database of this module's own: its list tests see only its jobs.
DATABASE_URL = fresh_database_url()
#: The README's first job.
README_JOB = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7,
                         "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}},
              "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]},
              "t_final": 1000.0, "samples": 201, "checks": ["integrals", "measure"]}
LONG = {**README_JOB, "t_final": 1e8, "samples": 2, "checks": ["integrals"]}  # runs until cancelled
QUICK = {**README_JOB, "t_final": 1.0, "samples": 11}
LIMITS = {"NONHOLONOMIC_MAX_T_FINAL": "1e9"}
#: No warm-up (compiling every system takes most of a minute on 2 cores): the first job compiles the
#: one system these tests use, and waits for the measure proof, which later jobs then reuse.
WORKER_ENV = {**LIMITS, "NONHOLONOMIC_WARM_UP": "false"}
#: Hang guard (seconds) of a wait for a small job: seconds on a quiet machine, never a result.
GUARD_S = 300.0

# What a job-queue client runs: it knows the broker, the task name, the queue and the JSON, nothing else.
SENDER = """
import json, sys
from celery import Celery
url, queue, request = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
client = Celery(broker=url, backend=url)
print(client.send_task("nonholonomic.simulate", args=[request], queue=queue).id)
"""


@pytest.fixture(scope="module")
def stack(tmp_path_factory) -> Iterator[tuple[httpx.Client, redis.Redis, Celery, str]]:
    if not redis_available(REDIS_URL):
        pytest.fail(f"no Redis at {REDIS_URL}: run the README's test command, which starts one")
    store = redis.Redis.from_url(REDIS_URL)
    store.flushdb()
    logs = tmp_path_factory.mktemp("queue-clients-logs")
    queue = f"test-qc-{uuid.uuid4().hex[:8]}"
    port = free_port()
    database = {"NONHOLONOMIC_DATABASE_URL": DATABASE_URL}
    worker = start_worker(REDIS_URL, queue, logs / "worker.log", extra_env={**WORKER_ENV, **database})
    api = start_api(port, logs / "api.log", {"REDIS_URL": REDIS_URL, "NONHOLONOMIC_QUEUE": queue, **LIMITS,
                                            **database})
    base = f"http://127.0.0.1:{port}"
    sender = Celery(broker=REDIS_URL, backend=REDIS_URL)  # a plain client: no app of this project
    try:
        wait_healthy(base, timeout=GUARD_S)
        with httpx.Client(base_url=base, timeout=10) as client:
            client.worker_log = logs / "worker.log"  # type: ignore[attr-defined]
            yield client, store, sender, queue
    except Exception:
        for p in sorted(logs.glob("*.log")):
            print(f"--- {p.name}\n{p.read_text()[-4000:]}")
        raise
    finally:
        stop(api)
        stop(worker)
        sender.close()
        store.flushdb()
        drop_database(DATABASE_URL)


def _send(sender: Celery, queue: str, *args, **kwargs) -> str:
    return sender.send_task("nonholonomic.simulate", args=list(args), kwargs=kwargs, queue=queue).id


@contextmanager
def _busy_worker(client: httpx.Client) -> Iterator[None]:
    """The worker (one process, prefetch 1) runs a long job: what is sent meanwhile waits in the broker."""
    location = client.post("/v1/jobs", json=LONG).headers["location"]
    wait_until(lambda: client.get(location).json()["status"] == "running", 240, "the long job to start")
    try:
        yield
    finally:
        assert client.delete(location).status_code == 202


def _listed(client: httpx.Client, job_id: str, **params) -> dict | None:
    items = client.get("/v1/jobs", params={"limit": 500, **params}).json()["items"]
    return next((i for i in items if i["id"] == job_id), None)


def test_a_sent_job_is_visible_queued_listed_then_succeeds_like_a_posted_one(stack):
    client, _, sender, queue = stack
    with _busy_worker(client):
        out = subprocess.run([sys.executable, "-c", SENDER, REDIS_URL, queue, json.dumps(README_JOB)],
                             capture_output=True, text=True, timeout=60, cwd="/", check=False)
        assert out.returncode == 0, out.stderr
        job_id = out.stdout.strip()
        as_text = _send(sender, queue, json.dumps(README_JOB))  # the request as a JSON string works too
        r = client.get(f"/v1/jobs/{job_id}")
        assert r.status_code == 200, r.text
        view = r.json()
        assert view["status"] == "queued" and view["result"] is None
        assert view["request"]["system"] == README_JOB["system"] and view["request"]["t_final"] == 1000.0
        item = _listed(client, as_text, status="queued")  # found in the broker by the list itself
        assert item is not None and item["kind"] == "chaplygin_ball" and item["location"] == f"/v1/jobs/{as_text}"
        assert _listed(client, job_id, status="queued") is not None
    sent = poll_job(client, f"/v1/jobs/{job_id}", timeout=GUARD_S)
    assert sent["status"] == "succeeded", sent["error"]
    posted = poll_job(client, client.post("/v1/jobs", json=README_JOB).headers["location"], timeout=GUARD_S)
    assert posted["request"] == sent["request"]
    for view in (sent, posted, poll_job(client, f"/v1/jobs/{as_text}", timeout=GUARD_S)):
        view["result"]["integration"].pop("wall_time_s")
    assert sent["result"] == posted["result"]  # the same numbers, bit for bit
    assert poll_job(client, f"/v1/jobs/{as_text}")["result"]["final_state"] == posted["result"]["final_state"]
    listed = _listed(client, job_id)
    assert listed is not None and listed["status"] == "succeeded" and listed["progress"] == 1.0


def test_a_sent_job_cancelled_while_queued_never_runs(stack):
    client, store, sender, queue = stack
    with _busy_worker(client):
        job_id = _send(sender, queue, README_JOB)
        r = client.delete(f"/v1/jobs/{job_id}")
        assert r.status_code == 202 and r.json()["status"] == "cancelled"
        assert _listed(client, job_id, status="cancelled") is not None
    # The queue is first in, first out: once a job sent after it finished, the worker has dropped it.
    after = poll_job(client, client.post("/v1/jobs", json=QUICK).headers["location"], timeout=GUARD_S)
    assert after["status"] == "succeeded"
    view = client.get(f"/v1/jobs/{job_id}").json()
    assert view["status"] == "cancelled" and view["result"] is None
    meta = store.get(f"celery-task-meta-{job_id}")
    assert meta is None or json.loads(meta)["status"] == "REVOKED"


def test_a_sent_job_registers_itself_when_it_starts_and_stops_when_cancelled(stack):
    client, store, sender, queue = stack
    job_id = _send(sender, queue, LONG)  # the worker is idle: it takes the job before the API hears of it
    jobs = JobStore(DATABASE_URL, 600)
    wait_until(lambda: jobs.status(job_id) is not None, GUARD_S, "the task to record its job (a hang guard)")
    jobs.close()
    wait_until(lambda: client.get(f"/v1/jobs/{job_id}").json()["progress"] > 0, GUARD_S, "progress (a hang guard)")
    assert client.get(f"/v1/jobs/{job_id}").json()["status"] == "running"
    assert _listed(client, job_id, status="running") is not None
    r = client.delete(f"/v1/jobs/{job_id}")
    assert r.status_code == 202 and r.json()["status"] == "cancelled"
    # One worker process: the next job runs once the cancelled one let go of it. The cancelled one stopped
    # at its next progress report (its task ignored); it did not run to its end (succeeded).
    after = poll_job(client, client.post("/v1/jobs", json=QUICK).headers["location"], timeout=GUARD_S)
    assert after["status"] == "succeeded", after["error"]
    log = client.worker_log.read_text()
    assert f"simulate[{job_id}] ignored" in log and f"simulate[{job_id}] succeeded" not in log, log[-3000:]
    assert log.index(f"simulate[{job_id}] ignored") < log.index(f"simulate[{after['id']}] received")
    assert client.get(f"/v1/jobs/{job_id}").json()["status"] == "cancelled"


def test_invalid_sent_requests_fail_with_their_reason(stack):
    client, _, sender, queue = stack
    bad_gamma = {**README_JOB, "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.0, 3.0]}}
    cases = {
        _send(sender, queue, "{not json"): ("InvalidJob", "not valid JSON"),
        _send(sender, queue, [1, 2]): ("InvalidJob", "must be a JSON object"),
        _send(sender, queue): ("InvalidJob", "takes one argument"),
        _send(sender, queue, bad_gamma): ("InvalidJob", "initial_state.gamma"),
        _send(sender, queue, {**README_JOB, "t_final": -1, "system": {**README_JOB["system"], "D": -1}}):
            ("InvalidJob", "system.D: Input should be greater than or equal to 0; t_final: Input should be greater"),
    }
    for job_id, (kind, reason) in cases.items():
        location = f"/v1/jobs/{job_id}"
        wait_until(lambda location=location: client.get(location).status_code == 200, GUARD_S,
                   f"{location} to be known (a hang guard)")
        view = poll_job(client, f"/v1/jobs/{job_id}", timeout=GUARD_S)
        assert view["status"] == "failed" and view["result"] is None, view
        assert view["error"]["type"] == kind and reason in view["error"]["message"], view["error"]
    assert client.get(f"/v1/jobs/{next(iter(cases))}").json()["request"] == {"raw": "{not json"}
    failed = {i["id"]: i for i in client.get("/v1/jobs", params={"status": "failed"}).json()["items"]}
    assert set(cases) <= set(failed)
    assert [failed[j]["kind"] for j in cases] == [None, None, None, "chaplygin_ball", "chaplygin_ball"]


def _all_pages(client: httpx.Client, **params) -> list[str]:
    seen, cursor = [], None
    while True:
        body = client.get("/v1/jobs", params={**params, **({"cursor": cursor} if cursor else {})}).json()
        seen += [i["id"] for i in body["items"]]
        cursor = body["next_cursor"]
        if cursor is None:
            return seen


def test_list_pages_through_equal_creation_times(stack):
    # Records all created at the same instant (a tie the cursor must break by id), older than the rest.
    client, _, _, _ = stack
    ids = sorted(f"tie-{uuid.uuid4().hex[:8]}" for _ in range(5))
    jobs = JobStore(DATABASE_URL, 600)
    for job_id in ids:
        jobs.create(job_id, QUICK)
    # cancelled, not queued: an API of another test sharing the database re-sends queued jobs that no broker
    # holds (store.jobs.sent_before) and its worker would run them while this test pages
    with jobs.session() as session, session.begin():
        session.execute(update(JobRow).where(JobRow.id.in_(ids)).values(created=1000.0, status="cancelled"))
    try:
        everything = _all_pages(client, limit=2)  # pages end inside the tie
        assert len(everything) == len(set(everything)) and everything[-5:] == ids[::-1]  # ties: by id, each once
        assert _all_pages(client, status="cancelled", limit=2)[-5:] == ids[::-1]
    finally:
        with jobs.session() as session, session.begin():
            session.execute(delete(JobRow).where(JobRow.id.in_(ids)))
        jobs.close()
