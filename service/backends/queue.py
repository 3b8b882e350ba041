"""Queue mode: jobs go to Celery workers through Redis; the job registry lives in Redis too."""

from __future__ import annotations

import time
import uuid
from typing import Any

import redis
from celery import group
from celery.result import AsyncResult

from schemas.jobs import TERMINAL_STATUSES
from schemas.settings import Settings
from service.backends.base import JobRecord
from workers.celery_app import app as celery_app
from workers.registry import RedisJobRegistry
from workers.ensembles import RedisEnsembleStore
from workers.tasks import ensemble_chunk, simulate_job

#: Celery task state → job status.
#: Seconds a census of the workers stays valid (asking them takes a full inspect timeout).
WORKER_CENSUS_TTL_S = 5.0

_STATUS = {"PENDING": "queued", "RECEIVED": "queued", "RETRY": "queued", "STARTED": "running",
           "PROGRESS": "running", "SUCCESS": "succeeded", "FAILURE": "failed", "REVOKED": "cancelled"}


def _chunk_task_id(ensemble_id: str, chunk: int) -> str:
    return f"{ensemble_id}.chunk-{chunk}"


class QueueBackend:
    """Submits to the Celery queue ``settings.queue``; status and results from the result backend."""

    mode = "queue"

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.redis = redis.Redis.from_url(settings.redis_url or "", socket_timeout=5)
        self.registry = RedisJobRegistry(self.redis, settings.job_ttl_s)
        self.ensembles = RedisEnsembleStore(self.redis, settings.job_ttl_s)
        self._census: tuple[float, dict[str, list[str]]] = (-float("inf"), {})

    def submit(self, request: dict[str, Any]) -> JobRecord:
        job_id = str(uuid.uuid4())
        created_at = self.registry.create(job_id, request)
        simulate_job.apply_async(args=[request], task_id=job_id, queue=self.settings.queue)
        return JobRecord(job_id, "queued", 0.0, created_at, request)

    def get(self, job_id: str) -> JobRecord | None:
        entry = self.registry.get(job_id)
        if entry is None:
            return None
        outcome = AsyncResult(job_id, app=celery_app)
        state = outcome.state
        status = _STATUS.get(state, "running")
        record = JobRecord(job_id, status, 0.0, entry["created_at"], entry["request"])
        if entry["cancelled"] and status not in ("succeeded", "failed"):
            record.status = "cancelled"
        if status == "succeeded":
            record.result, record.progress = outcome.result, 1.0
        elif status == "failed":
            exc = outcome.result
            record.error = {"type": type(exc).__name__, "message": str(exc)}
        elif state == "PROGRESS" and isinstance(outcome.info, dict):
            record.progress = float(outcome.info.get("progress", 0.0))
        return record

    def cancel(self, job_id: str) -> JobRecord | None:
        record = self.get(job_id)
        if record is None or record.status in TERMINAL_STATUSES:
            return record
        self.registry.cancel(job_id)  # a running job sees this within a progress interval
        celery_app.control.revoke(job_id)  # a queued job is dropped by the worker that receives it
        record.status = "cancelled"
        return record

    def submit_ensemble(self, request: dict[str, Any], chunks: list[tuple[int, int]]) -> tuple[str, str]:
        ensemble_id = str(uuid.uuid4())
        created_at = self.ensembles.create(ensemble_id, request, chunks)
        group(ensemble_chunk.si(ensemble_id, i).set(task_id=_chunk_task_id(ensemble_id, i), queue=self.settings.queue)
              for i in range(len(chunks))).apply_async()
        return ensemble_id, created_at

    def cancel_ensemble(self, ensemble_id: str) -> None:
        record = self.ensembles.record(ensemble_id)
        self.ensembles.cancel(ensemble_id)  # running chunks see it within their progress interval
        if record is not None:  # queued chunks are dropped by the worker that receives them
            celery_app.control.revoke([_chunk_task_id(ensemble_id, i) for i in range(len(record["chunks"]))
                                       if i not in record["done"]])

    def health(self) -> dict[str, Any]:
        try:
            self.redis.ping()
            broker = "ok"
        except redis.RedisError as exc:
            broker = f"unreachable: {exc}"
        workers: dict[str, list[str]] = {}
        if broker == "ok":
            workers = self._workers()
        serving = [w for w, queues in workers.items() if self.settings.queue in queues]
        return {"ok": broker == "ok" and bool(serving), "mode": self.mode, "broker": broker,
                "queue": self.settings.queue, "workers": workers}

    def _workers(self) -> dict[str, list[str]]:
        """Queues consumed by each live worker, cached for :data:`WORKER_CENSUS_TTL_S` when non-empty."""
        taken_at, workers = self._census
        if workers and time.monotonic() - taken_at < WORKER_CENSUS_TTL_S:
            return workers
        replies = celery_app.control.inspect(timeout=1.0).active_queues() or {}
        workers = {name: [q["name"] for q in queues] for name, queues in replies.items()}
        self._census = (time.monotonic(), workers)
        return workers

    def close(self) -> None:
        self.redis.close()
