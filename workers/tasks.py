"""Celery tasks: thin wrappers of :func:`workers.jobs.run_job`."""

from __future__ import annotations

import time
from functools import lru_cache
from typing import Any

import redis
from celery import Task, states
from celery.exceptions import Ignore, SoftTimeLimitExceeded

from nonholonomic.integration import IntegrationCancelled
from schemas.settings import get_settings
from workers.celery_app import DEFAULT_REDIS_URL, app
from workers.ensembles import RedisEnsembleStore, run_ensemble_chunk
from workers.jobs import InvalidJob, run_job
from workers.registry import RedisJobRegistry, request_from_args

#: Seconds between progress updates (and cancellation checks) of a running job.
PROGRESS_INTERVAL_S = 0.2


class JobTimeout(RuntimeError):
    """The job ran past its soft time limit."""


@lru_cache(maxsize=1)
def _registry() -> RedisJobRegistry:
    settings = get_settings()
    return RedisJobRegistry(redis.Redis.from_url(settings.redis_url or DEFAULT_REDIS_URL), settings.job_ttl_s)


class _Progress:
    """Reports progress through ``update_state`` and stops the job when it was cancelled."""

    def __init__(self, task: Task, job_id: str) -> None:
        self.task, self.job_id, self.last = task, job_id, time.monotonic()

    def __call__(self, fraction: float) -> bool:
        now = time.monotonic()
        if now - self.last < PROGRESS_INTERVAL_S:
            return True
        self.last = now
        if _registry().is_cancelled(self.job_id):
            return False
        self.task.update_state(state="PROGRESS", meta={"progress": fraction})
        return True


class _JobTask(Task):
    """Records the job's terminal status in the registry once Celery stored the outcome (``after_return``
    runs after the result backend was written), so the job list need not read results."""

    def after_return(self, status: str, retval: Any, task_id: str, args: Any, kwargs: Any, einfo: Any) -> None:
        recorded = {states.SUCCESS: "succeeded", states.FAILURE: "failed"}.get(status)
        if recorded is not None:
            _registry().set_status(task_id, recorded)


@app.task(bind=True, base=_JobTask, name="nonholonomic.simulate")
def simulate_job(self: Task, *args: Any, **kwargs: Any) -> dict[str, Any]:
    """Run a simulation job; returns the result JSON.

    The one argument is the request: a ``JobRequest`` (or ``PaperReportRequest``) as a JSON object, or
    a string holding that JSON. A job sent straight to the queue by a job-queue client
    (``send_task("nonholonomic.simulate", args=[request], queue=...)``) is registered here when it
    starts, unless the API registered it already (it keeps the API's record and cancellation flag).
    Anything else fails with the reason (:class:`workers.jobs.InvalidJob`).
    """
    job_id = self.request.id
    request, refused = request_from_args(args, kwargs)
    registry = _registry()
    registry.ensure(job_id, request)
    if registry.finished(job_id):  # a redelivered message of a finished job (workers.redelivery)
        raise Ignore()
    if registry.is_cancelled(job_id):
        self.update_state(state=states.REVOKED)
        raise Ignore()
    self.update_state(state=states.STARTED)
    if refused is not None:
        raise InvalidJob(refused)
    try:
        return run_job(request, _Progress(self, job_id))
    except IntegrationCancelled:
        self.update_state(state=states.REVOKED)
        raise Ignore() from None
    except SoftTimeLimitExceeded:
        raise JobTimeout(f"the job exceeded its time limit of {get_settings().job_soft_time_limit_s:g} s") from None


@lru_cache(maxsize=1)
def _ensemble_store() -> RedisEnsembleStore:
    settings = get_settings()
    return RedisEnsembleStore(redis.Redis.from_url(settings.redis_url or DEFAULT_REDIS_URL), settings.job_ttl_s)


@app.task(bind=True, name="nonholonomic.ensemble_chunk", ignore_result=True)
def ensemble_chunk(self: Task, ensemble_id: str, chunk: int) -> str:
    """Run one chunk of an ensemble (:func:`workers.ensembles.run_ensemble_chunk`); the results go to
    the ensemble's record, the task's own result is only what happened (``done``, ``cancelled`` ...)."""
    return run_ensemble_chunk(_ensemble_store(), ensemble_id, chunk, self.request.hostname or "worker")
