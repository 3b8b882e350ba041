"""Admission control: a bounded pool for the symbolic endpoints, bounds on queued work for the others.

A symbolic request occupies one of ``symbolic_workers`` slots while its child process runs
(:mod:`service.isolated`); up to ``symbolic_queue`` more wait for a slot. A request beyond both is
refused at once with a 503 problem and ``Retry-After`` (the expected wait), instead of taking a
request thread until it times out: the API's threads, and ``/health``, stay free under any load.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import Request

from schemas.problems import OVERLOADED, QUEUE_FULL
from schemas.settings import Settings
from service.errors import ProblemError

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


def admit_work(request: Request) -> None:
    """Refuse new work (429 with ``Retry-After``) beyond the caller's key's bound on queued and running
    jobs, or beyond the bound on messages waiting in the queue."""
    settings: Settings = request.app.state.settings
    backend, owner = request.app.state.backend, getattr(request.state, "owner", None)
    if owner is not None:
        active = backend.active_jobs(owner)
        if active >= settings.max_active_jobs_per_key:
            raise ProblemError(429, "Too many jobs", f"this key has {active} queued or running jobs, the most it may "
                               f"have (max_active_jobs_per_key={settings.max_active_jobs_per_key}); retry when some "
                               "have finished", QUEUE_FULL, headers={"Retry-After": str(QUEUE_FULL_RETRY_S)})
    waiting = backend.queued_messages()
    if waiting >= settings.max_queued_messages:
        raise ProblemError(429, "Queue full", f"{waiting} jobs and ensemble chunks wait in the queue, the most it "
                           f"holds (max_queued_messages={settings.max_queued_messages}); retry later", QUEUE_FULL,
                           headers={"Retry-After": str(QUEUE_FULL_RETRY_S)})
