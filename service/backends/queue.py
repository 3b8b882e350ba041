"""Queue mode: jobs are recorded in the job store (PostgreSQL) and go to Celery workers through Redis,
which is only the broker (and carries jobs' progress); ensembles live in the same database.

Jobs sent straight to the queue by a job-queue client (``send_task("nonholonomic.simulate", ...)``)
are jobs like any other: the task records its job when it starts, and this backend records one
still waiting in the broker when asked for its id (``GET /v1/jobs/{id}``) or when listing the first
page, reading at most :data:`BROKER_SCAN_LIMIT` messages of the queue (and, for an id, of the
messages workers reserved but did not start yet). A message looked at once is not parsed again.

Admission is atomic across API processes: an owner's active jobs are counted and its job recorded
under one PostgreSQL advisory lock (:meth:`store.jobs.JobStore.create`), and room in the queue is
reserved in Redis (one Lua script reads the queue's length and the reservations of requests still
sending) before a job's or an ensemble's messages are sent.
"""

from __future__ import annotations

import threading
import time
import uuid
from collections import OrderedDict
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import redis
from celery import group
from celery.result import AsyncResult
from sqlalchemy import create_engine, text

from schemas.settings import Settings
from service.backends.base import JobRecord, QueueFull, decode_cursor, encode_cursor
from store.ensembles import EnsembleStore
from store.idempotency import IdempotencyKeys, KeyBinding
from store.jobs import JobStore, StoredJob
from workers.broker_messages import (
    parse_task_message,
    queued_messages,
    request_from_args,
    reserved_messages,
)
from workers.celery_app import app as celery_app
from workers.ensembles import chunk_task_id
from workers.heartbeat import census
from workers.job_store import broker_epoch
from workers.tasks import ensemble_chunk, simulate_job

#: Messages of the queue read, at most, to find jobs sent straight to the broker (all of them when the
#: queue is no longer; else its newest and oldest halves). One such scan per unknown id and per first
#: page of the list.
BROKER_SCAN_LIMIT = 1000
#: Broker messages remembered as looked at (their hashes): a long queue is parsed once, not per page.
SEEN_LIMIT = 20_000
#: Seconds a reservation of room in the queue holds if its request never ends it (an API that died).
RESERVATION_LEASE_S = 60
#: KEYS: the queue's list, the reservations (a sorted set: "token:messages" by expiry, ms).
#: ARGV: messages, bound, lease (ms), token. Returns {admitted 0/1, waiting, pending}.
RESERVE_SCRIPT = """
local clock = redis.call('TIME')
local now = tonumber(clock[1]) * 1000 + math.floor(tonumber(clock[2]) / 1000)
redis.call('ZREMRANGEBYSCORE', KEYS[2], '-inf', now)
local pending = 0
for _, member in ipairs(redis.call('ZRANGE', KEYS[2], 0, -1)) do
  pending = pending + tonumber(string.match(member, ':(%d+)$'))
end
local waiting = redis.call('LLEN', KEYS[1])
local messages = tonumber(ARGV[1])
if waiting + pending + messages > tonumber(ARGV[2]) then return {0, waiting, pending} end
redis.call('ZADD', KEYS[2], now + tonumber(ARGV[3]), ARGV[4] .. ':' .. messages)
redis.call('PEXPIRE', KEYS[2], tonumber(ARGV[3]))
return {1, waiting, pending}
"""
#: Seconds the broker's epoch is cached (one Redis round trip less per submission).
EPOCH_TTL_S = 1.0
#: Seconds /health's check waits for Redis (in a thread of its own: the route answers from its latest
#: check meanwhile, so a reply that a loaded machine reads late is no outage).
HEALTH_TIMEOUT_S = 1.0


def _argsrepr(request: dict[str, Any]) -> str:
    """How the task's argument shows in the worker's logs: the job's kind, not the whole request."""
    system = request.get("system")
    kind = system.get("kind") if isinstance(system, dict) else ("paper report" if "claims" in request else None)
    return f"[<{kind or 'job'} request>]"


