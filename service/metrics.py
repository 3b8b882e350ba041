"""``GET /metrics``: the API's Prometheus metrics (text format 0.0.4).

* requests by route template, method and status, and their durations (prometheus-fastapi-instrumentator:
  ``http_requests_total``, ``http_request_duration_seconds``);
* jobs and ensembles submitted and cancelled, by kind; admission refusals, by reason (counters of this
  API process);
* read at each scrape: jobs in the store by status (``nonholonomic_jobs``), active jobs, the queue's depth,
  workers with a live heartbeat, the symbolic pool's use;
* in embedded mode, where this process runs the jobs, also the work's (:mod:`workers.metrics`): jobs and
  members ended, integrations, crossings, memory (the task metrics are Celery's: none here).

A Celery worker serves its own (:mod:`workers.metrics`, port ``NONHOLONOMIC_WORKER_METRICS_PORT``).
``/metrics`` asks for an API key like every ``/v1`` route when keys are on. One uvicorn process per API
replica: the counters are this process's.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from typing import Any

from fastapi import Depends, FastAPI, Request, Response
from prometheus_client import REGISTRY, CollectorRegistry, Counter, generate_latest
from prometheus_client.core import GaugeMetricFamily
from prometheus_client.registry import Collector
from prometheus_fastapi_instrumentator import Instrumentator, metrics as instrumentator_metrics

from schemas.settings import Settings
from workers.metrics import add_tally, job_kind, note_memory

log = logging.getLogger(__name__)

METRICS_URL = "/metrics"
#: Prometheus' text exposition format.
CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"
#: Request durations (seconds): most answers take milliseconds, a symbolic request seconds.
LATENCY_BUCKETS = (0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0)

JOBS_SUBMITTED = Counter("nonholonomic_jobs_submitted", "Jobs accepted (202) by this API", ["kind"])
ENSEMBLES_SUBMITTED = Counter("nonholonomic_ensembles_submitted", "Ensembles accepted (202) by this API", ["kind"])
JOBS_CANCELLED = Counter("nonholonomic_jobs_cancelled", "Jobs cancelled through this API", ["kind"])
ENSEMBLES_CANCELLED = Counter("nonholonomic_ensembles_cancelled", "Ensembles cancelled through this API")
ADMISSION_REFUSALS = Counter("nonholonomic_admission_refusals",
                             "Requests refused by admission and rate limits (429/503)", ["reason"])


def submitted(request: dict[str, Any]) -> None:
    JOBS_SUBMITTED.labels(job_kind(request)).inc()


def ensemble_submitted(spec: dict[str, Any]) -> None:
    ENSEMBLES_SUBMITTED.labels(job_kind(spec)).inc()


def cancelled(request: dict[str, Any]) -> None:
    JOBS_CANCELLED.labels(job_kind(request)).inc()


def refused(reason: str) -> None:
    """A refusal: ``too_many_jobs``, ``queue_full`` (429), ``symbolic_pool_busy`` (503), ``rate_limited`` (a
    key past its requests a minute) or ``unknown_keys`` (an address sending unknown keys)."""
    ADMISSION_REFUSALS.labels(reason).inc()


class StateCollector(Collector):
    """What the service holds now, read at each scrape (a part that cannot be read is left out and
    logged: the scrape still answers)."""

    def __init__(self, app: FastAPI) -> None:
        self.app = app

    def collect(self) -> Iterator[GaugeMetricFamily]:
        state = self.app.state
        backend = getattr(state, "backend", None)
        settings: Settings = state.settings
        if backend is not None:
            yield from self._guarded("the store", lambda: _store_families(backend))
            yield from self._guarded("the queue", lambda: _queue_families(backend, settings))
        pool = getattr(state, "symbolic_pool", None)
        if pool is not None:
            status = pool.status()
            for name, key, doc in (("busy", "running", "symbolic requests running"),
                                   ("waiting", "waiting", "symbolic requests waiting for a slot"),
                                   ("size", "size", "symbolic requests that may run at once")):
                yield GaugeMetricFamily(f"nonholonomic_symbolic_pool_{name}", doc, value=status[key])

    @staticmethod
    def _guarded(what: str, families: Any) -> Iterator[GaugeMetricFamily]:
        try:
            found = list(families())
        except Exception as exc:  # noqa: BLE001 - an outage: the rest of the scrape still answers
            first_line = next(iter(str(exc).splitlines()), "")
            log.warning("metrics: %s not read (%s: %s)", what, type(exc).__name__, first_line)
            return
        yield from found


def _store_families(backend: Any) -> Iterator[GaugeMetricFamily]:
    counts = backend.job_counts()
    jobs = GaugeMetricFamily("nonholonomic_jobs", "Jobs in the store, by status", labels=["status"])
    for status in ("queued", "running", "succeeded", "failed", "cancelled"):
        jobs.add_metric([status], counts.get(status, 0))
    yield jobs
    yield GaugeMetricFamily("nonholonomic_active_jobs", "Jobs queued or running",
                            value=counts.get("queued", 0) + counts.get("running", 0))


def _queue_families(backend: Any, settings: Settings) -> Iterator[GaugeMetricFamily]:
    depth = GaugeMetricFamily("nonholonomic_queue_depth", "Messages (jobs and ensemble chunks) waiting in the queue",
                              labels=["queue"])
    depth.add_metric([settings.queue], backend.queue_depth())
    yield depth
    alive = backend.live_workers()
    if alive is not None:
        yield GaugeMetricFamily("nonholonomic_workers_alive", "Workers with a live heartbeat serving the queue",
                                value=alive)


def install(app: FastAPI, settings: Settings) -> None:
    """Count the requests and serve ``GET /metrics`` (unless ``settings.metrics`` is off)."""
    if not settings.metrics:
        return
    from service.access import caller  # here: access counts its refusals in this module

    registry = CollectorRegistry()  # this app's: several apps in one process (tests) do not collide
    instrumentator = Instrumentator(should_group_status_codes=False,
                                    excluded_handlers=[f"^{METRICS_URL}$", "^/health/live$"], registry=registry)
    instrumentator.add(instrumentator_metrics.requests(registry=registry),
                       instrumentator_metrics.latency(registry=registry, buckets=LATENCY_BUCKETS))
    instrumentator.instrument(app)
    registry.register(StateCollector(app))

    @app.get(METRICS_URL, tags=["health"], operation_id="metrics-get", dependencies=[Depends(caller)],
             response_class=Response, summary="Prometheus metrics",
             responses={200: {"content": {CONTENT_TYPE: {"schema": {"type": "string"}}},
                              "description": "the metrics in Prometheus' text format"}})
    def metrics_text(request: Request) -> Response:
        """The API's metrics in Prometheus' text format: requests by route and status, jobs and ensembles
        submitted and cancelled, admission refusals, the store's jobs by status, the queue's depth, the live
        workers, the symbolic pool (and in embedded mode the work's: jobs ended, integrations, crossings)."""
        if request.app.state.settings.embedded:  # this process runs the jobs
            add_tally()
            note_memory()
        return Response(generate_latest(REGISTRY) + generate_latest(registry), media_type=CONTENT_TYPE)
