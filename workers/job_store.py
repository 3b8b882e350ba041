"""The job and ensemble stores of the workers and the API in queue mode, and the broker's epoch.

The broker's *epoch* is a random id kept in Redis (``nonholonomic:broker-epoch``), created when
missing. Every job row records the epoch it was sent in. A Redis that lost its data (restarted
without persistence) comes back without the key: a new epoch begins, and every job still queued
in an older epoch lost its message, so it is sent again (:func:`resend_lost`), and so are the
pending chunks of every ensemble sent in an older epoch (:func:`resend_lost_chunks`).
"""

from __future__ import annotations

import logging
import time
import uuid
from collections.abc import Callable
from functools import lru_cache
from typing import Any, TypeVar, cast

import redis
from sqlalchemy.exc import OperationalError

from schemas.settings import get_settings
from store.ensembles import EnsembleStore
from store.jobs import JobStore

T = TypeVar("T")

log = logging.getLogger(__name__)

EPOCH_KEY = "nonholonomic:broker-epoch"
#: Seconds a worker retries writing a result while the database is away.
STORE_RETRY_S = 600.0


@lru_cache(maxsize=1)
def job_store() -> JobStore:
    """The store of ``DATABASE_URL`` (PostgreSQL in queue mode), migrated once per process."""
    settings = get_settings()
    store = JobStore(settings.store_url, settings.job_ttl_s)
    store.migrate()
    return store


@lru_cache(maxsize=1)
def ensemble_store() -> EnsembleStore:
    """The ensembles of ``DATABASE_URL``, on the job store's engine."""
    return EnsembleStore(job_store().engine, get_settings().job_ttl_s)


def write_until_stored(write: Callable[[], T], limit_s: float = STORE_RETRY_S) -> T:
    """Call ``write`` until the database takes it, for up to ``limit_s`` seconds (then raise), and return
    what it returned: a result computed is not thrown away because the database restarts."""
    deadline = time.monotonic() + limit_s
    delay = 0.5
    while True:
        try:
            return write()
        except OperationalError:
            if time.monotonic() > deadline:
                raise
            time.sleep(delay)
            delay = min(2 * delay, 10.0)


def broker_epoch(client: redis.Redis) -> str:
    """The broker's current epoch (created if Redis has none), in one round trip (``SET NX GET``)."""
    fresh = uuid.uuid4().hex
    old = cast("bytes | None", client.set(EPOCH_KEY, fresh, nx=True, get=True))  # GET: the old value, undecoded
    return old.decode() if old is not None else fresh


def resend_lost(store: JobStore, client: redis.Redis, send: Callable[[dict[str, Any], str, str], None],
                worker_alive: Callable[[str], bool]) -> list[str]:
    """Send again the jobs whose message the broker lost (queued in an older epoch) and those running
    on a worker that is gone (no heartbeat); ``send(request, job_id, queue)`` publishes one. Each is
    claimed in the store first, so that one sweep sends it."""
    epoch = broker_epoch(client)
    default_queue = get_settings().queue
    resent = []
    for job_id, request, queue, old in store.sent_before(epoch):
        if store.resend_claim(job_id, old, epoch):
            send(request, job_id, queue or default_queue)
            resent.append(job_id)
    for worker, job_ids in store.running_on().items():
        if worker and worker != "embedded" and not worker_alive(worker):
            for job_id in job_ids:
                stored = store.get(job_id)
                if stored is not None and store.requeue(job_id, worker, epoch):
                    send(stored.request, job_id, stored.queue or default_queue)
                    resent.append(job_id)
    if resent:
        log.warning("sent again %d job(s) whose message or worker was lost: %s", len(resent), ", ".join(resent[:10]))
    return resent


def resend_lost_chunks(store: EnsembleStore, client: redis.Redis,
                       send: Callable[[str, int, str], None]) -> list[str]:
    """Send again the pending chunks of every ensemble whose chunks were sent in an older broker epoch
    (the broker lost those messages); ``send(ensemble_id, chunk, queue)`` publishes one. Each ensemble
    is claimed first, so that one sweep sends it. Returns the ensembles' ids."""
    epoch = broker_epoch(client)
    default_queue = get_settings().queue
    resent = []
    for ensemble_id, queue, old in store.sent_before(epoch):
        if store.resend_claim(ensemble_id, old, epoch):
            for chunk in store.pending_chunks(ensemble_id):
                send(ensemble_id, chunk, queue or default_queue)
            resent.append(ensemble_id)
    if resent:
        log.warning("sent again the pending chunks of %d ensemble(s) whose messages were lost: %s", len(resent),
                    ", ".join(resent[:10]))
    return resent
