"""Celery tasks: thin wrappers of :func:`workers.jobs.run_job`."""

from __future__ import annotations

import logging
import time
from typing import Any

from celery import Task, states
from celery.exceptions import Ignore, SoftTimeLimitExceeded, TimeLimitExceeded
from sqlalchemy.exc import OperationalError

from nonholonomic.numerics.integration import IntegrationCancelled
from schemas.settings import get_settings
from workers.broker_messages import request_from_args
from workers.celery_app import app
from workers.ensembles import ENSEMBLE_CHUNK, run_ensemble_chunk
from workers.job_store import ensemble_store, job_store, write_until_stored
from workers.jobs import InvalidJob, run_job
from workers.limits import Deadline, JobTimeout, hard_limit_message, log_thread_stacks, soft_limit_message
from workers.metrics import job_finished, job_kind, metrics

#: Seconds between progress updates (and cancellation checks) of a running job.
PROGRESS_INTERVAL_S = 0.2
#: Seconds before a job that could not start (the database away) is tried again.
START_RETRY_S = 5
#: Seconds without progress writes after one failed (the result backend, Redis, away).
PROGRESS_BACKOFF_S = 2.0

log = logging.getLogger(__name__)


class _Progress:
    """Reports progress through ``update_state``, stops the job when it was cancelled (its status in
    the store, read at most every :data:`PROGRESS_INTERVAL_S`) and at its soft time limit
    (:class:`workers.limits.Deadline`: raises :class:`JobTimeout`, also inside heyoka's loops, where
    Celery's signal would not act before the hard limit).

    Progress is best-effort: a write that fails (Redis away) is skipped, the job goes on, and the
    next write is tried :data:`PROGRESS_BACKOFF_S` later; the job's end goes to the store.
    """

    def __init__(self, task: Task, job_id: str, deadline: Deadline) -> None:
        self.task, self.job_id, self.deadline, self.last = task, job_id, deadline, time.monotonic()
        self.backoff_until = 0.0

    def __call__(self, fraction: float) -> bool:
        now = time.monotonic()
        if now - self.last < PROGRESS_INTERVAL_S:
            return True
        self.last = now
        self.deadline.check()
        try:
            if job_store().status(self.job_id) == "cancelled":
                return False
        except OperationalError:  # the database is away: the job goes on (a cancellation waits for it)
            pass
        if now >= self.backoff_until:
            self.backoff_until = 0.0 if _best_effort(self.task, "PROGRESS", {"progress": fraction}) \
                else now + PROGRESS_BACKOFF_S
        return True


def _best_effort(task: Task, state: str, meta: dict[str, Any] | None = None) -> bool:
    """``task.update_state``; False (logged) if the result backend is away."""
    try:
        task.update_state(state=state, meta=meta)
    except (SoftTimeLimitExceeded, JobTimeout):
        raise
    except Exception as exc:  # noqa: BLE001 - Redis away (ConnectionError, TimeoutError ...): skipped
        log.warning("progress of job %s not written (%s: %s); the job goes on", task.request.id,
                    type(exc).__name__, exc)
        return False
    return True


def _record_end(job_id: str, status: str, result: dict[str, Any] | None = None,
                error: dict[str, str] | None = None) -> bool:
    """Write the job's end to the store, retrying while the database is away; True if recorded (False: the
    job had ended already, e.g. run again elsewhere while this worker was cut off, or was cancelled)."""
    return write_until_stored(lambda: job_store().finish(job_id, status, result=result, error=error))


class _JobTask(Task):
    """Records a failure in the store, also one Celery notes in the worker's main process (a job killed
    at its hard time limit)."""

    def on_failure(self, exc: BaseException, task_id: str, args: Any, kwargs: Any, einfo: Any) -> None:
        if isinstance(exc, TimeLimitExceeded):  # the pool process was killed: no task_postrun counts it
            exc = JobTimeout(hard_limit_message(get_settings().job_time_limit_s))
            metrics().tasks.labels(self.name, "job_failed").inc()
        if _record_end(task_id, "failed", error={"type": type(exc).__name__, "message": str(exc)}):
            request, _ = request_from_args(args, kwargs)
            job_finished(request, "failed")
        log.info("job ended: failed", extra={"job_id": task_id, "error": type(exc).__name__})


