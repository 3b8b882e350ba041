"""Admission control: a bounded pool for the symbolic endpoints, bounds on queued work for the others.

A symbolic request occupies one of ``symbolic_workers`` slots while its child process runs
(:mod:`service.isolated`); up to ``symbolic_queue`` more wait for a slot. A request beyond both is
refused at once with a 503 problem and ``Retry-After`` (the expected wait), instead of taking a
request thread until it times out: the API's threads, and ``/health``, stay free under any load.

Work (jobs, ensembles, paper reports) is admitted and submitted in one step, :func:`admit_job` and
:func:`admit_ensemble`, so that concurrent requests cannot all see room for one more: a key has at
most ``max_active_jobs_per_key`` queued or running jobs, and the queue at most ``max_queued_messages``
jobs and ensemble chunks (an ensemble counts each chunk). In queue mode (several API processes) the
backend keeps both atomically (an advisory lock per owner in PostgreSQL, a reservation in Redis: see
:mod:`service.backends.queue`); in embedded mode (one API process) the backend's lock does. Both sit
behind the same two calls of :class:`service.backends.base.JobBackend`: ``submit(..., max_active=)``
and ``reserve_messages``.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager, contextmanager
from typing import Any

from schemas.problems import OVERLOADED, QUEUE_FULL, FieldError
from schemas.settings import Settings
from service import metrics
from service.backends.base import JobBackend, JobRecord, QueueFull
from service.errors import ProblemError, invalid_request
from store.idempotency import KeyBinding
from store.jobs import ActiveBoundReached
from workers.metrics import job_kind

log = logging.getLogger(__name__)

#: Seconds assumed for a request before any has finished (for ``Retry-After``).
_FIRST_GUESS_S = 5.0
#: Weight of the newest request in the running mean of durations.
_SMOOTHING = 0.2


class SymbolicPool:
    """At most ``size`` requests run at once, at most ``queue`` wait; the rest get a 503.

    Used from the event loop only (no lock needed): ``async with pool.slot(): ...``.
    """

    def __init__(self, size: int, queue: int) -> None:
        self.size, self.queue = size, queue
        self._slots = asyncio.Semaphore(size)
        self.running = 0
        self.waiting = 0
        self.refused = 0
        self._mean_s = _FIRST_GUESS_S

    def retry_after_s(self) -> int:
        """Seconds until a slot is likely free for a new request: the queue ahead of it drained at the
        pool's rate (the running mean of durations), at least 1."""
        ahead = self.waiting + 1
        return max(1, math.ceil(self._mean_s * ahead / self.size))

    @asynccontextmanager
    async def slot(self) -> AsyncIterator[None]:
        """Hold one slot for the body; wait for it if the queue has room, else raise a 503 problem."""
        if self.running >= self.size and self.waiting >= self.queue:
            self.refused += 1
            metrics.refused("symbolic_pool_busy")
            retry = self.retry_after_s()
            raise ProblemError(
                503, "Symbolic pool busy",
                f"{self.running} symbolic requests are running and {self.waiting} are waiting (the pool's bounds: "
                f"symbolic_workers={self.size}, symbolic_queue={self.queue}); retry after {retry} s",
                OVERLOADED, headers={"Retry-After": str(retry)})
        self.waiting += 1
        try:
            await self._slots.acquire()
        finally:
            self.waiting -= 1
        self.running += 1
        start = time.monotonic()
        try:
            yield
        finally:
            self.running -= 1
            self._slots.release()
            self._mean_s += _SMOOTHING * (time.monotonic() - start - self._mean_s)

    def status(self) -> dict[str, int]:
        """Occupancy, for ``/health``."""
        return {"size": self.size, "queue": self.queue, "running": self.running, "waiting": self.waiting,
                "refused": self.refused}


#: Seconds a client is told to wait when its key has too many active jobs or the queue is full.
QUEUE_FULL_RETRY_S = 10


def _too_many_jobs(active: int, settings: Settings) -> ProblemError:
    metrics.refused("too_many_jobs")
    return ProblemError(429, "Too many jobs", f"this key has {active} queued or running jobs, the most it may have "
                        f"(max_active_jobs_per_key={settings.max_active_jobs_per_key}); retry when some have finished",
                        QUEUE_FULL, headers={"Retry-After": str(QUEUE_FULL_RETRY_S)})


def _queue_full(waiting: int, messages: int, settings: Settings) -> ProblemError:
    metrics.refused("queue_full")
    what = "a job" if messages == 1 else f"{messages} ensemble chunks"
    return ProblemError(429, "Queue full", f"{waiting} jobs and ensemble chunks wait in the queue (or are being sent); "
                        f"{what} more would exceed what it holds (max_queued_messages={settings.max_queued_messages}); "
                        "retry later", QUEUE_FULL, headers={"Retry-After": str(QUEUE_FULL_RETRY_S)})


@contextmanager
def _admitted(backend: JobBackend, owner: str | None, settings: Settings, messages: int,
              adds_a_job: bool) -> Iterator[int | None]:
    """Room for ``messages`` in the queue (and, if ``adds_a_job``, one more active job of ``owner``)
    while the body submits; yields the per-key bound the backend keeps when it records the job (None:
    keys are off or no job is added). Raises the 429 problems."""
    if messages > settings.max_queued_messages:  # schemas.ensembles refuses these before any work: a safeguard
        raise invalid_request([FieldError(field="members", reason=(
            f"{messages} chunks exceed what the queue holds (max_queued_messages={settings.max_queued_messages})"))])
    if owner is not None and not adds_a_job:  # an ensemble adds no job: a plain check is exact enough
        active = backend.active_jobs(owner)
        if active >= settings.max_active_jobs_per_key:
            raise _too_many_jobs(active, settings)
    try:
        with backend.reserve_messages(messages, settings.max_queued_messages):
            yield settings.max_active_jobs_per_key if owner is not None and adds_a_job else None
    except QueueFull as exc:
        raise _queue_full(exc.waiting + exc.pending, messages, settings) from None
    except ActiveBoundReached as exc:
        raise _too_many_jobs(exc.active, settings) from None


def admit_job(backend: JobBackend, owner: str | None, settings: Settings, body: dict[str, Any],
              binding: KeyBinding | None = None) -> JobRecord:
    """Admit and submit a job (or a paper report) of ``owner``'s key: a 429 problem with ``Retry-After``
    if the key has ``max_active_jobs_per_key`` active jobs or the queue is full, else the queued job (its
    Idempotency-Key's ``binding`` recorded with it)."""
    with _admitted(backend, owner, settings, 1, adds_a_job=True) as max_active:
        record = backend.submit(body, owner, max_active=max_active, binding=binding)
    metrics.submitted(body)
    log.info("job submitted", extra={"job_id": record.id, "kind": job_kind(body)})
    return record


def admit_ensemble(backend: JobBackend, owner: str | None, settings: Settings, spec: dict[str, Any],
                   chunks: list[tuple[int, int]], binding: KeyBinding | None = None) -> str:
    """Admit and submit an ensemble: its chunks count against ``max_queued_messages`` (all of them fit
    with what is queued, or a 429 problem with ``Retry-After``); returns the ensemble's id."""
    with _admitted(backend, owner, settings, len(chunks), adds_a_job=False):
        ensemble_id, _ = backend.submit_ensemble(spec, chunks, owner, binding)
    metrics.ensemble_submitted(spec)
    log.info("ensemble submitted", extra={"job_id": ensemble_id, "kind": job_kind(spec), "chunks": len(chunks)})
    return ensemble_id
