"""The job store of the workers and the API in queue mode, and the broker's epoch.

The broker's *epoch* is a random id kept in Redis (``nonholonomic:broker-epoch``), created when
missing. Every job row records the epoch it was sent in. A Redis that lost its data (restarted
without persistence) comes back without the key: a new epoch begins, and every job still queued
in an older epoch lost its message, so it is sent again (:func:`resend_lost`).
"""

from __future__ import annotations

import logging
import uuid
from collections.abc import Callable
from functools import lru_cache
from typing import Any

import redis

from schemas.settings import get_settings
from store.jobs import JobStore

log = logging.getLogger(__name__)

EPOCH_KEY = "nonholonomic:broker-epoch"


@lru_cache(maxsize=1)
def job_store() -> JobStore:
    """The store of ``DATABASE_URL`` (PostgreSQL in queue mode), migrated once per process."""
    settings = get_settings()
    store = JobStore(settings.store_url, settings.job_ttl_s)
    store.migrate()
    return store


def broker_epoch(client: redis.Redis) -> str:
    """The broker's current epoch (created if Redis has none), in one round trip (``SET NX GET``)."""
    fresh = uuid.uuid4().hex
    old = client.set(EPOCH_KEY, fresh, nx=True, get=True)
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
