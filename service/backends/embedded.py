"""Embedded mode: jobs run in this process, in a few threads, through the same job function as the
Celery task (:func:`workers.jobs.run_job`). For a first run on a bare machine: no Redis, no worker.

A job has the workers' time limits (``job_soft_time_limit_s``, ``job_time_limit_s``). At the soft limit
it stops at its next progress report (every long loop reports within a fraction of a second, also
inside heyoka's integrations), and Python code that reports none gets :class:`JobTimeout` raised in
its thread, as Celery's signal does in a worker; the job fails naming the limit. A job still running
at the hard limit (stuck in code that never comes back to Python) is recorded failed and its thread
abandoned: a new thread takes its place (:class:`service.backends.job_threads.JobThreads`).

No job holds the others (issue 34, item 4). A job past ``embedded_long_after_s`` of work moves to the
long lane (up to ``embedded_long_lane`` such jobs): a new thread takes the next jobs, so a short job
does not wait behind a long one. A cancelled job whose thread has not come back to Python within
:data:`CANCEL_GRACE_S` (inside an LLVM compile) is let go the same way: its thread ends when the compile
returns, and its place is taken at once. A job started ``max_job_attempts`` times (the service stopped
under it each time) is quarantined as failed at the next start, not run again.
"""

from __future__ import annotations

import contextvars
import ctypes
import logging
import threading
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from nonholonomic.numerics.integration import IntegrationCancelled
from schemas.settings import Settings
from service.backends.base import JobRecord, QueueFull, decode_cursor, encode_cursor
from service.backends.job_threads import JobThreads
from store.ensembles import EnsembleStore
from store.idempotency import IdempotencyKeys, KeyBinding
from store.jobs import ActiveBoundReached, JobStore, StoredJob
from workers.ensembles import run_ensemble_chunk
from workers.jobs import WarmUp, run_job, warm_up
from workers.limits import Deadline, JobTimeout, log_thread_stacks, soft_limit_message
from workers.logs import JOB_ID
from workers.metrics import job_finished

log = logging.getLogger(__name__)
#: Seconds between two looks of the watchdog at the running jobs' time limits.
WATCHDOG_INTERVAL_S = 0.25
#: Seconds :meth:`EmbeddedBackend.close` waits for the running jobs to stop.
CLOSE_WAIT_S = 5.0
#: Seconds a cancelled job's thread has to come back to Python before its place is given to a new thread.
CANCEL_GRACE_S = 2.0


def abandoned_message(limit_s: float) -> str:
    """The error of a job abandoned at its hard time limit in embedded mode."""
    return f"the job was stopped at its hard time limit of {limit_s:g} s (its thread did not return and was replaced)"


@dataclass
class _Running:
    """A job running in a thread: whether it is inside ``run_job``, was interrupted or abandoned."""

    job_id: str
    thread: threading.Thread
    started: float = field(default_factory=time.monotonic)
    inside: bool = True
    interrupted: bool = False
    abandoned: bool = False
    #: Moved to the long lane (:meth:`JobThreads.promote`).
    promoted: bool = False
    #: When it was cancelled (monotonic seconds), if it was while running.
    cancelled_at: float | None = None


def _raise_in(thread: threading.Thread, exc: type[BaseException] | None) -> None:
    """Raise ``exc`` in ``thread`` when it next runs Python code (None: withdraw one not raised yet)."""
    if thread.ident is not None:
        ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(thread.ident),
                                                   None if exc is None else ctypes.py_object(exc))