class QueueBackend:
    """Jobs recorded in the job store (PostgreSQL, :mod:`store`) and sent to the Celery queue
    ``settings.queue``; workers write their ends and results to the store, progress through Celery."""

    mode = "queue"

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.redis = redis.Redis.from_url(settings.redis_url or "", socket_timeout=5)
        self.store = JobStore(settings.store_url, settings.job_ttl_s)
        self.store.migrate()
        self._epoch: tuple[str, float] | None = None
        self.ensembles = EnsembleStore(self.store.engine, settings.job_ttl_s)
        self.keys = IdempotencyKeys(self.store.engine)
        # /health answers within its deadline even when Redis does not
        self._health_redis = redis.Redis.from_url(settings.redis_url or "", socket_timeout=HEALTH_TIMEOUT_S,
                                                  socket_connect_timeout=HEALTH_TIMEOUT_S)
        # and pings the store on connections of its own, not behind the submissions' for the pool's
        self._health_store = create_engine(
            self.store.engine.url, pool_size=2, max_overflow=0, pool_pre_ping=True,
            connect_args={"connect_timeout": 2} if self.store.engine.dialect.name == "postgresql" else {})
        self._reserve = self.redis.register_script(RESERVE_SCRIPT)
        self._seen: OrderedDict[int, None] = OrderedDict()  # hashes of broker messages already looked at
        self._seen_lock = threading.Lock()

    def submit(self, request: dict[str, Any], owner: str | None = None, max_active: int | None = None,
               binding: KeyBinding | None = None) -> JobRecord:
        """Record the job (with its Idempotency-Key's ``binding``, in one transaction), send it, then
        mark it sent: an API that dies between the two leaves a job the workers' sweep sends
        (:meth:`store.jobs.JobStore.mark_sent`). If the broker refuses, the record and its key are removed
        and the error raised (a 503: nothing was accepted). With ``max_active``, raises
        :class:`store.jobs.ActiveBoundReached` (nothing recorded) if ``owner`` has that many active jobs."""
        job_id = str(uuid.uuid4())
        epoch = self._broker_epoch()
        created_at = self.store.create(job_id, request, owner, self.settings.queue, None, max_active, binding)
        try:
            # ignore_result: the result goes to the job store, so the API does not subscribe to the task's
            # result channel; argsrepr: the logs and events name the job instead of writing out the request
            simulate_job.apply_async(args=[request], task_id=job_id, queue=self.settings.queue, retry=False,
                                     ignore_result=True, argsrepr=_argsrepr(request), kwargsrepr="{}")
        except Exception:
            self.store.delete(job_id, binding.slot if binding is not None else None)
            raise
        self.store.mark_sent(job_id, epoch)
        return JobRecord(job_id, "queued", 0.0, created_at, request, owner=owner)

    def _broker_epoch(self) -> str:
        """The broker's epoch, read at most every :data:`EPOCH_TTL_S`. A job recorded with an epoch
        that has just ended is sent again by the workers' sweep: a second message, which the worker
        that receives it drops (the job runs once), never a lost one."""
        now = time.monotonic()
        if self._epoch is None or now - self._epoch[1] > EPOCH_TTL_S:
            self._epoch = (broker_epoch(self.redis), now)
        return self._epoch[0]

    def _progress(self, job_id: str) -> float:
        """A running job's progress as its worker last reported it (0 if Redis does not answer)."""
        try:
            outcome = AsyncResult(job_id, app=celery_app)
            info = outcome.info if outcome.state == "PROGRESS" else None
        except (redis.RedisError, OSError):
            return 0.0
        return float(info.get("progress", 0.0)) if isinstance(info, dict) else 0.0

    def _record(self, job: StoredJob, progress: bool) -> JobRecord:
        value = 1.0 if job.status == "succeeded" else (self._progress(job.id) if progress and job.status == "running"
                                                       else 0.0)
        return JobRecord(job.id, job.status, value, job.created_at, job.request, result=job.result, error=job.error,
                         owner=job.owner)

    def get(self, job_id: str) -> JobRecord | None:
        job = self.store.get(job_id)
        if job is None and self._discover(job_id):
            job = self.store.get(job_id)
        return None if job is None else self._record(job, progress=True)

    def find(self, job_id: str, owner: str | None) -> JobRecord | None:
        """The job if ``owner`` may see it (:func:`service.access.visible`), else None. An unknown id and
        another owner's do the same work (a visibility lookup, a broker scan, a second lookup), so that
        the time of a 404 does not tell whether the job exists."""
        if owner is None:
            return self.get(job_id)
        if not self.store.visible(job_id, owner):
            self._discover(job_id)  # a job sent straight to the broker has no owner: visible once recorded
            if not self.store.visible(job_id, owner):
                return None
        job = self.store.get(job_id)
        return None if job is None else self._record(job, progress=True)

    def _discover(self, job_id: str) -> bool:
        """Record a job a job-queue client sent straight to the queue, if its message is still there:
        waiting in the queue, or taken by a worker that has not started it yet (kombu's ``unacked``)."""
        needle = job_id.encode()
        unacked_key = (celery_app.conf.broker_transport_options or {}).get("unacked_key", "unacked")
        for raw in [*queued_messages(self.redis, self.settings.queue, BROKER_SCAN_LIMIT),
                    *reserved_messages(self.redis, self.settings.queue, BROKER_SCAN_LIMIT, unacked_key)]:
            if needle not in raw:
                continue
            parsed = parse_task_message(raw)
            if parsed is not None and parsed[0] == job_id:
                self.store.ensure(job_id, request_from_args(parsed[1], parsed[2])[0], self.settings.queue,
                                  self._broker_epoch())
                return True
        return False

    def _discover_all(self) -> None:
        """Record every job waiting in the queue's (scanned part) that the store does not know. Messages
        looked at before are skipped by their hash; the new ones are checked against the store in one
        query, and only a job it does not know is parsed into its request."""
        raws = queued_messages(self.redis, self.settings.queue, BROKER_SCAN_LIMIT)
        with self._seen_lock:
            fresh = [(h, raw) for h, raw in ((hash(raw), raw) for raw in raws) if h not in self._seen]
        if not fresh:
            return
        parsed = [parse_task_message(raw) for _, raw in fresh]
        known = self.store.existing([p[0] for p in parsed if p is not None])
        epoch = self._broker_epoch()
        for p in parsed:
            if p is not None and p[0] not in known:
                self.store.ensure(p[0], request_from_args(p[1], p[2])[0], self.settings.queue, epoch)
        with self._seen_lock:
            self._seen.update((h, None) for h, _ in fresh)
            while len(self._seen) > SEEN_LIMIT:
                self._seen.popitem(last=False)

    def list_jobs(self, status: str | None, limit: int, cursor: str | None,
                  owner: str | None = None) -> tuple[list[JobRecord], str | None]:
        """Newest first by (created_at, id) from the store; exact (the next cursor is None at the end)."""
        after = decode_cursor(cursor) if cursor is not None else None
        if after is None:
            try:
                self._discover_all()
            except redis.RedisError:  # the broker is away: the store still answers
                pass
        jobs, more = self.store.page(status, limit, after, owner)
        next_cursor = encode_cursor(jobs[-1].created, jobs[-1].id) if more else None
        return [self._record(j, progress=False) for j in jobs], next_cursor

    def cancel(self, job_id: str) -> JobRecord | None:
        """A queued job never starts (the store says cancelled; the worker also drops a revoked message);
        a running one stops at its next progress report."""
        if self.store.cancel(job_id):
            celery_app.control.revoke(job_id)
        return self.get(job_id)

    def job_ids_with_prefix(self, prefix: str, owner: str | None) -> list[str]:
        return self.store.with_prefix(prefix, owner)

    def active_jobs(self, owner: str) -> int:
        return self.store.active_count(owner)

    def queued_messages(self) -> int:
        return int(self.redis.llen(self.settings.queue))

    @contextmanager
    def reserve_messages(self, messages: int, bound: int) -> Iterator[None]:
        """Hold room for ``messages`` in the queue while the body sends them: admitted only if the queued
        messages, those other requests are sending and these stay within ``bound`` (one Lua script, atomic
        across API processes); else raises :class:`QueueFull`. A reservation whose API died ends after
        :data:`RESERVATION_LEASE_S`."""
        key = f"nonholonomic:admission:{self.settings.queue}"
        token = uuid.uuid4().hex
        admitted, waiting, pending = self._reserve(keys=[self.settings.queue, key],
                                                   args=[messages, bound, RESERVATION_LEASE_S * 1000, token])
        if not admitted:
            raise QueueFull(int(waiting), int(pending))
        try:
            yield
        finally:
            try:
                self.redis.zrem(key, f"{token}:{messages}")
            except redis.RedisError:  # the lease ends it
                pass

    def submit_ensemble(self, request: dict[str, Any], chunks: list[tuple[int, int]],
                        owner: str | None = None, binding: KeyBinding | None = None) -> tuple[str, str]:
        """Record the ensemble (with its key's ``binding``), send its chunks, mark it sent (as
        :meth:`submit`); if the broker refuses, the record and its key are removed and the error raised
        (a 503: nothing was accepted)."""
        ensemble_id = str(uuid.uuid4())
        epoch = self._broker_epoch()
        created_at = self.ensembles.create(ensemble_id, request, chunks, owner, self.settings.queue, None, binding)
        try:
            group(ensemble_chunk.si(ensemble_id, i).set(task_id=chunk_task_id(ensemble_id, i),
                                                        queue=self.settings.queue)
                  for i in range(len(chunks))).apply_async(retry=False)
        except Exception:
            self.ensembles.delete(ensemble_id, binding.slot if binding is not None else None)
            raise
        self.ensembles.mark_sent(ensemble_id, epoch)
        return ensemble_id, created_at

    def cancel_ensemble(self, ensemble_id: str) -> None:
        record = self.ensembles.record(ensemble_id)
        self.ensembles.cancel(ensemble_id)  # running chunks see it within their progress interval
        if record is not None:  # queued chunks are dropped by the worker that receives them
            celery_app.control.revoke([chunk_task_id(ensemble_id, i) for i in range(len(record["chunks"]))
                                       if i not in record["done"]])

    def health(self) -> dict[str, Any]:
        try:
            workers = census(self._health_redis)
            broker = "ok"
        except redis.TimeoutError:  # no answer yet is no evidence: /health's latest check ages (routes/health.py)
            raise
        except redis.RedisError as exc:
            workers, broker = {}, f"unreachable: {type(exc).__name__}"
        serving = {name: w for name, w in workers.items() if self.settings.queue in w["queues"]}
        warm = sum(w["warm_processes"] for w in serving.values())
        store = "ok" if self._ping_store() else "unreachable"
        detail = None
        if broker != "ok":
            detail = "the broker cannot be reached: jobs cannot be queued"
        elif store != "ok":
            detail = "the job store (PostgreSQL) cannot be reached: jobs cannot be recorded"
        elif not serving:
            detail = f"no worker consumes the queue '{self.settings.queue}': jobs would wait"
        elif not warm:
            detail = "the workers are compiling the integrators (warm-up): jobs would wait for it"
        return {"ok": detail is None, "mode": self.mode, "broker": broker, "store": store,
                "queue": self.settings.queue, "workers": workers, **({"detail": detail} if detail else {})}

    def job_counts(self) -> dict[str, int]:
        """On /health's own connections (a connect timeout of 2 s) within :data:`HEALTH_TIMEOUT_S`."""
        return self.store.count_by_status(self._health_store, timeout_ms=int(HEALTH_TIMEOUT_S * 1000))

    def live_workers(self) -> int | None:
        return sum(self.settings.queue in w["queues"] for w in census(self._health_redis).values())

    def queue_depth(self) -> int:
        return int(self._health_redis.llen(self.settings.queue))

    def _ping_store(self) -> bool:
        """Whether the job store answers ``SELECT 1`` (on /health's own connections)."""
        try:
            with self._health_store.connect() as connection:
                connection.execute(text("SELECT 1"))
            return True
        except Exception:  # noqa: BLE001 - any error: the store does not answer
            return False

    def close(self) -> None:
        self._health_store.dispose()
        self.redis.close()
        self.store.close()
        self._health_redis.close()