@app.task(bind=True, base=_JobTask, name="nonholonomic.simulate")
def simulate_job(self: Task, *args: Any, **kwargs: Any) -> dict[str, Any]:
    """Run a simulation job; its result goes to the job store (the task returns only the status).

    The one argument is the request: a ``JobRequest`` (or ``PaperReportRequest``) as a JSON object, or
    a string holding that JSON. A job sent straight to the queue by a job-queue client
    (``send_task("nonholonomic.simulate", args=[request], queue=...)``) is recorded here when it
    starts, unless the API recorded it already. A job that ended, was cancelled or runs on another
    worker is not run (a message delivered twice); one started ``max_job_attempts`` times already is
    failed as quarantined (a poison message), not run again. Anything invalid fails with the reason
    (:class:`workers.jobs.InvalidJob`).
    """
    job_id = self.request.id
    request, refused = request_from_args(args, kwargs)
    try:
        store = job_store()
        attempts = get_settings().max_job_attempts  # a poison message: quarantined after that many starts
        started = store.start(job_id, _worker_key(), attempts)
        if not started:  # sent straight to the broker: record it (unless the API just did), then start it
            store.ensure(job_id, request, (self.request.delivery_info or {}).get("routing_key"))
            started = store.start(job_id, _worker_key(), attempts)
    except OperationalError as exc:  # the database is away: try again in a few seconds, the job unchanged
        raise self.retry(exc=exc, countdown=START_RETRY_S, max_retries=None) from None
    if not started:
        raise Ignore()
    if refused is not None:
        raise InvalidJob(refused)
    try:
        result = run_job(request, _Progress(self, job_id, Deadline(get_settings().job_soft_time_limit_s)))
    except IntegrationCancelled:
        _best_effort(self, states.REVOKED)
        raise Ignore() from None
    except SoftTimeLimitExceeded:
        log_thread_stacks(log, f"job {job_id} past its soft time limit")
        raise JobTimeout(soft_limit_message(get_settings().job_soft_time_limit_s)) from None
    if _record_end(job_id, "succeeded", result=result):
        job_finished(request, "succeeded")  # counted once: not by a late run whose end the store refused
        log.info("job ended: succeeded", extra={"job_id": job_id, "kind": job_kind(request)})
    else:
        log.info("job ended: succeeded, but it had ended already; this run's result was not kept",
                 extra={"job_id": job_id, "kind": job_kind(request)})
    return {"status": "succeeded"}


def _worker_key() -> str:
    """This worker's heartbeat key (its main process's): the runner recorded with a running job."""
    import os

    from workers.heartbeat import worker_key

    return worker_key(os.getppid() if _in_pool_process() else os.getpid())


def _in_pool_process() -> bool:
    from billiard import current_process

    return current_process().name != "MainProcess"


@app.task(bind=True, name=ENSEMBLE_CHUNK, ignore_result=True)
def ensemble_chunk(self: Task, ensemble_id: str, chunk: int) -> str:
    """Run one chunk of an ensemble (:func:`workers.ensembles.run_ensemble_chunk`); the results go to
    the ensemble's record, the task's own result is only what happened (``done``, ``cancelled`` ...).
    A database that is away when the chunk starts: tried again in a few seconds."""
    try:
        return run_ensemble_chunk(ensemble_store(), ensemble_id, chunk, self.request.hostname or "worker",
                                  time_limit_s=get_settings().job_soft_time_limit_s)
    except OperationalError as exc:
        raise self.retry(exc=exc, countdown=START_RETRY_S, max_retries=None) from None
