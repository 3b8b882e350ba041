"""The bounds on work hold under concurrency (issue 19, items 5 and 10), through real API processes
(uvicorn), a real Redis and a real PostgreSQL; no worker, so that what is admitted stays queued.

30 concurrent POSTs of one key against ``max_active_jobs_per_key=5`` admit exactly 5, in queue mode
split over two API processes and in embedded mode; concurrent ensembles against ``max_queued_messages``
fill the queue to its bound and never past it; an ensemble at the bound is admitted, one chunk more is
a 429, one whose chunks alone exceed the bound a 422.
"""

from __future__ import annotations

import threading
import uuid
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
import redis
from sqlalchemy import func, select

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

KEY = {"X-API-Key": "alpha-secret"}
BALL = {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7}
STATE = {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}
#: Runs for minutes (embedded mode runs the first one): stays active while the test looks.
LONG = {"system": BALL, "initial_state": STATE, "t_final": 1e8, "samples": 2}
CONCURRENT, BOUND = 30, 5


def _ensemble(chunks: int) -> dict:
    return {"system": BALL, "members": {"initial_states": [STATE] * chunks}, "t_final": 1.0, "samples": 2,
            "chunk_size": 1}


def _at_once(requests: list[tuple[str, str, dict]]) -> list[httpx.Response]:
    """Send every ``(base, path, body)`` POST at the same moment, each from a client of its own."""
    answers: list[httpx.Response] = []
    ready = threading.Barrier(len(requests))

    def post(base: str, path: str, body: dict) -> None:
        with httpx.Client(base_url=base, timeout=120) as client:
            ready.wait()
            answers.append(client.post(path, json=body, headers=KEY))

    threads = [threading.Thread(target=post, args=request) for request in requests]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return answers


def _answering(base: str) -> None:
    wait_until(lambda: httpx.get(f"{base}/health", timeout=5).status_code in (200, 503), 300,
               f"{base} (a hang guard: an API starts within seconds on a quiet machine)")


@pytest.fixture()
def queue_mode(tmp_path: Path) -> Iterator[tuple[list[str], str, str]]:
    """Two API processes sharing a queue of their own and a database of their own."""
    if not redis_available():
        pytest.fail(f"no Redis at {TEST_REDIS_URL}: run the README's test command, which starts one")
    queue, database = f"races-{uuid.uuid4().hex[:8]}", fresh_database_url()
    env = {"REDIS_URL": TEST_REDIS_URL, "NONHOLONOMIC_QUEUE": queue, "NONHOLONOMIC_DATABASE_URL": database,
           "NONHOLONOMIC_WARM_UP": "false", "NONHOLONOMIC_MAX_T_FINAL": "1e9",
           "NONHOLONOMIC_API_KEYS": "alice:alpha-secret", "NONHOLONOMIC_MAX_ACTIVE_JOBS_PER_KEY": str(BOUND),
           "NONHOLONOMIC_MAX_QUEUED_MESSAGES": "10"}
    ports = [free_port(), free_port()]
    procs = [start_api(port, tmp_path / f"api-{i}.log", env) for i, port in enumerate(ports)]
    bases = [f"http://127.0.0.1:{port}" for port in ports]
    try:
        for base in bases:
            _answering(base)
        yield bases, queue, database
    except Exception:
        for log in sorted(tmp_path.glob("*.log")):
            print(f"--- {log.name}\n{log.read_text()[-3000:]}")
        raise
    finally:
        for proc in procs:
            stop(proc)
        redis.Redis.from_url(TEST_REDIS_URL).delete(queue, f"nonholonomic:admission:{queue}")
        drop_database(database)


def _active_of(database: str, owner: str) -> int:
    store = JobStore(database, 600)
    try:
        with store.session() as session:
            return int(session.scalar(select(func.count()).select_from(JobRow).where(
                JobRow.owner == owner, JobRow.status.in_(("queued", "running")))))
    finally:
        store.close()


def test_30_concurrent_posts_of_one_key_admit_exactly_its_bound_across_api_processes(queue_mode):
    bases, queue, database = queue_mode
    answers = _at_once([(bases[i % 2], "/v1/jobs", LONG) for i in range(CONCURRENT)])
    codes = sorted(r.status_code for r in answers)
    assert codes == [202] * BOUND + [429] * (CONCURRENT - BOUND), codes
    for r in answers:
        if r.status_code == 429:
            assert r.json()["type"] == "/problems/queue-full" and r.headers["retry-after"], r.text
    assert _active_of(database, "alice") == BOUND
    assert redis.Redis.from_url(TEST_REDIS_URL).llen(queue) == BOUND  # each admitted job sent once


def test_concurrent_ensembles_fill_the_queue_to_its_bound_never_past_it(queue_mode):
    bases, queue, _ = queue_mode
    broker = redis.Redis.from_url(TEST_REDIS_URL)
    # 10 ensembles of 3 chunks each against a bound of 10 messages: 3 fit (9 messages), never 4
    answers = _at_once([(bases[i % 2], "/v1/ensembles", _ensemble(3)) for i in range(10)])
    codes = sorted(r.status_code for r in answers)
    assert codes == [202] * 3 + [429] * 7, [r.text for r in answers]
    assert broker.llen(queue) == 9
    one = httpx.Client(base_url=bases[0], timeout=60, headers=KEY)
    refused = one.post("/v1/ensembles", json=_ensemble(2))  # 9 + 2 > 10
    assert refused.status_code == 429 and "2 ensemble chunks more" in refused.json()["detail"], refused.text
    assert one.post("/v1/ensembles", json=_ensemble(1)).status_code == 202  # 9 + 1 = 10: at the bound
    assert broker.llen(queue) == 10
    assert one.post("/v1/jobs", json=LONG).status_code == 429
    too_big = one.post("/v1/ensembles", json=_ensemble(11))  # could never fit: a 422, nothing sent
    assert too_big.status_code == 422 and too_big.json()["errors"][0]["field"] == "chunk_size", too_big.text
    assert "11 chunks" in too_big.json()["errors"][0]["reason"]
    assert broker.llen(queue) == 10 and broker.zcard(f"nonholonomic:admission:{queue}") == 0


def test_30_concurrent_posts_of_one_key_admit_exactly_its_bound_in_embedded_mode(tmp_path):
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    api = start_api(port, tmp_path / "api.log", {"REDIS_URL": "", "NONHOLONOMIC_WARM_UP": "false",
                                                 "NONHOLONOMIC_MAX_T_FINAL": "1e9",
                                                 "NONHOLONOMIC_API_KEYS": "alice:alpha-secret",
                                                 "NONHOLONOMIC_MAX_ACTIVE_JOBS_PER_KEY": str(BOUND)})
    try:
        _answering(base)
        answers = _at_once([(base, "/v1/jobs", LONG) for _ in range(CONCURRENT)])
        codes = sorted(r.status_code for r in answers)
        assert codes == [202] * BOUND + [429] * (CONCURRENT - BOUND), codes
        listed = httpx.get(f"{base}/v1/jobs", headers=KEY, timeout=30).json()["items"]
        assert len(listed) == BOUND
    except Exception:
        print((tmp_path / "api.log").read_text()[-3000:])
        raise
    finally:
        stop(api)
