"""Access control (issue "Nothing lost, nobody locked out", item 5): API keys, each key's own jobs and
ensembles, rate limits, bounds on queued work, CORS and Idempotency-Key; embedded mode, in-process.
Queue mode is covered by tests/integration/test_access_queue.py."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from schemas.settings import get_settings
from service.main import create_app
from tests.api.conftest import job

A, B = {"Authorization": "Bearer alpha-secret"}, {"X-API-Key": "beta-secret"}
PROBLEM = "application/problem+json"
#: A job that runs for minutes: it stays queued or running while a test looks at it.
LONG = job(t_final=1e8, samples=2)


def _app(monkeypatch, **env: str) -> TestClient:
    monkeypatch.delenv("REDIS_URL", raising=False)
    monkeypatch.setenv("NONHOLONOMIC_WARM_UP", "false")
    monkeypatch.setenv("NONHOLONOMIC_MAX_T_FINAL", "1e9")
    for name, value in env.items():
        monkeypatch.setenv(f"NONHOLONOMIC_{name}", value)
    get_settings.cache_clear()
    return TestClient(create_app())


@pytest.fixture()
def keyed(monkeypatch) -> Iterator[TestClient]:
    with _app(monkeypatch, API_KEYS="alice:alpha-secret,bob:beta-secret") as client:
        yield client
    get_settings.cache_clear()


def _cancel_all(client: TestClient, headers: dict[str, str]) -> None:
    for item in client.get("/v1/jobs", headers=headers).json()["items"]:
        if item["status"] in ("queued", "running"):
            client.delete(item["location"], headers=headers)


def test_without_a_key_every_v1_route_is_401_and_health_and_docs_are_open(keyed):
    for method, path in (("GET", "/v1/systems"), ("GET", "/v1/jobs"), ("POST", "/v1/jobs"),
                         ("POST", "/v1/brackets/verify"), ("GET", "/v1/paper/claims")):
        r = keyed.request(method, path, json={})
        assert r.status_code == 401 and r.headers["content-type"] == PROBLEM, (path, r.text)
        assert r.json()["type"] == "/problems/unauthorized" and r.headers["www-authenticate"] == "Bearer"
    r = keyed.get("/v1/systems", headers={"Authorization": "Bearer not-a-key"})
    assert r.status_code == 401 and "not one of this service's" in r.json()["detail"]
    assert keyed.get("/health").status_code == 200 and keyed.get("/openapi.json").status_code == 200
    assert (keyed.get("/v1/systems", headers=A).status_code == 200
            and keyed.get("/v1/systems", headers=B).status_code == 200)
    assert "secret" not in keyed.get("/health").text


def test_a_key_sees_and_cancels_only_its_own_jobs(keyed):
    location = keyed.post("/v1/jobs", json=job(), headers=A).headers["location"]
    for path in (location, f"{location}/trajectory", f"{location}/page", f"{location}/plots/integrals.png"):
        r = keyed.get(path, headers=B)
        assert r.status_code == 404 and r.json()["type"] == "/problems/not-found", (path, r.text)
    assert keyed.delete(location, headers=B).status_code == 404
    assert keyed.get(location, headers=A).status_code == 200
    mine = [i["location"] for i in keyed.get("/v1/jobs", headers=A).json()["items"]]
    theirs = [i["location"] for i in keyed.get("/v1/jobs", headers=B).json()["items"]]
    assert location in mine and location not in theirs
    assert keyed.get(f"/v1/jobs/{location.rsplit('/', 1)[1]}-other", headers=A).status_code == 404


def test_a_key_sees_only_its_own_ensembles(keyed):
    body = {"system": job()["system"], "t_final": 5.0, "samples": 3,
            "members": {"sample": {"count": 2, "seed": 7, "level": {"energy": 1.0, "area": 0.0}}}}
    r = keyed.post("/v1/ensembles", json=body, headers=A)
    assert r.status_code == 202, r.text
    location = r.headers["location"]
    for path in (location, f"{location}/members", f"{location}/page"):
        assert keyed.get(path, headers=B).status_code == 404, path
    assert keyed.delete(location, headers=B).status_code == 404
    assert keyed.get(location, headers=A).status_code == 200


def test_rate_limit_per_key_is_429_with_retry_after(monkeypatch):
    with _app(monkeypatch, API_KEYS="alpha-secret,beta-secret", RATE_LIMIT_PER_MINUTE="3") as client:
        assert [client.get("/v1/systems", headers=A).status_code for _ in range(3)] == [200, 200, 200]
        r = client.get("/v1/systems", headers=A)
        assert r.status_code == 429 and r.json()["type"] == "/problems/rate-limited"
        assert 1 <= int(r.headers["retry-after"]) <= 20  # one token in 20 s
        assert client.get("/v1/systems", headers=B).status_code == 200  # another key has its own bucket
    get_settings.cache_clear()


def test_a_key_with_too_many_active_jobs_gets_429(monkeypatch):
    with _app(monkeypatch, API_KEYS="alpha-secret,beta-secret", MAX_ACTIVE_JOBS_PER_KEY="2") as client:
        try:
            assert [client.post("/v1/jobs", json=LONG, headers=A).status_code for _ in range(2)] == [202, 202]
            r = client.post("/v1/jobs", json=LONG, headers=A)
            assert r.status_code == 429 and r.json()["type"] == "/problems/queue-full"
            assert "2 queued or running jobs" in r.json()["detail"] and r.headers["retry-after"] == "10"
            assert client.post("/v1/jobs", json=job(), headers=B).status_code == 202  # B is not bound by A's
            _cancel_all(client, A)
            assert client.post("/v1/jobs", json=job(), headers=A).status_code == 202
        finally:
            _cancel_all(client, A)
    get_settings.cache_clear()


def test_a_full_queue_is_429_before_anything_is_queued(monkeypatch):
    with _app(monkeypatch, MAX_QUEUED_MESSAGES="1") as client:
        try:
            first = client.post("/v1/jobs", json=LONG).headers["location"]
            import time

            for _ in range(200):  # the one thread takes it: nothing waits
                if client.get(first).json()["status"] == "running":
                    break
                time.sleep(0.01)
            assert client.post("/v1/jobs", json=LONG).status_code == 202  # waits for the thread
            before = len(client.get("/v1/jobs").json()["items"])
            r = client.post("/v1/jobs", json=LONG)
            assert r.status_code == 429 and "1 jobs and ensemble chunks wait" in r.json()["detail"]
            assert len(client.get("/v1/jobs").json()["items"]) == before
        finally:
            _cancel_all(client, {})
    get_settings.cache_clear()


def test_idempotency_key_replays_the_first_answer_and_refuses_another_body(keyed):
    headers = {**A, "Idempotency-Key": "run-42"}
    first = keyed.post("/v1/jobs", json=job(), headers=headers)
    again = keyed.post("/v1/jobs", json=job(), headers=headers)
    assert first.status_code == again.status_code == 202
    assert again.json() == first.json() and again.headers["location"] == first.headers["location"]
    assert again.headers["idempotent-replayed"] == "true" and "idempotent-replayed" not in first.headers
    reordered = dict(reversed(list(job().items())))  # the same JSON, keys in another order
    assert keyed.post("/v1/jobs", json=reordered, headers=headers).json()["id"] == first.json()["id"]
    other = keyed.post("/v1/jobs", json=job(t_final=21.0), headers=headers)
    assert other.status_code == 422 and other.json()["errors"][0]["field"] == "Idempotency-Key"
    report = keyed.post("/v1/paper/report", json={"claims": ["general.bracket"]}, headers=headers)  # another path
    assert report.status_code == 422 and report.json()["errors"][0]["field"] == "Idempotency-Key"
    theirs = keyed.post("/v1/jobs", json=job(), headers={**B, "Idempotency-Key": "run-42"})
    assert theirs.status_code == 202 and theirs.json()["id"] != first.json()["id"]  # keys are per owner
    jobs = [i["id"] for i in keyed.get("/v1/jobs", headers=A).json()["items"]]
    assert jobs.count(first.json()["id"]) == 1 and len(jobs) == 1
    bad = keyed.post("/v1/jobs", json=job(), headers={**A, "Idempotency-Key": "x" * 256})
    assert bad.status_code == 422 and bad.json()["errors"][0]["field"] == "Idempotency-Key"


def test_an_invalid_request_frees_its_idempotency_key(keyed):
    headers = {**A, "Idempotency-Key": "fix-and-retry"}
    bad = job(t_final=-1.0)
    assert keyed.post("/v1/jobs", json=bad, headers=headers).status_code == 422
    assert keyed.post("/v1/jobs", json=job(), headers=headers).status_code == 202


def test_cors_allows_the_configured_origins_only(monkeypatch):
    with _app(monkeypatch, CORS_ORIGINS="https://lab.example.org") as client:
        preflight = {"Origin": "https://lab.example.org", "Access-Control-Request-Method": "POST",
                     "Access-Control-Request-Headers": "content-type,idempotency-key"}
        r = client.options("/v1/jobs", headers=preflight)
        assert r.status_code == 200 and r.headers["access-control-allow-origin"] == "https://lab.example.org"
        r = client.options("/v1/jobs", headers={**preflight, "Origin": "https://elsewhere.example.com"})
        assert "access-control-allow-origin" not in r.headers
        r = client.post("/v1/jobs", json=job(), headers={"Origin": "https://lab.example.org"})
        assert r.headers["access-control-allow-origin"] == "https://lab.example.org"
        assert "Location" in r.headers["access-control-expose-headers"]
    with _app(monkeypatch, CORS_ORIGINS="") as client:  # the default: no CORS headers
        assert "access-control-allow-origin" not in client.get("/v1/systems", headers={"Origin": "https://x.org"}).headers
    get_settings.cache_clear()
