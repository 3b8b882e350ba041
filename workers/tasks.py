"""Celery tasks: thin wrappers of :func:`workers.jobs.run_job`."""

from __future__ import annotations

import time
from typing import Any

from celery import Task, states
from celery.exceptions import Ignore, SoftTimeLimitExceeded, TimeLimitExceeded
from sqlalchemy.exc import OperationalError

from nonholonomic.integration import IntegrationCancelled
from schemas.settings import get_settings
from workers.celery_app import app
from workers.ensembles import ENSEMBLE_CHUNK, run_ensemble_chunk
from workers.jobs import InvalidJob, run_job
from workers.job_store import ensemble_store, job_store, write_until_stored
from workers.broker_messages import request_from_args

#: Seconds between progress updates (and cancellation checks) of a running job.
PROGRESS_INTERVAL_S = 0.2
#: Seconds before a job that could not start (the database away) is tried again.
START_RETRY_S = 5


class JobTimeout(RuntimeError):
    """The job ran past its soft time limit."""


class _Progress:
    """Reports progress through ``update_state`` and stops the job when it was cancelled (its status in
    the store, read at most every :data:`PROGRESS_INTERVAL_S`)."""

    def __init__(self, task: Task, job_id: str) -> None:
        self.task, self.job_id, self.last = task, job_id, time.monotonic()

    def __call__(self, fraction: float) -> bool:
        now = time.monotonic()
        if now - self.last < PROGRESS_INTERVAL_S:
            return True
        self.last = now
        try:
            if job_store().status(self.job_id) == "cancelled":
                return False
        except OperationalError:  # the database is away: the job goes on (a cancellation waits for it)
            pass
        self.task.update_state(state="PROGRESS", meta={"progress": fraction})
        return True


def _record_end(job_id: str, status: str, result: dict[str, Any] | None = None,
                error: dict[str, str] | None = None) -> None:
    """Write the job's end to the store, retrying while the database is away."""
    write_until_stored(lambda: job_store().finish(job_id, status, result=result, error=error))


class _JobTask(Task):
    """Records a failure in the store, also one Celery notes in the worker's main process (a job killed
    at its hard time limit)."""

    def on_failure(self, exc: BaseException, task_id: str, args: Any, kwargs: Any, einfo: Any) -> None:
        if isinstance(exc, TimeLimitExceeded):
            exc = JobTimeout(f"the job was killed at its hard time limit of {get_settings().job_time_limit_s:g} s")
        _record_end(task_id, "failed", error={"type": type(exc).__name__, "message": str(exc)})


@app.task(bind=True, base=_JobTask, name="nonholonomic.simulate")
def simulate_job(self: Task, *args: Any, **kwargs: Any) -> dict[str, Any]:
    """Run a simulation job; its result goes to the job store (the task returns only the status).

    The one argument is the request: a ``JobRequest`` (or ``PaperReportRequest``) as a JSON object, or
    a string holding that JSON. A job sent straight to the queue by a job-queue client
    (``send_task("nonholonomic.simulate", args=[request], queue=...)``) is recorded here when it
    starts, unless the API recorded it already. A job that ended, was cancelled or runs on another
    worker is not run (a message delivered twice). Anything invalid fails with the reason
    (:class:`workers.jobs.InvalidJob`).
    """
    job_id = self.request.id
    request, refused = request_from_args(args, kwargs)
    try:
        store = job_store()
        started = store.start(job_id, _worker_key())
        if not started:  # sent straight to the broker: record it (unless the API just did), then start it
            store.ensure(job_id, request, (self.request.delivery_info or {}).get("routing_key"))
            started = store.start(job_id, _worker_key())
    except OperationalError as exc:  # the database is away: try again in a few seconds, the job unchanged
        raise self.retry(exc=exc, countdown=START_RETRY_S, max_retries=None) from None
    if not started:
        raise Ignore()
    if refused is not None:
        raise InvalidJob(refused)
    try:
        result = run_job(request, _Progress(self, job_id))
    except IntegrationCancelled:
        self.update_state(state=states.REVOKED)
        raise Ignore() from None
    except SoftTimeLimitExceeded:
        raise JobTimeout(f"the job exceeded its time limit of {get_settings().job_soft_time_limit_s:g} s") from None
    _record_end(job_id, "succeeded", result=result)
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
        return run_ensemble_chunk(ensemble_store(), ensemble_id, chunk, self.request.hostname or "worker")
    except OperationalError as exc:
        raise self.retry(exc=exc, countdown=START_RETRY_S, max_retries=None) from None
