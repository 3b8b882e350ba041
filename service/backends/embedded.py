"""Embedded mode: jobs run in this process, in a thread pool, through the same job function as the
Celery task (:func:`workers.jobs.run_job`). For a first run on a bare machine: no Redis, no worker."""

from __future__ import annotations

import threading
import time
import uuid
from concurrent.futures import ThreadPoolExecutor
from datetime import datetime, timezone
from typing import Any

from nonholonomic.integration import IntegrationCancelled
from schemas.jobs import TERMINAL_STATUSES
from schemas.settings import Settings
from service.access import visible
from service.backends.base import JobRecord, decode_cursor, encode_cursor
from workers.ensembles import MemoryEnsembleStore, run_ensemble_chunk
from workers.jobs import run_job, warm_up


class EmbeddedBackend:
    """Jobs in memory, run by ``settings.embedded_workers`` threads; finished jobs are forgotten
    ``settings.job_ttl_s`` after they were submitted."""

    mode = "embedded"

    def __init__(self, settings: Settings) -> None:
        self._jobs: dict[str, JobRecord] = {}
        self._cancel: dict[str, threading.Event] = {}
        self._submitted: dict[str, float] = {}
        self._lock = threading.Lock()
        self._ttl_s = settings.job_ttl_s
        self._threads = settings.embedded_workers
        self._pool = ThreadPoolExecutor(self._threads, thread_name_prefix="nonholonomic-job")
        self.ensembles = MemoryEnsembleStore()
        self._ensemble_ids: list[str] = []
        self._warm = threading.Event()
        if settings.warm_up:  # in its own thread, so the first jobs need not wait behind it
            threading.Thread(target=self._warm_up, daemon=True, name="nonholonomic-warm-up").start()
        else:
            self._warm.set()

    def _warm_up(self) -> None:
        try:
            warm_up()
        finally:
            self._warm.set()

    def submit(self, request: dict[str, Any], owner: str | None = None) -> JobRecord:
        job_id = str(uuid.uuid4())
        record = JobRecord(job_id, "queued", 0.0, datetime.now(timezone.utc).isoformat(), request, owner=owner)
        with self._lock:
            self._forget_expired()
            self._jobs[job_id] = record
            self._cancel[job_id] = threading.Event()
            self._submitted[job_id] = time.monotonic()
        self._pool.submit(self._run, job_id)
        return record

    def _forget_expired(self) -> None:
        horizon = time.monotonic() - self._ttl_s
        for job_id in [j for j, t in self._submitted.items() if t < horizon]:
            if self._jobs[job_id].status in TERMINAL_STATUSES:
                del self._jobs[job_id], self._cancel[job_id], self._submitted[job_id]

    def _run(self, job_id: str) -> None:
        record, cancelled = self._jobs[job_id], self._cancel[job_id]
        with self._lock:
            if cancelled.is_set():
                return
            record.status = "running"

        def progress(fraction: float) -> bool:
            record.progress = fraction
            return not cancelled.is_set()

        try:
            result = run_job(record.request, progress)
        except IntegrationCancelled:
            return
        except Exception as exc:  # reported to the client as the job's error
            with self._lock:
                if not cancelled.is_set():
                    record.error = {"type": type(exc).__name__, "message": str(exc)}
                    record.status = "failed"
        else:
            with self._lock:
                if not cancelled.is_set():
                    record.result, record.progress, record.status = result, 1.0, "succeeded"

    def submit_ensemble(self, request: dict[str, Any], chunks: list[tuple[int, int]],
                        owner: str | None = None) -> tuple[str, str]:
        ensemble_id = str(uuid.uuid4())
        created_at = self.ensembles.create(ensemble_id, request, chunks, owner)
        self._ensemble_ids.append(ensemble_id)
        for chunk in range(len(chunks)):
            self._pool.submit(run_ensemble_chunk, self.ensembles, ensemble_id, chunk, "embedded")
        return ensemble_id, created_at

    def cancel_ensemble(self, ensemble_id: str) -> None:
        self.ensembles.cancel(ensemble_id)

    def get(self, job_id: str) -> JobRecord | None:
        return self._jobs.get(job_id)

    def cancel(self, job_id: str) -> JobRecord | None:
        record = self._jobs.get(job_id)
        if record is None:
            return None
        with self._lock:
            if record.status not in TERMINAL_STATUSES:
                self._cancel[job_id].set()
                record.status = "cancelled"
        return record

    def list_jobs(self, status: str | None, limit: int, cursor: str | None,
                  owner: str | None = None) -> tuple[list[JobRecord], str | None]:
        """Newest first by (created_at, id); exact: the next cursor is None once nothing more matches."""
        after = decode_cursor(cursor) if cursor is not None else None
        with self._lock:
            self._forget_expired()
            keyed = sorted(((datetime.fromisoformat(r.created_at).timestamp(), r.id), r) for r in self._jobs.values())
        keyed.reverse()
        matching = [(key, r) for key, r in keyed
                    if (after is None or key < after) and (status is None or r.status == status)
                    and visible(r.owner, owner)]
        page = matching[:limit]
        more = len(matching) > limit
        return [r for _, r in page], encode_cursor(*page[-1][0]) if more else None

    def active_jobs(self, owner: str, enough: int) -> int:
        with self._lock:
            return sum(1 for r in self._jobs.values() if r.status in ("queued", "running") and r.owner == owner)

    def queued_messages(self) -> int:
        return self._pool._work_queue.qsize()  # jobs and chunks not started by a thread yet

    def health(self) -> dict[str, Any]:
        warm = self._warm.is_set()
        detail = None if warm else "the integrators are being compiled (warm-up): jobs would wait for it"
        return {"ok": warm, "mode": self.mode, "broker": "none (embedded)",
                "workers": {"threads": self._threads, "warm": warm}, **({"detail": detail} if detail else {})}

    def close(self) -> None:
        """Stop every job and ensemble chunk at its next progress report, drop what is queued."""
        for event in self._cancel.values():
            event.set()
        for ensemble_id in self._ensemble_ids:
            self.ensembles.cancel(ensemble_id)
        self._pool.shutdown(wait=False, cancel_futures=True)
