"""Access control in queue mode: owners in the Redis registry, the per-key bound counted there, the
queue's length, and Idempotency-Key shared by two API processes. No worker: the jobs stay queued."""

from __future__ import annotations

import uuid
from collections.abc import Iterator

import httpx
import pytest
import redis

from tests.support import TEST_REDIS_URL, free_port, redis_available, start_api, stop, wait_until

pytestmark = pytest.mark.integration

A, B = {"X-API-Key": "alpha-secret"}, {"Authorization": "Bearer beta-secret"}
BODY = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
        "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 20.0, "samples": 11}


@pytest.fixture(scope="module")
def apis(tmp_path_factory) -> Iterator[tuple[httpx.Client, httpx.Client, str]]:
    if not redis_available():
        pytest.fail(f"no Redis at {TEST_REDIS_URL}: run the README's test command, which starts one")
    logs = tmp_path_factory.mktemp("access-logs")
    queue = f"access-{uuid.uuid4().hex[:8]}"
    env = {"REDIS_URL": TEST_REDIS_URL, "NONHOLONOMIC_QUEUE": queue, "NONHOLONOMIC_WARM_UP": "false",
           "NONHOLONOMIC_API_KEYS": "alice:alpha-secret,bob:beta-secret", "NONHOLONOMIC_MAX_ACTIVE_JOBS_PER_KEY": "3",
           "NONHOLONOMIC_MAX_QUEUED_MESSAGES": "6"}
    ports = [free_port(), free_port()]
    procs = [start_api(port, logs / f"api-{i}.log", env) for i, port in enumerate(ports)]
    clients = [httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=10) for port in ports]
    try:
        for client in clients:  # /health is 503 (no worker): wait for any answer
            wait_until(lambda c=client: c.get("/health").status_code in (200, 503), 60, "the API")
        yield clients[0], clients[1], queue
    finally:
        for proc in procs:
            stop(proc)
        redis.Redis.from_url(TEST_REDIS_URL).delete(queue)


def test_owners_live_in_the_registry_and_the_per_key_bound_is_counted_there(apis):
    one, two, _ = apis
    mine = [one.post("/v1/jobs", json=BODY, headers=A) for _ in range(3)]
    assert [r.status_code for r in mine] == [202] * 3
    location = mine[0].headers["location"]
    assert two.get(location, headers=A).json()["status"] == "queued"  # any API process: the same record
    assert two.get(location, headers=B).status_code == 404 and two.delete(location, headers=B).status_code == 404
    assert location not in [i["location"] for i in two.get("/v1/jobs", headers=B).json()["items"]]
    refused = two.post("/v1/jobs", json=BODY, headers=A)
    assert refused.status_code == 429 and refused.json()["type"] == "/problems/queue-full", refused.text
    assert one.delete(location, headers=A).status_code == 202  # a cancelled job no longer counts
    assert two.post("/v1/jobs", json=BODY, headers=A).status_code == 202
    for item in one.get("/v1/jobs", headers=A).json()["items"]:
        one.delete(item["location"], headers=A)


def test_an_idempotency_key_holds_across_api_processes(apis):
    one, two, _ = apis
    headers = {**B, "Idempotency-Key": f"k-{uuid.uuid4().hex}"}
    first = one.post("/v1/jobs", json=BODY, headers=headers)
    again = two.post("/v1/jobs", json=BODY, headers=headers)
    assert first.status_code == again.status_code == 202 and first.json()["id"] == again.json()["id"]
    assert again.headers["idempotent-replayed"] == "true"
    assert two.post("/v1/jobs", json={**BODY, "samples": 12}, headers=headers).status_code == 422
    one.delete(first.headers["location"], headers=B)


def test_the_queue_length_bounds_what_is_accepted(apis):
    one, _, queue = apis
    store = redis.Redis.from_url(TEST_REDIS_URL)
    accepted = 0
    while store.llen(queue) < 6 and accepted < 20:  # B's own bound is 3 active: cancelled ones make room
        r = one.post("/v1/jobs", json=BODY, headers=B)
        assert r.status_code == 202, r.text
        one.delete(r.headers["location"], headers=B)  # cancelled, but its message stays in the queue
        accepted += 1
    r = one.post("/v1/jobs", json=BODY, headers=B)
    assert r.status_code == 429 and "6 jobs and ensemble chunks wait in the queue" in r.json()["detail"]
    assert r.headers["retry-after"] == "10"
