"""Issue 37, items 1-2 in embedded mode (in-process): ``GET /metrics`` and ``X-Request-ID``.

The numbers are read before and after: each event moves its own series by exactly what happened (a
job submitted and succeeded, an integration and its crossings, a refusal, a request counted by its route
template and status). Queue mode (a real worker, its own metrics port, the task events, the request id in
the worker's lines) is tests/integration/test_observability.py.
"""

from __future__ import annotations

import io
import json
import logging
import time
from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from nonholonomic_client.errors import ApiError
from schemas.settings import get_settings
from service.main import create_app
from tests.api.conftest import job
from tests.support import Samples, metric_samples
from workers.logs import REQUEST_ID, ContextFilter, formatter, request_id_from

A = {"Authorization": "Bearer alpha-secret"}
#: A section job: some crossings of the plane gamma3 = 0.
SECTION = job(t_final=200.0, samples=20, poincare={"surface": "gamma3", "max_points": 40})


def _app(monkeypatch, **env: str) -> TestClient:
    monkeypatch.delenv("REDIS_URL", raising=False)
    monkeypatch.setenv("NONHOLONOMIC_WARM_UP", "false")
    for name, value in env.items():
        monkeypatch.setenv(f"NONHOLONOMIC_{name}", value)
    get_settings.cache_clear()
    return TestClient(create_app())


@pytest.fixture()
def client(monkeypatch) -> Iterator[TestClient]:
    with _app(monkeypatch, MAX_T_FINAL="1e9") as c:
        yield c
    get_settings.cache_clear()


def samples(client: TestClient, headers: dict[str, str] | None = None) -> Samples:
    """Every sample of ``/metrics``."""
    r = client.get("/metrics", headers=headers or {})
    assert r.status_code == 200, r.text
    assert r.headers["content-type"].startswith("text/plain; version=0.0.4")
    return metric_samples(r.text)


def value(found: Samples, name: str, **labels: str) -> float:
    """The one sample ``name`` with exactly ``labels``."""
    return found.get((name, frozenset(labels.items())), 0.0)


def _wait(client: TestClient, location: str, timeout: float = 120.0) -> dict:
    end = time.monotonic() + timeout  # a hang guard, not the result
    while time.monotonic() < end:
        view = client.get(location).json()
        if view["status"] in ("succeeded", "failed", "cancelled"):
            return view
        time.sleep(0.05)
    raise AssertionError(f"{location} did not end within {timeout} s")


def test_a_job_moves_its_counters_by_exactly_what_happened(client):
    before = samples(client)
    r = client.post("/v1/jobs", json=SECTION)
    assert r.status_code == 202, r.text
    view = _wait(client, r.headers["location"])
    assert view["status"] == "succeeded", view
    crossings = view["result"]["poincare"]["count"]
    assert crossings > 0
    after = samples(client)

    def moved(name: str, **labels: str) -> float:
        return value(after, name, **labels) - value(before, name, **labels)

    assert moved("nonholonomic_jobs_submitted_total", kind="chaplygin_ball") == 1
    assert moved("nonholonomic_jobs_finished_total", kind="chaplygin_ball", status="succeeded") == 1
    assert moved("nonholonomic_jobs", status="succeeded") == 1 and value(after, "nonholonomic_active_jobs") == 0
    # the trajectory and the section: two integrations; the section's crossings, each once
    assert moved("nonholonomic_integrations_total") == 2
    assert moved("nonholonomic_crossings_total") == crossings
    assert moved("http_requests_total", handler="/v1/jobs", method="POST", status="202") == 1
    assert moved("http_requests_total", handler="/v1/jobs/{job_id}", method="GET", status="200") >= 1
    assert moved("http_request_duration_seconds_count", handler="/v1/jobs", method="POST", status="202") == 1
    assert value(after, "nonholonomic_symbolic_pool_size") == get_settings().symbolic_workers
    assert value(after, "nonholonomic_queue_depth", queue=get_settings().queue) == 0
    assert value(after, "nonholonomic_worker_resident_memory_bytes") > 50e6  # this process: > 50 MB with heyoka
    scrapes = frozenset({("handler", "/metrics"), ("method", "GET"), ("status", "200")})
    assert ("http_requests_total", scrapes) not in after


def test_a_cancelled_job_and_an_unknown_route_are_counted_by_template(client):
    before = samples(client)
    location = client.post("/v1/jobs", json=job(t_final=1e8, samples=2)).headers["location"]
    assert client.delete(location).status_code == 202
    assert _wait(client, location)["status"] == "cancelled"
    assert client.get("/v1/no-such-route").status_code == 404
    after = samples(client)
    assert (value(after, "nonholonomic_jobs_cancelled_total", kind="chaplygin_ball")
            - value(before, "nonholonomic_jobs_cancelled_total", kind="chaplygin_ball")) == 1
    assert value(after, "nonholonomic_jobs", status="cancelled") - value(before, "nonholonomic_jobs",
                                                                         status="cancelled") == 1
    # the path itself is not a label (unbounded): untemplated routes are grouped as "none"
    assert not any("no-such-route" in str(labels) for _, labels in after)
    assert value(after, "http_requests_total", handler="none", method="GET", status="404") >= 1


