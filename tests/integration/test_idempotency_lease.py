"""An Idempotency-Key whose API died mid-request is free again within its lease (issue 19, item 4).

Queue mode, real API processes (uvicorn), Redis and PostgreSQL. A keyed POST is held in flight (the test
locks the jobs table, so its INSERT waits), longer than the lease: the key stays in progress (409 with
``Retry-After``) because the API serving it renews the lease. Then that API is SIGKILLed and started
again: the key answers 409 while the lease lasts, then the retry is an ordinary 202, and one job exists.
"""

from __future__ import annotations

import os
import signal
import threading
import time
import uuid
from pathlib import Path

import httpx
import pytest
import redis
from sqlalchemy import create_engine, func, select, text

from store.jobs import JobStore
from store.models import JobRow
from tests.support import (
    TEST_REDIS_URL,
    drop_database,
    free_port,
    fresh_database_url,
    redis_available,
    start_api,
    stop,
    wait_until,
)

pytestmark = pytest.mark.integration

LEASE_S = 6.0
#: Hang guard (seconds) of the waits: an API's start and the lease's few seconds take far less on a quiet
#: machine; never a result (when the key is free again is the store's lease, not this test's bound).
GUARD_S = 300.0
KEY = {"X-API-Key": "alpha-secret"}
BODY = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
        "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 20.0, "samples": 11}


def _answering(base: str) -> None:
    wait_until(lambda: httpx.get(f"{base}/health", timeout=5).status_code in (200, 503), GUARD_S,
               f"{base} (a hang guard)")


def test_a_key_whose_api_died_mid_request_is_free_again_after_its_lease(tmp_path: Path):
    if not redis_available():
        pytest.fail(f"no Redis at {TEST_REDIS_URL}: run the README's test command, which starts one")
    queue, database = f"lease-{uuid.uuid4().hex[:8]}", fresh_database_url()
    env = {"REDIS_URL": TEST_REDIS_URL, "NONHOLONOMIC_QUEUE": queue, "NONHOLONOMIC_DATABASE_URL": database,
           "NONHOLONOMIC_WARM_UP": "false", "NONHOLONOMIC_API_KEYS": "alice:alpha-secret",
           "NONHOLONOMIC_IDEMPOTENCY_LEASE_S": str(LEASE_S)}
    ports = [free_port(), free_port()]
    bases = [f"http://127.0.0.1:{port}" for port in ports]
    procs = [start_api(port, tmp_path / f"api-{i}.log", env) for i, port in enumerate(ports)]
    locker = create_engine(database, isolation_level="AUTOCOMMIT")
    headers = {**KEY, "Idempotency-Key": f"lease-{uuid.uuid4().hex}"}
    try:
        for base in bases:
            _answering(base)
        other = httpx.Client(base_url=bases[1], timeout=30)
        with locker.connect() as lock:
            lock.execute(text("BEGIN"))
            lock.execute(text("LOCK TABLE jobs IN EXCLUSIVE MODE"))  # the keyed POST's INSERT waits

            def doomed() -> None:
                try:
                    httpx.post(f"{bases[0]}/v1/jobs", json=BODY, headers=headers, timeout=120)
                except httpx.HTTPError:
                    pass  # its API is killed

            threading.Thread(target=doomed, daemon=True).start()
            wait_until(lambda: lock.execute(text(
                "SELECT count(*) FROM pg_locks l JOIN pg_class c ON c.oid = l.relation "
                "WHERE c.relname = 'jobs' AND NOT l.granted "
                "AND l.database = "
                "(SELECT oid FROM pg_database WHERE datname = current_database())")).scalar() >= 1, GUARD_S,
                "the POST to wait for the table (a hang guard)")
            time.sleep(1.5 * LEASE_S)  # served longer than its lease: renewed, still in progress
            busy = other.post("/v1/jobs", json=BODY, headers=headers)
            assert busy.status_code == 409 and busy.headers["retry-after"] == "1", busy.text
            assert busy.json()["type"] == "/problems/conflict"
            os.kill(procs[0].pid, signal.SIGKILL)  # mid-request
            procs[0].wait(10)
            killed_at = time.monotonic()
            lock.execute(text("ROLLBACK"))
        dead = other.post("/v1/jobs", json=BODY, headers=headers)  # its API is dead, the lease not over
        assert dead.status_code == 409 and dead.headers["retry-after"] == "1", dead.text
        procs[0] = start_api(ports[0], tmp_path / "api-0-again.log", env)  # started again
        _answering(bases[0])
        again = httpx.Client(base_url=bases[0], timeout=30)
        answers: list[httpx.Response] = []

        def retried() -> bool:
            answers.append(again.post("/v1/jobs", json=BODY, headers=headers))
            return answers[-1].status_code != 409

        wait_until(retried, GUARD_S, "the key to be free again (a hang guard)", interval=0.25)
        free_after_s = time.monotonic() - killed_at
        first = answers[-1]
        assert first.status_code == 202 and "idempotent-replayed" not in first.headers, first.text  # a normal 202
        for r in answers[:-1]:  # while the lease lasted: in progress
            assert r.status_code == 409 and r.headers["retry-after"] == "1", r.text
        replay = other.post("/v1/jobs", json=BODY, headers=headers)
        assert replay.status_code == 202 and replay.headers["idempotent-replayed"] == "true"
        assert replay.json()["id"] == first.json()["id"]
        jobs = JobStore(database, 600)
        try:
            with jobs.session() as session:
                assert session.scalar(select(func.count()).select_from(JobRow)) == 1  # the killed POST left none
        finally:
            jobs.close()
        print(f"key free again {free_after_s:.1f} s after its API was killed (lease {LEASE_S:g} s)")
    except Exception:
        for log in sorted(tmp_path.glob("*.log")):
            print(f"--- {log.name}\n{log.read_text()[-3000:]}")
        raise
    finally:
        for proc in procs:
            stop(proc)
        locker.dispose()
        redis.Redis.from_url(TEST_REDIS_URL).delete(queue)
        drop_database(database)
