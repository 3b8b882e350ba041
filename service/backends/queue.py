"""Queue mode: jobs go to Celery workers through Redis; the job registry lives in Redis too.

Jobs sent straight to the queue by a job-queue client (``send_task("nonholonomic.simulate", ...)``)
are jobs like any other: the task registers its job when it starts, and this backend registers one
still waiting in the broker when asked for its id (``GET /v1/jobs/{id}``) or when listing the first
page, reading at most :data:`BROKER_SCAN_LIMIT` messages of the queue (and, for an id, of the
messages workers reserved but did not start yet).
"""

from __future__ import annotations

import uuid
from typing import Any

import redis
from celery import group
from celery.result import AsyncResult

from schemas.jobs import TERMINAL_STATUSES
from schemas.settings import Settings
from service.access import visible
from service.backends.base import JobRecord, decode_cursor, encode_cursor
from workers.celery_app import app as celery_app
from workers.ensembles import RedisEnsembleStore
from workers.heartbeat import census
from workers.registry import (
    RedisJobRegistry,
    parse_task_message,
    queued_messages,
    request_from_args,
    reserved_messages,
)
from workers.tasks import ensemble_chunk, simulate_job

#: Messages of the queue read, at most, to find jobs sent straight to the broker (all of them when the
#: queue is no longer; else its newest and oldest halves). One such scan per unknown id and per first
#: page of the list.
BROKER_SCAN_LIMIT = 1000
#: Index entries read, at most, for one page of a list with a status filter (the page is then shorter
#: than asked, with a next cursor after the last entry read).
LIST_SCAN_LIMIT = 2000
#: Index entries read per round trip while listing.
LIST_BATCH = 200

#: Seconds /health waits for Redis.
HEALTH_TIMEOUT_S = 0.05

#: Celery task state → job status.
_STATUS = {"PENDING": "queued", "RECEIVED": "queued", "RETRY": "queued", "STARTED": "running",
           "PROGRESS": "running", "SUCCESS": "succeeded", "FAILURE": "failed", "REVOKED": "cancelled"}


