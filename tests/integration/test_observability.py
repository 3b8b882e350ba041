"""Issue 37, items 1-2 in queue mode: a real API, a real Celery worker (prefork, two pool processes), Redis
and PostgreSQL.

* The worker's ``/metrics`` (its own port) adds up both pool processes: every job counted once, none lost
  to the prefork pool (prometheus-client's multiprocess mode).
* Celery's task events are on: a receiver on the broker (what Flower and celery-exporter read) sees each
  job sent, received, started and succeeded.
* One request id finds the request, its job and the worker's lines: the API's ``job submitted`` line and
  the worker's ``job ended`` line carry the client's ``X-Request-ID``.
"""

from __future__ import annotations

import json
import subprocess
import threading
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from celery import Celery

from tests.support import (
    TEST_REDIS_URL,
    Samples,
    free_port,
    metric_samples,
    metric_total,
    poll_job,
    redis_available,
    start_api,
    start_worker,
    stop,
    wait_healthy,
    wait_until,
)

pytestmark = pytest.mark.integration

JOBS = 6
BODY = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
        "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 50.0, "samples": 11}
#: Hang guards (a loaded 2-core machine), never the result.
START_S, JOB_S = 240.0, 120.0


class Events:
    """Celery task events as a monitor receives them from the broker (Flower's and celery-exporter's way)."""

    def __init__(self, broker: str) -> None:
        self.app = Celery(broker=broker)
        self.seen: list[dict[str, Any]] = []
        self.ready = threading.Event()
        self.receiver: Any = None
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        with self.app.connection() as connection:
            self.receiver = self.app.events.Receiver(connection, handlers={"*": self.seen.append})
            self.ready.set()
            self.receiver.capture(limit=None, timeout=None, wakeup=False)  # until should_stop

    def stop(self) -> None:
        if self.receiver is not None:
            self.receiver.should_stop = True
        self.thread.join(10)

    def types(self, task_id: str) -> set[str]:
        return {e["type"] for e in list(self.seen) if e.get("uuid") == task_id}


def _samples(url: str) -> Samples:
    return metric_samples(httpx.get(url, timeout=10).text)


def _json_lines(path: Path) -> list[dict[str, Any]]:
    lines = []
    for line in path.read_text().splitlines():
        try:
            lines.append(json.loads(line))
        except ValueError:
            continue  # Celery's banner
    return lines


@pytest.fixture(scope="module")
def stack(tmp_path_factory) -> Iterator[dict[str, Any]]:
    if not redis_available():
        pytest.fail(f"no Redis at {TEST_REDIS_URL}: run the README's test command, which starts one")
    logs = tmp_path_factory.mktemp("observability")
    queue = f"test-obs-{uuid.uuid4().hex[:8]}"
    api_port, metrics_port = free_port(), free_port()
    processes: list[subprocess.Popen] = []
    events = Events(TEST_REDIS_URL)
    events.thread.start()
    try:
        processes.append(start_worker(TEST_REDIS_URL, queue, logs / "worker.log", concurrency=2,
                                      extra_env={"NONHOLONOMIC_WORKER_METRICS_PORT": str(metrics_port)}))
        processes.append(start_api(api_port, logs / "api.log", {"REDIS_URL": TEST_REDIS_URL,
                                                                 "NONHOLONOMIC_QUEUE": queue}))
        base = f"http://127.0.0.1:{api_port}"
        wait_healthy(base, START_S)
        assert events.ready.wait(START_S)
        yield {"base": base, "worker_metrics": f"http://127.0.0.1:{metrics_port}/metrics", "logs": logs,
               "queue": queue, "events": events}
    except BaseException:
        for p in sorted(logs.glob("*.log")):
            print(f"--- {p.name}\n{p.read_text()[-4000:]}")
        raise
    finally:
        events.stop()
        for proc in reversed(processes):
            stop(proc)


