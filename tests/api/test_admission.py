"""Admission in embedded mode, in-process (issue 19): an ensemble counts its chunks against the queue's
bound, one whose chunks alone exceed it is a cheap 422; failed authentication is rate limited per client
address; an unknown job or ensemble id and another key's answer alike, after the same database work; an
Idempotency-Key is bound with its job in one transaction. Queue mode: tests/integration/test_admission_races.py
and test_idempotency_crash.py."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import event

from schemas.settings import get_settings
from service.main import create_app
from tests.api.conftest import BALL, STATE, job

A, B = {"X-API-Key": "alpha-secret"}, {"X-API-Key": "beta-secret"}
#: A job that runs for minutes: it keeps the one embedded thread while the others wait in its queue.
LONG = job(t_final=1e8, samples=2)
#: Hang guard (seconds) of each wait for a job's status: far above the few seconds a quiet machine needs
#: (the first job compiles its integrator), never a result.
GUARD_S = 300.0


def _until_status(client: TestClient, location: str, status: str) -> None:
    """Wait until the work at ``location`` (alice's) has ``status``; fail past the hang guard."""
    deadline = time.monotonic() + GUARD_S
    while (seen := client.get(location, headers=A).json()["status"]) != status:
        if time.monotonic() > deadline:
            pytest.fail(f"hang guard: {location} still {seen!r}, not {status!r}, after {GUARD_S:g} s")
        time.sleep(0.01)


def ensemble(members: int, chunk_size: int | None = 1, sample: bool = False) -> dict:
    spec = ({"sample": {"count": members, "seed": 1, "level": {"energy": 1.0, "area": 0.0}}} if sample
            else {"initial_states": [dict(STATE)] * members})
    body = {"system": dict(BALL), "members": spec, "t_final": 1.0, "samples": 2}
    return body if chunk_size is None else {**body, "chunk_size": chunk_size}


@pytest.fixture()
def app_with(monkeypatch) -> Iterator:
    opened: list[TestClient] = []

    def make(client: tuple[str, int] = ("testclient", 50000), **env: str) -> TestClient:
        monkeypatch.delenv("REDIS_URL", raising=False)
        monkeypatch.setenv("NONHOLONOMIC_WARM_UP", "false")
        monkeypatch.setenv("NONHOLONOMIC_MAX_T_FINAL", "1e9")
        for name, value in env.items():
            monkeypatch.setenv(f"NONHOLONOMIC_{name}", value)
        get_settings.cache_clear()
        test_client = TestClient(create_app(), client=client)
        opened.append(test_client.__enter__())
        return test_client

    yield make
    for test_client in opened:
        for item in test_client.get("/v1/jobs", headers=A).json().get("items", []):
            if item["status"] in ("queued", "running"):
                test_client.delete(item["location"], headers=A)
        test_client.__exit__(None, None, None)
    get_settings.cache_clear()


def test_an_ensemble_counts_its_chunks_against_the_queue_bound(app_with):
    client = app_with(MAX_QUEUED_MESSAGES="5", API_KEYS="alice:alpha-secret")
    first = client.post("/v1/jobs", json=LONG, headers=A).headers["location"]
    _until_status(client, first, "running")  # the one thread takes it, nothing waits
    assert [client.post("/v1/jobs", json=LONG, headers=A).status_code for _ in range(3)] == [202] * 3  # 3 wait
    r = client.post("/v1/ensembles", json=ensemble(3), headers=A)  # 3 + 3 > 5
    assert r.status_code == 429 and r.json()["type"] == "/problems/queue-full", r.text
    assert "3 ensemble chunks more" in r.json()["detail"] and "max_queued_messages=5" in r.json()["detail"]
    assert r.headers["retry-after"] == "10"
    assert client.post("/v1/ensembles", json=ensemble(2), headers=A).status_code == 202  # 3 + 2 = 5: at the bound
    full = client.post("/v1/jobs", json=LONG, headers=A)
    assert full.status_code == 429 and "5 jobs and ensemble chunks wait" in full.json()["detail"]


def test_an_ensemble_whose_chunks_alone_exceed_the_bound_is_a_cheap_422(app_with):
    client = app_with(MAX_QUEUED_MESSAGES="5", MAX_ENSEMBLE_MEMBERS="100000", MAX_ENSEMBLE_VALUES="1000000")
    r = client.post("/v1/ensembles", json=ensemble(6), headers=A)
    assert r.status_code == 422, r.text
    (error,) = r.json()["errors"]
    assert (error["field"] == "chunk_size" and "6 chunks" in error["reason"]
            and "max_queued_messages=5" in error["reason"])
    default = client.post("/v1/ensembles", json=ensemble(30_000, chunk_size=None, sample=True))  # default chunks
    assert default.status_code == 422 and default.json()["errors"][0]["field"] == "members", default.text
    # 20,000 members, one chunk each: refused before any member is validated or any chunk is queued
    start = time.process_time()
    huge = client.post("/v1/ensembles", json=ensemble(20_000, sample=True))
    cpu_s = time.process_time() - start
    assert huge.status_code == 422 and "20000 chunks" in huge.json()["errors"][0]["reason"]
    print(f"a 20,000-chunk ensemble refused in {cpu_s * 1000:.0f} ms of CPU (body parsing included)")
    assert client.get("/v1/jobs").json()["items"] == []


def test_an_ensemble_has_at_most_max_ensemble_chunks_chunks(app_with):
    """Each chunk is a message its POST sends: explicit chunks beyond the bound are a 422 naming
    chunk_size with the least size that fits; default chunks grow to fit it."""
    client = app_with(MAX_ENSEMBLE_CHUNKS="4", MAX_ENSEMBLE_MEMBERS="100000", MAX_ENSEMBLE_VALUES="1000000")
    r = client.post("/v1/ensembles", json=ensemble(10, chunk_size=2))
    assert r.status_code == 422, r.text
    (error,) = r.json()["errors"]
    assert error["field"] == "chunk_size" and "5 chunks" in error["reason"] and "chunk_size >= 3" in error["reason"]
    fits = client.post("/v1/ensembles", json=ensemble(10, chunk_size=3))
    assert fits.status_code == 202 and fits.json()["chunks"] == 4, fits.text
    grown = client.post("/v1/ensembles", json=ensemble(4000, chunk_size=None, sample=True))
    assert grown.status_code == 202 and grown.json()["chunks"] <= 4, grown.text


def test_failed_authentication_is_rate_limited_per_address(app_with):
    client = app_with(API_KEYS="alice:alpha-secret,bob:beta-secret", AUTH_FAILURES_PER_MINUTE="3")
    wrong = {"X-API-Key": "guess"}
    assert client.get("/v1/systems", headers=A).status_code == 200  # alice works from this address
    assert [client.get("/v1/systems", headers=wrong).status_code for _ in range(3)] == [401] * 3
    limited = client.get("/v1/systems", headers=wrong)
    assert limited.status_code == 429 and limited.json()["type"] == "/problems/rate-limited"
    assert 1 <= int(limited.headers["retry-after"]) <= 20  # one failure's token comes back in 20 s
    # a key already at work from this address is not locked out by a guesser beside it (issue 34, item 5)
    assert [client.get("/v1/systems", headers=A).status_code for _ in range(5)] == [200] * 5
    # a key new to this address answers as a wrong one while limited: a guess tells nothing
    assert client.get("/v1/systems", headers=B).status_code == 429
    assert client.get("/v1/systems").status_code == 401  # no key: nothing guessed, nothing counted
    other = TestClient(client.app, client=("192.0.2.7", 40000))  # another address has its own bucket
    assert other.get("/v1/systems", headers=A).status_code == 200
    assert other.get("/v1/systems", headers=wrong).status_code == 401


def _finished(client: TestClient, location: str) -> None:
    """Wait for the work at ``location`` (alice's): no writes in the background while counting."""
    _until_status(client, location, "succeeded")


def _asked_by_bob(client: TestClient, foreign: str, unknown: str) -> tuple[dict, dict]:
    """Bob's answers for alice's ``foreign`` path and an ``unknown`` one, and the SQL each cost."""
    statements: list[str] = []
    engine = client.app.state.backend.store.engine
    asked = [""]

    def record(conn, cursor, statement, parameters, context, executemany) -> None:
        if asked[0] in str(parameters):  # this request's lookups, not a background thread's statements
            statements.append(statement)

    event.listen(engine, "before_cursor_execute", record)
    try:
        answers, work = {}, {}
        for name, path in (("foreign", foreign), ("unknown", unknown)):
            statements.clear()
            asked[0] = path.rsplit("/", 1)[1]
            answers[name] = client.get(path, headers=B)
            work[name] = list(statements)
    finally:
        event.remove(engine, "before_cursor_execute", record)
    assert answers["foreign"].status_code == answers["unknown"].status_code == 404
    assert (answers["foreign"].text.replace(foreign.rsplit("/", 1)[1], "ID")
            == answers["unknown"].text.replace(unknown.rsplit("/", 1)[1], "ID"))  # the same body
    assert answers["foreign"].headers["content-type"] == answers["unknown"].headers["content-type"]
    return answers, work


def test_an_unknown_and_a_foreign_job_id_answer_alike_after_the_same_work(app_with):
    client = app_with(API_KEYS="alice:alpha-secret,bob:beta-secret")
    foreign = client.post("/v1/jobs", json=job(samples=2001), headers=A).headers["location"]
    _finished(client, foreign)
    _, work = _asked_by_bob(client, foreign, f"/v1/jobs/{'0' * 8}-0000-4000-8000-{'0' * 12}")
    assert work["foreign"] == work["unknown"] and len(work["foreign"]) == 1  # one lookup ...
    assert "result" not in work["foreign"][0]  # ... that never reads another key's result
    assert client.get(foreign, headers=A).json()["result"] is not None


def test_an_unknown_and_a_foreign_ensemble_id_answer_alike_after_the_same_work(app_with):
    client = app_with(API_KEYS="alice:alpha-secret,bob:beta-secret")
    foreign = client.post("/v1/ensembles", json=ensemble(2), headers=A).headers["location"]
    _finished(client, foreign)
    _, work = _asked_by_bob(client, foreign, f"/v1/ensembles/{'0' * 8}-0000-4000-8000-{'0' * 12}")
    assert work["foreign"] == work["unknown"] and len(work["foreign"]) == 1  # one lookup, never the chunks
    assert "ensemble_chunks" not in work["foreign"][0]
    assert client.get(foreign, headers=A).status_code == 200


def test_an_idempotency_key_is_bound_with_its_job_in_one_transaction_or_not_at_all(tmp_path):
    """SQLite (embedded): the key's row commits or rolls back with the job's; a second binding finds the first."""
    from store.idempotency import KeyBinding, KeyBound
    from store.jobs import ActiveBoundReached, JobStore

    store = JobStore(f"sqlite:///{tmp_path / 'jobs.db'}", ttl_s=3600)
    store.migrate()
    try:
        store.create("job-1", {"a": 1}, "alice", binding=KeyBinding("alice:k", "f1"))
        with pytest.raises(KeyBound) as bound:
            store.create("job-2", {"a": 1}, "alice", binding=KeyBinding("alice:k", "f1"))
        assert (bound.value.fingerprint, bound.value.resource) == ("f1", "job-1")
        assert store.get("job-2") is None  # nothing recorded beside the refused binding
        with pytest.raises(ActiveBoundReached):  # refused after binding: the binding rolls back with it
            store.create("job-3", {"a": 3}, "alice", max_active=1, binding=KeyBinding("alice:other", "f3"))
        assert store.get("job-3") is None
        assert store_keys(store).bound("alice:other") is None
        assert store_keys(store).bound("alice:k") == ("f1", "job-1")
        store.delete("job-1", "alice:k")  # the broker refused it: job and key go together
        assert store.get("job-1") is None and store_keys(store).bound("alice:k") is None
    finally:
        store.close()


def store_keys(store):
    from store.idempotency import IdempotencyKeys

    return IdempotencyKeys(store.engine)