def _job_status(state: str, info: Any, cancelled: bool) -> tuple[str, float]:
    """``(status, progress)`` of a job from its Celery state and info and its cancellation flag."""
    status = _STATUS.get(state, "running")
    if cancelled and status not in ("succeeded", "failed"):
        status = "cancelled"
    if status == "succeeded":
        return status, 1.0
    if state == "PROGRESS" and isinstance(info, dict):
        return status, float(info.get("progress", 0.0))
    return status, 0.0


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
        # /health answers within its deadline even when Redis does not
        self._health_redis = redis.Redis.from_url(settings.redis_url or "", socket_timeout=HEALTH_TIMEOUT_S,
                                                  socket_connect_timeout=HEALTH_TIMEOUT_S)

    def submit(self, request: dict[str, Any], owner: str | None = None) -> JobRecord:
        job_id = str(uuid.uuid4())
        created_at = self.registry.create(job_id, request, owner)
        simulate_job.apply_async(args=[request], task_id=job_id, queue=self.settings.queue)
        return JobRecord(job_id, "queued", 0.0, created_at, request, owner=owner)

    def get(self, job_id: str) -> JobRecord | None:
        entry = self.registry.get(job_id) or self._discover(job_id)
        if entry is None:
            return None
        outcome = AsyncResult(job_id, app=celery_app)
        state = outcome.state
        status, progress = _job_status(state, outcome.info, entry["cancelled"])
        record = JobRecord(job_id, status, progress, entry["created_at"], entry["request"], owner=entry["owner"])
        if status == "succeeded":
            record.result = outcome.result
        elif status == "failed":
            exc = outcome.result
            record.error = {"type": type(exc).__name__, "message": str(exc)}
        return record

    def _discover(self, job_id: str) -> dict[str, Any] | None:
        """Register a job a job-queue client sent straight to the queue, if its message is still there:
        waiting in the queue, or taken by a worker that has not started it yet (kombu's ``unacked``)."""
        needle = job_id.encode()
        unacked_key = (celery_app.conf.broker_transport_options or {}).get("unacked_key", "unacked")
        for raw in [*queued_messages(self.redis, self.settings.queue, BROKER_SCAN_LIMIT),
                    *reserved_messages(self.redis, self.settings.queue, BROKER_SCAN_LIMIT, unacked_key)]:
            if needle not in raw:
                continue
            parsed = parse_task_message(raw)
            if parsed is not None and parsed[0] == job_id:
                self.registry.ensure(job_id, request_from_args(parsed[1], parsed[2])[0])
                return self.registry.get(job_id)
        return None

    def _discover_all(self) -> None:
        """Register every job waiting in the queue's (scanned part) that the registry does not know."""
        found = {}
        for raw in queued_messages(self.redis, self.settings.queue, BROKER_SCAN_LIMIT):
            parsed = parse_task_message(raw)
            if parsed is not None:
                found[parsed[0]] = parsed
        ids = list(found)
        for job_id, known in zip(ids, self.registry.exists_many(ids)):
            if not known:
                self.registry.ensure(job_id, request_from_args(found[job_id][1], found[job_id][2])[0])

    def list_jobs(self, status: str | None, limit: int, cursor: str | None,
                  owner: str | None = None) -> tuple[list[JobRecord], str | None]:
        """Newest first from the index ``nonholonomic:jobs``; statuses from the records (terminal ones the
        worker wrote) or the result backend (queued and running ones: small), never the results.

        With a status filter at most :data:`LIST_SCAN_LIMIT` index entries are read per page; if the
        page is not full by then it ends early with a cursor after the last entry read.
        """
        after = decode_cursor(cursor) if cursor is not None else None
        if after is None:
            self._discover_all()
        page: list[JobRecord] = []
        expired: list[str] = []
        position = after  # the last (score, id) read
        scanned = 0
        more = True
        while len(page) < limit and scanned < LIST_SCAN_LIMIT:
            # Unfiltered, one entry more than the page needs says whether there is a next page.
            filtered = status is not None or owner is not None
            want = LIST_BATCH if filtered else min(LIST_BATCH, limit - len(page) + 1)
            batch = self._after(position, want)
            if not batch:
                more = False
                break
            entries = self.registry.get_many([job_id for job_id, _ in batch])
            records = self._light_records(batch, entries)
            for n, ((job_id, score), record) in enumerate(zip(batch, records), 1):
                scanned += 1
                position = (score, job_id)
                if record is None:
                    expired.append(job_id)
                elif (status is None or record.status == status) and visible(record.owner, owner):
                    page.append(record)
                    if len(page) == limit:
                        more = n < len(batch) or bool(self._after(position, 1))
                        break
            else:
                if len(batch) < want:
                    more = False
                    break
        self.registry.prune(expired)
        return page, encode_cursor(*position) if more and position is not None else None

    def _after(self, position: tuple[float, str] | None, count: int) -> list[tuple[str, float]]:
        """Up to ``count`` index entries strictly after ``position`` in (score, id) descending order."""
        if position is None:
            return self.registry.newest(None, count)
        score, last = position
        want = count
        while True:  # entries tied with ``position`` (same score) that come before it are skipped
            batch = self.registry.newest(score, want)
            kept = [(j, s) for j, s in batch if s < score or j < last]
            if len(kept) >= count or len(batch) < want:
                return kept[:count]
            want = count + len(batch) - len(kept)  # the skipped ones head the batch: read past them

    def _light_records(self, batch: list[tuple[str, float]],
                       entries: list[dict[str, Any] | None]) -> list[JobRecord | None]:
        """Records without results: the worker's recorded terminal status, else the task's state."""
        backend = celery_app.backend
        pending = [job_id for (job_id, _), e in zip(batch, entries) if e is not None and e["status"] is None]
        metas: dict[str, Any] = {}
        if pending:
            pipe = self.redis.pipeline(transaction=False)
            for job_id in pending:
                pipe.get(backend.get_key_for_task(job_id))
            metas = {job_id: backend.decode(raw) if raw is not None else None
                     for job_id, raw in zip(pending, pipe.execute())}
        records: list[JobRecord | None] = []
        for (job_id, _), entry in zip(batch, entries):
            if entry is None:
                records.append(None)
                continue
            if entry["status"] is not None:
                status, progress = entry["status"], 1.0 if entry["status"] == "succeeded" else 0.0
            else:
                meta = metas.get(job_id) or {}
                status, progress = _job_status(meta.get("status", "PENDING"), meta.get("result"), entry["cancelled"])
            records.append(JobRecord(job_id, status, progress, entry["created_at"], entry["request"],
                                     owner=entry["owner"]))
        return records

    def cancel(self, job_id: str) -> JobRecord | None:
        record = self.get(job_id)
        if record is None or record.status in TERMINAL_STATUSES:
            return record
        self.registry.cancel(job_id)  # a running job sees this within a progress interval
        celery_app.control.revoke(job_id)  # a queued job is dropped by the worker that receives it
        record.status = "cancelled"
        return record

    def submit_ensemble(self, request: dict[str, Any], chunks: list[tuple[int, int]],
                        owner: str | None = None) -> tuple[str, str]:
        ensemble_id = str(uuid.uuid4())
        created_at = self.ensembles.create(ensemble_id, request, chunks, owner)
        group(ensemble_chunk.si(ensemble_id, i).set(task_id=_chunk_task_id(ensemble_id, i), queue=self.settings.queue)
              for i in range(len(chunks))).apply_async()
        return ensemble_id, created_at

    def cancel_ensemble(self, ensemble_id: str) -> None:
        record = self.ensembles.record(ensemble_id)
        self.ensembles.cancel(ensemble_id)  # running chunks see it within their progress interval
        if record is not None:  # queued chunks are dropped by the worker that receives them
            celery_app.control.revoke([_chunk_task_id(ensemble_id, i) for i in range(len(record["chunks"]))
                                       if i not in record["done"]])

    def active_jobs(self, owner: str, enough: int) -> int:
        return self.registry.active_count(owner, enough)

    def queued_messages(self) -> int:
        return int(self.redis.llen(self.settings.queue))

    def health(self) -> dict[str, Any]:
        try:
            workers = census(self._health_redis)
            broker = "ok"
        except redis.RedisError as exc:
            workers, broker = {}, f"unreachable: {type(exc).__name__}"
        serving = {name: w for name, w in workers.items() if self.settings.queue in w["queues"]}
        warm = sum(w["warm_processes"] for w in serving.values())
        detail = None
        if broker != "ok":
            detail = "the broker cannot be reached: jobs cannot be queued"
        elif not serving:
            detail = f"no worker consumes the queue '{self.settings.queue}': jobs would wait"
        elif not warm:
            detail = "the workers are compiling the integrators (warm-up): jobs would wait for it"
        return {"ok": detail is None, "mode": self.mode, "broker": broker, "queue": self.settings.queue,
                "workers": workers, **({"detail": detail} if detail else {})}

    def close(self) -> None:
        self.redis.close()
        self._health_redis.close()