def test_jobs_are_counted_once_across_the_pool_seen_as_events_and_followed_by_their_request_id(stack):
    base, events = stack["base"], stack["events"]
    before = _samples(stack["worker_metrics"])
    api_before = _samples(f"{base}/metrics")
    ids: dict[str, str] = {}
    with httpx.Client(base_url=base, timeout=10) as client:
        for i in range(JOBS):
            request_id = f"obs-{uuid.uuid4().hex[:6]}-{i}"
            r = client.post("/v1/jobs", json=BODY, headers={"X-Request-ID": request_id})
            assert r.status_code == 202 and r.headers["x-request-id"] == request_id, r.text
            ids[r.json()["id"]] = request_id
        for job_id in ids:
            assert poll_job(client, f"/v1/jobs/{job_id}", JOB_S, interval=0.05)["status"] == "succeeded"

    # The worker's metrics: both pool processes' counts, added up, each job once.
    simulate = "nonholonomic.simulate"
    wait_until(lambda: metric_total(_samples(stack["worker_metrics"]), "nonholonomic_tasks_total", task=simulate,
                              status="succeeded") - metric_total(before, "nonholonomic_tasks_total", task=simulate,
                                                          status="succeeded") >= JOBS, 30, "the last task's count")
    after = _samples(stack["worker_metrics"])

    def moved(name: str, **labels: str) -> float:
        return metric_total(after, name, **labels) - metric_total(before, name, **labels)

    assert moved("nonholonomic_tasks_total", task=simulate, status="succeeded") == JOBS
    assert moved("nonholonomic_task_duration_seconds_count", task=simulate, status="succeeded") == JOBS
    assert moved("nonholonomic_jobs_finished_total", kind="chaplygin_ball", status="succeeded") == JOBS
    assert moved("nonholonomic_integrations_total") == JOBS  # one trajectory each, no section
    assert moved("nonholonomic_crossings_total") == 0
    pids = {dict(labels)["pid"] for (name, labels) in after if name == "nonholonomic_worker_resident_memory_bytes"}
    assert len(pids) == 2, pids  # the two pool processes, each its own series
    assert all(100e6 < metric_total(after, "nonholonomic_worker_resident_memory_bytes", pid=pid) < 8e9 for pid in pids)

    # The API's: submitted, in the store, the live worker serving the queue.
    api = _samples(f"{base}/metrics")
    assert (metric_total(api, "nonholonomic_jobs_submitted_total", kind="chaplygin_ball")
            - metric_total(api_before, "nonholonomic_jobs_submitted_total", kind="chaplygin_ball")) == JOBS
    assert metric_total(api, "nonholonomic_jobs", status="succeeded") == JOBS
    assert metric_total(api, "nonholonomic_active_jobs") == 0 and metric_total(api, "nonholonomic_workers_alive") == 1
    assert metric_total(api, "nonholonomic_queue_depth", queue=stack["queue"]) == 0
    assert metric_total(api, "http_requests_total", handler="/v1/jobs", method="POST", status="202") == JOBS

    # Task events on the broker, as a monitor sees them.
    lifecycle = {"task-sent", "task-received", "task-started", "task-succeeded"}
    wait_until(lambda: all(lifecycle <= events.types(job_id) for job_id in ids), 30, "every job's task events")

    # One id: the API's line of the request, the worker's lines of its job.
    api_lines, worker_lines = _json_lines(stack["logs"] / "api.log"), _json_lines(stack["logs"] / "worker.log")
    for job_id, request_id in ids.items():
        submitted = [x for x in api_lines if x.get("message") == "job submitted" and x.get("job_id") == job_id]
        assert [x["request_id"] for x in submitted] == [request_id]
        access = [x for x in api_lines if x.get("logger") == "uvicorn.access" and x.get("request_id") == request_id]
        assert [(x["method"], x["path"], x["status"]) for x in access] == [("POST", "/v1/jobs", 202)]
        ended = [x for x in worker_lines if x.get("request_id") == request_id]
        assert any(x["message"] == "job ended: succeeded" and x["job_id"] == job_id for x in ended), ended
        assert all(x["job_id"] == job_id for x in ended)



