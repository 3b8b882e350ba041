"""Embedded mode: jobs run in this process, in a thread pool, through the same job function as the
Celery task (:func:`workers.jobs.run_job`). For a first run on a bare machine: no Redis, no worker."""

from __future__ import annotations

import threading
import uuid
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from nonholonomic.integration import IntegrationCancelled
from schemas.settings import Settings
from service.backends.base import JobRecord, decode_cursor, encode_cursor
from store.jobs import JobStore, StoredJob
from store.ensembles import EnsembleStore
from workers.ensembles import run_ensemble_chunk
from workers.jobs import run_job, warm_up


class EmbeddedBackend:
    """Jobs recorded in a SQLite file (:mod:`store`), run by ``settings.embedded_workers`` threads.

    A restart loses nothing: jobs that were queued or running when the API stopped are run again
    when it starts, and so are the chunks of ensembles not done yet. Finished jobs and ensembles are
    deleted ``settings.job_ttl_s`` after they were submitted.
    """

    mode = "embedded"

    def __init__(self, settings: Settings) -> None:
        self.store = JobStore(settings.store_url, settings.job_ttl_s)
        self.store.migrate()
        self._progress: dict[str, float] = {}
        self._cancel: dict[str, threading.Event] = {}
        self._lock = threading.Lock()
        self._threads = settings.embedded_workers
        self._pool = ThreadPoolExecutor(self._threads, thread_name_prefix="nonholonomic-job")
        self.ensembles = EnsembleStore(self.store.engine, settings.job_ttl_s)
        self._closing = threading.Event()
        self._warm = threading.Event()
        if settings.warm_up:  # in its own thread, so the first jobs need not wait behind it
            threading.Thread(target=self._warm_up, daemon=True, name="nonholonomic-warm-up").start()
        else:
            self._warm.set()
        self.resumed = [job.id for job in self.store.unfinished()]
        for job_id in self.resumed:  # interrupted by the last stop: run again
            self.store.requeue(job_id)
            self._enqueue(job_id)
        self.resumed_ensembles = self.ensembles.unfinished()
        for ensemble_id in self.resumed_ensembles:
            for chunk in self.ensembles.pending_chunks(ensemble_id):
                self._enqueue_chunk(ensemble_id, chunk)

    def _warm_up(self) -> None:
        try:
            warm_up()
        finally:
            self._warm.set()

    def _enqueue(self, job_id: str) -> None:
        with self._lock:
            self._cancel[job_id] = threading.Event()
            self._progress[job_id] = 0.0
        self._pool.submit(self._run, job_id)

    def submit(self, request: dict[str, Any], owner: str | None = None) -> JobRecord:
        job_id = str(uuid.uuid4())
        created_at = self.store.create(job_id, request, owner)
        self._enqueue(job_id)
        return JobRecord(job_id, "queued", 0.0, created_at, request, owner=owner)

    def _run(self, job_id: str) -> None:
        cancelled = self._cancel[job_id]
        stored = self.store.get(job_id)
        if stored is None or cancelled.is_set() or not self.store.start(job_id, "embedded"):
            self._forget(job_id)
            return

        def progress(fraction: float) -> bool:
            self._progress[job_id] = fraction
            return not cancelled.is_set()

        try:
            result = run_job(stored.request, progress)
        except IntegrationCancelled:
            pass
        except Exception as exc:  # reported to the client as the job's error
            self.store.finish(job_id, "failed", error={"type": type(exc).__name__, "message": str(exc)})
        else:
            self.store.finish(job_id, "succeeded", result=result)
        self._forget(job_id)

    def _forget(self, job_id: str) -> None:
        with self._lock:
            self._cancel.pop(job_id, None)
            self._progress.pop(job_id, None)

    def submit_ensemble(self, request: dict[str, Any], chunks: list[tuple[int, int]],
                        owner: str | None = None) -> tuple[str, str]:
        ensemble_id = str(uuid.uuid4())
        created_at = self.ensembles.create(ensemble_id, request, chunks, owner)
        for chunk in range(len(chunks)):
            self._enqueue_chunk(ensemble_id, chunk)
        return ensemble_id, created_at

    def _enqueue_chunk(self, ensemble_id: str, chunk: int) -> None:
        self._pool.submit(run_ensemble_chunk, self.ensembles, ensemble_id, chunk, "embedded", self._closing.is_set)

    def cancel_ensemble(self, ensemble_id: str) -> None:
        self.ensembles.cancel(ensemble_id)

    def _record(self, job: StoredJob) -> JobRecord:
        progress = 1.0 if job.status == "succeeded" else self._progress.get(job.id, 0.0)
        return JobRecord(job.id, job.status, progress, job.created_at, job.request, result=job.result,
                         error=job.error, owner=job.owner)

    def get(self, job_id: str) -> JobRecord | None:
        job = self.store.get(job_id)
        return None if job is None else self._record(job)

    def cancel(self, job_id: str) -> JobRecord | None:
        if self.store.cancel(job_id):
            event = self._cancel.get(job_id)
            if event is not None:
                event.set()  # a running job stops at its next progress report
        return self.get(job_id)

    def list_jobs(self, status: str | None, limit: int, cursor: str | None,
                  owner: str | None = None) -> tuple[list[JobRecord], str | None]:
        """Newest first by (created_at, id); exact: the next cursor is None once nothing more matches."""
        after = decode_cursor(cursor) if cursor is not None else None
        jobs, more = self.store.page(status, limit, after, owner)
        return [self._record(j) for j in jobs], encode_cursor(jobs[-1].created, jobs[-1].id) if more else None

    def active_jobs(self, owner: str) -> int:
        return self.store.active_count(owner)

    def queued_messages(self) -> int:
        return self._pool._work_queue.qsize()  # jobs and chunks not started by a thread yet

    def health(self) -> dict[str, Any]:
        warm = self._warm.is_set()
        detail = None if warm else "the integrators are being compiled (warm-up): jobs would wait for it"
        store = "ok" if self.store.ping() else "unreachable"
        return {"ok": warm and store == "ok", "mode": self.mode, "broker": "none (embedded)", "store": store,
                "workers": {"threads": self._threads, "warm": warm}, **({"detail": detail} if detail else {})}

    def close(self) -> None:
        """Stop every job and ensemble chunk at its next progress report, drop what is queued (the jobs
        stay queued or running in the store, the chunks pending: the next start runs them again)."""
        self._closing.set()
        for event in list(self._cancel.values()):
            event.set()
        self._pool.shutdown(wait=False, cancel_futures=True)
        self.store.close()