class EmbeddedBackend:
    """Jobs recorded in a SQLite file (:mod:`store`), run by ``settings.embedded_workers`` threads.

    A restart loses nothing: jobs that were queued or running when the API stopped are run again
    when it starts, and so are the chunks of ensembles not done yet. Finished jobs and ensembles are
    deleted ``settings.job_ttl_s`` after they were submitted.
    """

    mode = "embedded"
    redis = None

    def __init__(self, settings: Settings) -> None:
        self.store = JobStore(settings.store_url, settings.job_ttl_s)
        self.store.migrate()
        self._progress: dict[str, float] = {}
        self._cancel: dict[str, threading.Event] = {}
        self._lock = threading.Lock()
        #: Admissions one at a time (one API process): counted and recorded under this lock.
        self._admission = threading.RLock()
        self._threads = settings.embedded_workers
        self._soft_limit_s, self._hard_limit_s = settings.job_soft_time_limit_s, settings.job_time_limit_s
        self._running: dict[str, _Running] = {}
        self._long_after_s, self._max_attempts = settings.embedded_long_after_s, settings.max_job_attempts
        self._pool = JobThreads(self._threads, "nonholonomic-job", settings.embedded_long_lane)
        self.ensembles = EnsembleStore(self.store.engine, settings.job_ttl_s)
        self.keys = IdempotencyKeys(self.store.engine)
        self._closing = threading.Event()
        threading.Thread(target=self._watch, daemon=True, name="nonholonomic-job-watchdog").start()
        self._warm = threading.Event()
        self._warming = WarmUp()
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
            warm_up(self._warming)
        finally:
            self._warm.set()

    def _enqueue(self, job_id: str) -> None:
        with self._lock:
            self._cancel[job_id] = threading.Event()
            self._progress[job_id] = 0.0
        context = contextvars.copy_context()  # the submitting request's id goes with the job's log lines
        context.run(JOB_ID.set, job_id)
        self._pool.submit(context.run, self._run, job_id)

    def submit(self, request: dict[str, Any], owner: str | None = None,
               max_active: int | None = None, binding: KeyBinding | None = None) -> JobRecord:
        job_id = str(uuid.uuid4())
        with self._admission:
            if max_active is not None and owner is not None:
                active = self.store.active_count(owner)
                if active >= max_active:
                    raise ActiveBoundReached(active)
            created_at = self.store.create(job_id, request, owner, binding=binding)
        self._enqueue(job_id)
        return JobRecord(job_id, "queued", 0.0, created_at, request, owner=owner)

    @contextmanager
    def reserve_messages(self, messages: int, bound: int) -> Iterator[None]:
        """Admit ``messages`` more if the queue stays within ``bound``, else raise :class:`QueueFull`; the
        body sends them while other admissions wait (one API process: a lock is atomic enough)."""
        with self._admission:
            waiting = self.queued_messages()
            if waiting + messages > bound:
                raise QueueFull(waiting)
            yield

    def _run(self, job_id: str) -> None:
        cancelled = self._cancel[job_id]
        stored = self.store.get(job_id)
        if stored is None or cancelled.is_set() or not self.store.start(job_id, "embedded", self._max_attempts):
            self._forget(job_id)
            return
        deadline = Deadline(self._soft_limit_s)

        def progress(fraction: float) -> bool:
            self._progress[job_id] = fraction
            if cancelled.is_set():
                return False
            deadline.check()
            return True

        running = _Running(job_id, threading.current_thread())
        with self._lock:
            self._running[job_id] = running
        end: dict[str, Any] | None = None
        try:
            try:
                end = {"status": "succeeded", "result": run_job(stored.request, progress)}
            finally:
                self._leave(running)
        except IntegrationCancelled:
            pass
        except JobTimeout as exc:  # at its next progress report, or raised by the watchdog
            self._leave(running)
            end = {"status": "failed", "error": {"type": "JobTimeout",
                                                 "message": str(exc) or soft_limit_message(self._soft_limit_s)}}
        except Exception as exc:  # reported to the client as the job's error
            end = {"status": "failed", "error": {"type": type(exc).__name__, "message": str(exc)}}
        if end is not None and not running.abandoned:  # an abandoned job has failed already
            if self.store.finish(job_id, **end):
                job_finished(stored.request, end["status"])
        self._forget(job_id)

    def _leave(self, running: _Running) -> None:
        """The job's thread has left ``run_job``: no time-limit exception may reach it any more."""
        with self._lock:
            if running.inside and running.interrupted:
                _raise_in(running.thread, None)  # withdraw it if it was not raised yet
            running.inside = False
            self._running.pop(running.job_id, None)

    def _watch(self) -> None:
        """The watchdog: moves a job past ``embedded_long_after_s`` to the long lane, lets go of a cancelled
        job's thread after :data:`CANCEL_GRACE_S`, raises :class:`JobTimeout` in a job's thread at its soft
        limit (for Python code that reports no progress), and at its hard limit records the job failed and
        replaces its thread."""
        while not self._closing.wait(WATCHDOG_INTERVAL_S):
            now = time.monotonic()
            with self._lock:
                running_now = [r for r in self._running.values() if r.inside]
                late = [r for r in running_now if now - r.started >= self._soft_limit_s]
                stopped = [r for r in late if not r.interrupted]
                for running in stopped:
                    running.interrupted = True
                    _raise_in(running.thread, JobTimeout)
            for running in stopped:
                log_thread_stacks(log, f"job {running.job_id} past its soft time limit")
            for running in running_now:
                if not running.promoted and now - running.started >= self._long_after_s:
                    running.promoted = self._pool.promote(running.thread)
                if running.cancelled_at is not None and now - running.cancelled_at >= CANCEL_GRACE_S:
                    self._let_go(running)
            for running in late:
                if now - running.started >= self._hard_limit_s and not running.abandoned:
                    self._abandon(running)

    def _let_go(self, running: _Running) -> None:
        """A cancelled job still inside code that does not come back to Python (a compile): its thread
        ends when that returns (its job stops at its first progress report), and its place is taken now."""
        self._give_up(running, f"its job was cancelled and had not stopped {CANCEL_GRACE_S:g} s later")

    def _give_up(self, running: _Running, why: str) -> None:
        """Nothing more of ``running`` is recorded; a new thread takes its thread's place (``JobThreads.replace``)."""
        running.abandoned = True
        self._pool.replace(running.thread, why)
        with self._lock:
            self._running.pop(running.job_id, None)
            self._progress.pop(running.job_id, None)

    def _abandon(self, running: _Running) -> None:
        running.abandoned = True  # before the record below: its own end, should it come, is not recorded
        event = self._cancel.get(running.job_id)
        if event is not None:
            event.set()  # should it ever report progress again, it stops there
        try:
            request = self.store.get(running.job_id)
            if self.store.finish(running.job_id, "failed", error={
                    "type": "JobTimeout", "message": abandoned_message(self._hard_limit_s)}) and request is not None:
                job_finished(request.request, "failed")
        except Exception:  # the store away: the restart runs the job again
            log.exception("could not record job %s failed at its hard time limit", running.job_id)
        self._give_up(running, "stuck past a job's hard time limit")

    def _forget(self, job_id: str) -> None:
        with self._lock:
            self._cancel.pop(job_id, None)
            self._progress.pop(job_id, None)

    def submit_ensemble(self, request: dict[str, Any], chunks: list[tuple[int, int]],
                        owner: str | None = None, binding: KeyBinding | None = None) -> tuple[str, str]:
        ensemble_id = str(uuid.uuid4())
        created_at = self.ensembles.create(ensemble_id, request, chunks, owner, binding=binding)
        for chunk in range(len(chunks)):
            self._enqueue_chunk(ensemble_id, chunk)
        return ensemble_id, created_at

    def _enqueue_chunk(self, ensemble_id: str, chunk: int) -> None:
        context = contextvars.copy_context()
        context.run(JOB_ID.set, ensemble_id)
        self._pool.submit(context.run, run_ensemble_chunk, self.ensembles, ensemble_id, chunk, "embedded",
                          self._closing.is_set, self._soft_limit_s)

    def cancel_ensemble(self, ensemble_id: str) -> None:
        self.ensembles.cancel(ensemble_id)

    def _record(self, job: StoredJob) -> JobRecord:
        progress = 1.0 if job.status == "succeeded" else self._progress.get(job.id, 0.0)
        return JobRecord(job.id, job.status, progress, job.created_at, job.request, result=job.result,
                         error=job.error, owner=job.owner)

    def find(self, job_id: str, owner: str | None) -> JobRecord | None:
        """The job if ``owner`` may see it, else None: the visibility is asked first, in one lookup that
        costs the same for an unknown id and another owner's job (the record is read only when visible)."""
        if owner is not None and not self.store.visible(job_id, owner):
            return None
        return self.get(job_id)

    def get(self, job_id: str) -> JobRecord | None:
        job = self.store.get(job_id)
        return None if job is None else self._record(job)

    def cancel(self, job_id: str) -> JobRecord | None:
        if self.store.cancel(job_id):
            event = self._cancel.get(job_id)
            if event is not None:
                event.set()  # a running job stops at its next progress report
            with self._lock:
                running = self._running.get(job_id)
                if running is not None:  # or its thread is let go after CANCEL_GRACE_S
                    running.cancelled_at = time.monotonic()
        return self.get(job_id)

    def list_jobs(self, status: str | None, limit: int, cursor: str | None,
                  owner: str | None = None) -> tuple[list[JobRecord], str | None]:
        """Newest first by (created_at, id); exact: the next cursor is None once nothing more matches."""
        after = decode_cursor(cursor) if cursor is not None else None
        jobs, more = self.store.page(status, limit, after, owner)
        return [self._record(j) for j in jobs], encode_cursor(jobs[-1].created, jobs[-1].id) if more else None

    def job_ids_with_prefix(self, prefix: str, owner: str | None) -> list[str]:
        return self.store.with_prefix(prefix, owner)

    def active_jobs(self, owner: str) -> int:
        return self.store.active_count(owner)

    def queued_messages(self) -> int:
        return self._pool.pending()  # jobs and chunks not started by a thread yet

    def job_counts(self) -> dict[str, int]:
        return self.store.count_by_status()

    def live_workers(self) -> int | None:
        return None

    def queue_depth(self) -> int:
        return self.queued_messages()

    def health(self) -> dict[str, Any]:
        warm = self._warm.is_set()
        w = self._warming
        detail = None if warm else (
            f"warm-up ({w.done} of {w.total or '?'} systems{f', now {w.now}' if w.now else ''}; "
            f"{_warm_source(w)})"
            ": jobs would wait for it")
        store = "ok" if self.store.ping() else "unreachable"
        return {"ok": warm and store == "ok", "mode": self.mode, "broker": "none (embedded)", "store": store,
                "workers": {"threads": self._threads, "warm": warm, "warm_up": w.as_json(), **self._pool.status()},
                **({"detail": detail} if detail else {})}

    def close(self) -> None:
        """Stop every job and ensemble chunk at its next progress report, drop what is queued (the jobs
        stay queued or running in the store, the chunks pending: the next start runs them again)."""
        self._closing.set()
        for event in list(self._cancel.values()):
            event.set()
        self._pool.close(CLOSE_WAIT_S)
        self.store.close()


def _warm_source(w: Any) -> str:
    """Where the warm-up's systems come from, for ``/health``'s detail."""
    if w.read_back > w.derived:
        return "read back from the memo on disk"
    if w.read_back == 0 and w.derived == 0:
        return "starting"
    return "deriving and compiling (first start, or no memo on disk: about a minute on 2 cores)"