def test_a_job_s_own_failure_is_not_a_task_failure(stack):
    """A job that fails for its own reason (here a request the worker refuses, sent straight to the broker)
    is a task that ``job_failed`` and a job ended ``failed``; ``failed`` tasks stay for the unexpected, which
    the failure-rate alert watches."""
    simulate = "nonholonomic.simulate"
    before = _samples(stack["worker_metrics"])
    sender = Celery(broker=TEST_REDIS_URL)
    job_id = f"straight-{uuid.uuid4().hex[:8]}"
    sender.send_task(simulate, args=[{"system": {"kind": "no-such-kind"}, "t_final": 1.0}], task_id=job_id,
                     queue=stack["queue"])

    def moved(name: str, **labels: str) -> float:
        return metric_total(_samples(stack["worker_metrics"]), name, **labels) - metric_total(before, name, **labels)

    wait_until(lambda: moved("nonholonomic_tasks_total", task=simulate) >= 1, JOB_S, "the refused job's task")
    assert moved("nonholonomic_tasks_total", task=simulate, status="job_failed") == 1
    assert moved("nonholonomic_tasks_total", task=simulate, status="failed") == 0
    assert moved("nonholonomic_jobs_finished_total", kind="other", status="failed") == 1
    with httpx.Client(base_url=stack["base"], timeout=10) as client:
        view = client.get(f"/v1/jobs/{job_id}").json()
    assert view["status"] == "failed" and view["error"]["type"] == "InvalidJob", view

def _spans(text: str) -> list[dict[str, Any]]:
    """The spans OpenTelemetry's console exporter wrote into a log: raw JSON objects (the API's standard
    output) or a worker's log lines that carry them (Celery redirects a pool process's standard output)."""
    spans, decoder, at = [], json.JSONDecoder(), 0
    while (at := text.find('{\n    "name"', at)) != -1:
        span, at = decoder.raw_decode(text, at)
        spans.append(span)
    for line in text.splitlines():
        try:
            record = json.loads(line)
        except ValueError:
            continue
        if isinstance(record, dict) and str(record.get("message", "")).startswith('{\n    "name"'):
            spans.append(json.loads(record["message"]))
    return spans


def test_with_otel_variables_one_trace_spans_the_request_and_its_job_in_a_prefork_worker(tmp_path):
    if not redis_available():
        pytest.fail(f"no Redis at {TEST_REDIS_URL}: run the README's test command, which starts one")
    queue = f"test-otel-{uuid.uuid4().hex[:8]}"
    otel = {"OTEL_TRACES_EXPORTER": "console"}
    port = free_port()
    worker = start_worker(TEST_REDIS_URL, queue, tmp_path / "worker.log", extra_env=otel)
    api = start_api(port, tmp_path / "api.log", {"REDIS_URL": TEST_REDIS_URL, "NONHOLONOMIC_QUEUE": queue, **otel})
    base = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(base, START_S)
        with httpx.Client(base_url=base, timeout=10) as client:
            r = client.post("/v1/jobs", json=BODY, headers={"X-Request-ID": "traced-1"})
            assert r.status_code == 202, r.text
            job_id = r.json()["id"]
            assert poll_job(client, r.headers["location"], JOB_S, interval=0.05)["status"] == "succeeded"

        def run_span() -> list[dict[str, Any]]:
            return [s for s in _spans((tmp_path / "worker.log").read_text())
                    if s["name"] == "run/nonholonomic.simulate"
                    and s["attributes"].get("messaging.message.id") == job_id]

        wait_until(run_span, 30, "the worker's span of the job")
        api_spans = _spans((tmp_path / "api.log").read_text())
        request = [s for s in api_spans if s["name"] == "POST /v1/jobs" and s["kind"] == "SpanKind.SERVER"]
        sent = [s for s in api_spans if s["name"] == "apply_async/nonholonomic.simulate"]
        assert len(request) == 1 and len(sent) == 1, [s["name"] for s in api_spans]
        trace_id = request[0]["context"]["trace_id"]
        (run,) = run_span()
        # one trace: the request, the task sent within it, the task run in the pool process
        assert sent[0]["context"]["trace_id"] == trace_id and run["context"]["trace_id"] == trace_id
        assert run["parent_id"] == sent[0]["context"]["span_id"]
        assert run["resource"]["attributes"]["service.name"] == "nonholonomic-worker"
        # and the worker's log line of the job names both ids
        ended = [x for x in _json_lines(tmp_path / "worker.log") if x.get("message") == "job ended: succeeded"]
        assert [(x["request_id"], x["job_id"], x["trace_id"]) for x in ended] == \
            [("traced-1", job_id, trace_id.removeprefix("0x"))]
    except BaseException:
        for p in sorted(tmp_path.glob("*.log")):
            print(f"--- {p.name}\n{p.read_text()[-4000:]}")
        raise
    finally:
        stop(api)
        stop(worker)