def test_admission_refusals_are_counted_by_reason(monkeypatch):
    with _app(monkeypatch, API_KEYS="alice:alpha-secret", MAX_ACTIVE_JOBS_PER_KEY="1", MAX_T_FINAL="1e9") as c:
        before = value(samples(c, A), "nonholonomic_admission_refusals_total", reason="too_many_jobs")
        long = job(t_final=1e8, samples=2)
        location = c.post("/v1/jobs", json=long, headers=A).headers["location"]
        refused = [c.post("/v1/jobs", json=long, headers=A).status_code for _ in range(2)]
        assert refused == [429, 429]
        assert value(samples(c, A), "nonholonomic_admission_refusals_total", reason="too_many_jobs") == before + 2
        assert c.delete(location, headers=A).status_code == 202
    get_settings.cache_clear()


def test_metrics_ask_for_a_key_when_keys_are_on_and_can_be_turned_off(monkeypatch):
    with _app(monkeypatch, API_KEYS="alice:alpha-secret") as c:
        r = c.get("/metrics")
        assert r.status_code == 401 and r.headers["content-type"] == "application/problem+json"
        assert "secret" not in c.get("/metrics", headers=A).text
        assert value(samples(c, A), "nonholonomic_jobs", status="queued") == 0
    with _app(monkeypatch, API_KEYS="", METRICS="false") as c:
        assert c.get("/metrics").status_code == 404
        assert c.get("/health").status_code == 200
    get_settings.cache_clear()


def test_every_answer_carries_the_request_id_given_or_made(client):
    r = client.get("/health", headers={"X-Request-ID": "lab-7.run:3"})
    assert r.headers["x-request-id"] == "lab-7.run:3"
    made = client.get("/v1/systems").headers["x-request-id"]
    assert len(made) == 32 and int(made, 16) >= 0
    assert client.get("/v1/systems").headers["x-request-id"] != made
    # a header that could forge log lines or is too long is replaced, not echoed
    for bad in ("a b", "x" * 129, 'q"}{'):
        echoed = client.get("/health", headers={"X-Request-ID": bad}).headers["x-request-id"]
        assert echoed != bad and len(echoed) == 32
    # errors carry it too: a 404 problem and a 422; the Python client's ApiError keeps it to quote
    missing = client.get("/v1/jobs/nope", headers={"X-Request-ID": "e1"})
    assert missing.headers["x-request-id"] == "e1" and ApiError.from_response(missing).request_id == "e1"
    assert client.post("/v1/jobs", json={}, headers={"X-Request-ID": "e2"}).headers["x-request-id"] == "e2"


def test_a_json_log_line_names_its_request_and_job():
    stream = io.StringIO()
    handler = logging.StreamHandler(stream)
    handler.setFormatter(formatter("json"))
    handler.addFilter(ContextFilter())
    log = logging.getLogger("tests.metrics.json")
    log.addHandler(handler)
    log.setLevel(logging.INFO)
    token = REQUEST_ID.set(request_id_from("r-1"))
    try:
        log.info("job submitted", extra={"job_id": "j-1", "kind": "chaplygin_ball"})
    finally:
        REQUEST_ID.reset(token)
        log.removeHandler(handler)
    line = json.loads(stream.getvalue())
    assert line["message"] == "job submitted" and line["level"] == "INFO"
    assert line["request_id"] == "r-1" and line["job_id"] == "j-1" and line["kind"] == "chaplygin_ball"
    assert line["time"].endswith("+00:00")


def test_a_store_that_cannot_be_read_leaves_its_gauges_out_and_the_scrape_answers(client, monkeypatch, caplog):
    def away() -> dict[str, int]:
        raise ConnectionError("the database is away\nsecond line")

    monkeypatch.setattr(client.app.state.backend.store, "count_by_status", away)
    with caplog.at_level(logging.WARNING, logger="service.metrics"):
        found = samples(client)
    names = {name for name, _ in found}
    assert "nonholonomic_jobs" not in names and "nonholonomic_active_jobs" not in names
    assert "nonholonomic_symbolic_pool_size" in names and "nonholonomic_queue_depth" in names
    assert "metrics: the store not read (ConnectionError: the database is away)" in caplog.text


def test_a_text_log_line_names_its_ids_only_where_there_are_any():
    record = logging.LogRecord("service.x", logging.INFO, __file__, 1, "job submitted", None, None)
    ContextFilter().filter(record)
    assert formatter("text").format(record).endswith(" INFO service.x job submitted")
    record.request_id, record.job_id = "r-2", "j-2"
    assert formatter("text").format(record).endswith(" INFO service.x [request_id=r-2 job_id=j-2] job submitted")
