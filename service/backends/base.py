"""What the API needs from a job backend."""

from __future__ import annotations

import base64
import binascii
import json
import math
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from store.ensembles import EnsembleStore
from store.idempotency import IdempotencyKeys, KeyBinding

if TYPE_CHECKING:
    import redis


@dataclass
class JobRecord:
    """A job as the API reports it (see :class:`schemas.jobs.JobView`)."""

    id: str
    status: str
    progress: float
    created_at: str
    request: dict[str, Any]
    result: dict[str, Any] | None = None
    error: dict[str, str] | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    #: The API key's owner that submitted it (None: keys off, or sent straight to the broker).
    owner: str | None = None


class QueueFull(Exception):
    """Admitting ``messages`` more would take the queue past its bound: ``waiting`` are queued (and
    ``pending`` are being sent by other requests)."""

    def __init__(self, waiting: int, pending: int = 0) -> None:
        super().__init__(f"{waiting} waiting, {pending} being sent")
        self.waiting, self.pending = waiting, pending


class InvalidCursor(ValueError):
    """A ``cursor`` that no page of ``GET /v1/jobs`` gave out."""


_CURSOR_TAG = "j1"


def encode_cursor(score: float, job_id: str) -> str:
    """The opaque cursor after the job ``job_id`` created at ``score`` (epoch seconds): a list is
    ordered by (score, id) descending, and the next page starts strictly after this pair."""
    raw = json.dumps([_CURSOR_TAG, score, job_id], separators=(",", ":")).encode()
    return base64.urlsafe_b64encode(raw).decode().rstrip("=")


def decode_cursor(cursor: str) -> tuple[float, str]:
    """``(score, id)`` of a cursor from :func:`encode_cursor`; raises :class:`InvalidCursor`."""
    try:
        raw = base64.urlsafe_b64decode(cursor + "=" * (-len(cursor) % 4))
        tag, score, job_id = json.loads(raw)
    except (ValueError, TypeError, binascii.Error):
        raise InvalidCursor("not a cursor given out by this list (use a page's next_cursor as it is)") from None
    if (tag != _CURSOR_TAG or isinstance(score, bool) or not isinstance(score, (int, float))
            or not math.isfinite(score) or not isinstance(job_id, str) or not job_id):
        raise InvalidCursor("not a cursor given out by this list (use a page's next_cursor as it is)")
    return float(score), job_id


class JobBackend(Protocol):
    """Everything the API asks of a job backend (:mod:`service.backends.embedded`, :mod:`service.backends.queue`).

    Routes get the backend through :data:`service.deps.Backend`; nothing outside this interface is probed.
    """

    mode: str
    #: Where ensembles' records and member results live.
    ensembles: EnsembleStore
    #: The Idempotency-Keys bound to jobs and ensembles (in the job store's database).
    keys: IdempotencyKeys

    # Read-only (a property): embedded declares it None, queue a redis.Redis (a mutable attribute is invariant).
    @property
    def redis(self) -> redis.Redis | None:
        """The Redis every API process shares (queue mode), None in embedded mode."""

    def submit(self, request: dict[str, Any], owner: str | None = None,
               max_active: int | None = None, binding: KeyBinding | None = None) -> JobRecord:
        """Accept a validated request (of ``owner``'s key); returns the queued job. With ``max_active``,
        the owner's active jobs are counted and the job recorded in one atomic step: raises
        :class:`store.jobs.ActiveBoundReached` (nothing recorded) when the owner has ``max_active`` already.
        With ``binding``, its Idempotency-Key is bound to the job in the job's transaction: raises
        :class:`store.idempotency.KeyBound` or :class:`store.idempotency.KeyInProgress` (nothing recorded)."""

    def reserve_messages(self, messages: int, bound: int) -> AbstractContextManager[None]:
        """Hold room for ``messages`` more in the queue while the body sends them (at most ``bound`` queued
        and being sent, kept atomically across API processes); raises :class:`QueueFull` if there is none."""

    def get(self, job_id: str) -> JobRecord | None:
        """The job, or None if this service never accepted that id."""

    def find(self, job_id: str, owner: str | None) -> JobRecord | None:
        """The job if ``owner`` may see it (:func:`service.access.visible`; None: keys are off), else None.
        An unknown id and another owner's job cost the same work, so a 404's timing tells nothing."""

    def job_ids_with_prefix(self, prefix: str, owner: str | None) -> list[str]:
        """Ids of jobs starting with ``prefix`` that ``owner`` may see (at most 6; :mod:`store.listing`)."""

    def cancel(self, job_id: str) -> JobRecord | None:
        """Ask the job to stop; returns it (None if unknown)."""

    def list_jobs(self, status: str | None, limit: int, cursor: str | None,
                  owner: str | None = None) -> tuple[list[JobRecord], str | None]:
        """Jobs newest first (without results), only those with ``status`` if given and those ``owner``
        may see if given (:func:`service.access.visible`), at most ``limit``,
        starting after ``cursor`` (a previous page's next cursor, None for the first page).

        Returns the page and the cursor of the next one, None at the end (pages come from the job
        store: exact with any filter). Raises :class:`InvalidCursor` for a cursor it did not give out.
        """

    def submit_ensemble(self, request: dict[str, Any], chunks: list[tuple[int, int]],
                        owner: str | None = None, binding: KeyBinding | None = None) -> tuple[str, str]:
        """Record a validated ensemble and send its chunks to the workers; returns (id, created_at). With
        ``binding``, as :meth:`submit`."""

    def cancel_ensemble(self, ensemble_id: str) -> None:
        """Stop every chunk: queued ones never start, running ones stop at their next progress report."""

    def active_jobs(self, owner: str) -> int:
        """Queued and running jobs of ``owner``."""

    def queued_messages(self) -> int:
        """Jobs and ensemble chunks waiting to start."""

    def job_counts(self) -> dict[str, int]:
        """Jobs in the store by status, for ``/metrics`` (bounded in time: never held by the store)."""

    def live_workers(self) -> int | None:
        """Workers serving the queue with a live heartbeat (None in embedded mode), for ``/metrics``."""

    def queue_depth(self) -> int:
        """Messages waiting in the queue, for ``/metrics`` (bounded in time)."""

    def health(self) -> dict[str, Any]:
        """Status of the parts this backend depends on; ``ok`` is False if jobs cannot run."""

    def close(self) -> None:
        """Release threads and connections."""
