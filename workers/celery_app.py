"""The Celery app (``workers.celery_app:app``): Redis broker and result backend from ``REDIS_URL``.

Start a worker with::

    REDIS_URL=redis://127.0.0.1:6379/0 .venv/bin/celery -A workers.celery_app:app worker -Q nonholonomic
"""

from __future__ import annotations

import os
from functools import lru_cache
from typing import Any

from celery import Celery
from celery.signals import (
    after_setup_logger,
    after_setup_task_logger,
    before_task_publish,
    task_failure,
    task_postrun,
    task_prerun,
    task_received,
    task_retry,
    task_revoked,
    worker_init,
    worker_process_init,
    worker_process_shutdown,
    worker_ready,
    worker_shutdown,
)

from schemas.settings import get_settings

DEFAULT_REDIS_URL = "redis://127.0.0.1:6379/0"


def make_app() -> Celery:
    """Build the Celery app from :class:`schemas.settings.Settings`.

    Raises
    ------
    ValueError
        If the time limits are not below the broker's visibility timeout (a running job would be
        redelivered to a second worker).
    """
    settings = get_settings()
    if not settings.job_soft_time_limit_s < settings.job_time_limit_s < settings.visibility_timeout_s:
        raise ValueError("need job_soft_time_limit_s < job_time_limit_s < visibility_timeout_s")
    url = settings.redis_url or DEFAULT_REDIS_URL
    celery = Celery("nonholonomic", broker=url, backend=url, include=["workers.tasks"])
    celery.conf.update(
        task_serializer="json",
        result_serializer="json",
        accept_content=["json"],
        task_acks_late=True,
        task_reject_on_worker_lost=True,
        worker_prefetch_multiplier=1,
        task_soft_time_limit=settings.job_soft_time_limit_s,
        task_time_limit=settings.job_time_limit_s,
        broker_transport_options={"visibility_timeout": settings.visibility_timeout_s},
        result_expires=settings.job_ttl_s,
        # "running" is the job store's (written by the task once it checked that its job has not ended:
        # a redelivered task of a finished job must not show it running again); Celery's result backend
        # carries only PROGRESS
        task_track_started=False,
        task_default_queue=settings.queue,
        broker_connection_retry_on_startup=True,
        # The warm-up compiles every integrator in each child before it takes jobs.
        worker_proc_alive_timeout=300.0,
        # Progress writes are best-effort (workers.tasks._Progress): one quick retry, not Celery's 20
        # (~19 s of a job stalled per write while Redis is away)
        result_backend_transport_options={"retry_policy": {"max_retries": 1, "interval_start": 0.2,
                                                           "interval_step": 0.2, "interval_max": 0.2}},
        # A pool process past this resident memory (KiB) after a job is replaced by a fresh one, which warms
        # up before it says so (_warm_up): the code heyoka compiled for many distinct user expressions is
        # not all given back (bench/README.md, bench_user_potentials.py --worker)
        worker_max_memory_per_child=settings.worker_max_memory_mib * 1024 or None,
        worker_max_tasks_per_child=settings.worker_max_jobs or None,
        # Task events (sent, received, started, succeeded, failed ...): Flower and celery-exporter see the work
        worker_send_task_events=True,
        task_send_sent_event=True,
        # Soft shutdown (Celery >= 5.5): on a cold shutdown, running tasks get this long to end before their
        # messages go back to the queue (Kubernetes: REMAP_SIGTERM=SIGQUIT, within the grace period)
        worker_soft_shutdown_timeout=settings.worker_soft_shutdown_s,
    )
    return celery


app = make_app()


#: The task of a simulation job.
SIMULATE = "nonholonomic.simulate"
_heartbeats: list[Any] = []
_sweepers: list[Any] = []


@lru_cache(maxsize=1)
def _redis() -> Any:
    """The broker's Redis, for heartbeats and held tasks (redis-py reconnects after a fork)."""
    import redis

    return redis.Redis.from_url(get_settings().redis_url or DEFAULT_REDIS_URL, socket_timeout=5)


def _beat(key: str, value: str, measure: bool = False) -> None:
    """A heartbeat under ``key``; with ``measure``, each beat (every 3 s) also samples this process's
    resident memory for its metrics, during a job too."""
    from workers.heartbeat import Heartbeat

    def beat() -> str:
        if measure:
            from workers.metrics import note_memory

            try:
                note_memory()
            except Exception:  # noqa: BLE001 - a metric never stops the heartbeat
                pass
        return value

    _heartbeats.append(Heartbeat(get_settings().redis_url or DEFAULT_REDIS_URL, key, beat).start())


_metrics_dir: list[Any] = []


@worker_init.connect
def _serve_metrics(**_: Any) -> None:
    """The worker's metrics (:mod:`workers.metrics`): counted in files shared with the pool processes
    (chosen here, before they fork), served from this process on ``worker_metrics_port``."""
    port = get_settings().worker_metrics_port
    if port:
        from workers import metrics

        _metrics_dir.append(metrics.use_multiprocess())
        metrics.serve(port)


@after_setup_logger.connect
@after_setup_task_logger.connect
def _log_format(logger: Any = None, **_: Any) -> None:
    """The worker's lines in the service's format (:mod:`workers.logs`: JSON with the request and job ids)."""
    from workers.logs import use_format

    if logger is not None:
        use_format(list(logger.handlers), get_settings().log_format)


@before_task_publish.connect
def _carry_request_id(headers: dict[str, Any] | None = None, **_: Any) -> None:
    """The request id of the request that sends a task goes with it (its ``request_id`` header)."""
    from workers.logs import REQUEST_ID, TASK_HEADER

    request_id = REQUEST_ID.get()
    if headers is not None and request_id and TASK_HEADER not in headers:
        headers[TASK_HEADER] = request_id


_context_tokens: dict[str, tuple[Any, Any]] = {}


@task_prerun.connect
def _task_started(task_id: str | None = None, task: Any = None, **_: Any) -> None:
    """The task's request id and job id for its log lines; its start for its metrics."""
    from workers import metrics
    from workers.logs import JOB_ID, REQUEST_ID, TASK_HEADER

    if task_id is None or task is None:
        return
    request = task.request
    request_id = getattr(request, TASK_HEADER, None) or (request.headers or {}).get(TASK_HEADER)
    _context_tokens[task_id] = (REQUEST_ID.set(request_id), JOB_ID.set(task_id))
    metrics.task_started(task_id, task.name, bool((request.delivery_info or {}).get("redelivered")))


@task_failure.connect
def _task_raised(task_id: str | None = None, exception: BaseException | None = None, **_: Any) -> None:
    from workers import metrics

    if task_id is not None and exception is not None:
        metrics.job_failed_in_task(task_id, exception)


@task_postrun.connect
def _task_ended(task_id: str | None = None, task: Any = None, state: str | None = None, **_: Any) -> None:
    from workers import metrics
    from workers.logs import JOB_ID, REQUEST_ID

    if task_id is None or task is None:
        return
    tokens = _context_tokens.pop(task_id, None)
    try:
        metrics.task_ended(task_id, task.name, state)
    finally:  # the next task's lines never carry this one's ids
        if tokens is not None:
            REQUEST_ID.reset(tokens[0])
            JOB_ID.reset(tokens[1])


@task_retry.connect
def _task_retried(sender: Any = None, **_: Any) -> None:
    from workers import metrics

    metrics.task_retried(getattr(sender, "name", "unknown"))


@worker_init.connect
def _fingerprint_code(**_: Any) -> None:
    """The memo's fingerprints of the code as the main process loaded it, before the pool forks: a pool
    process started later (recycled past its memory bound) runs this code and must key its results by
    it, even if the files on disk changed since."""
    from workers.disk_memo import fingerprint, response_fingerprint

    fingerprint()
    response_fingerprint()


@worker_process_init.connect
def _warm_up(**_: Any) -> None:
    """A pool process opens the memo on disk (what another process derived is read back, not derived
    again), compiles every integrator before it takes jobs (unless ``warm_up`` is off), then says it
    is warm."""
    from workers.heartbeat import process_key

    _heartbeats.clear()  # copies of the main process's, inherited by the fork: not ours to stop
    from workers.tracing import set_up

    set_up("nonholonomic-worker")  # this process's own tracer provider (only when OTEL_* ask for traces)
    from workers.job_store import job_store

    if job_store.cache_info().currsize:  # the main process's engine, inherited: its connections are not ours
        job_store().engine.dispose(close=False)
    _open_job_store()
    from workers.disk_memo import install_from_settings

    install_from_settings()  # symbolic results remembered across processes, with or without a warm-up
    if get_settings().warm_up:
        from workers.jobs import warm_up

        warm_up()
    _beat(process_key(), "warm", measure=True)


def _open_job_store() -> None:
    """Connect to the job store (and migrate it) before taking jobs: not inside the first job's time
    limit. A database that is away now is tried again by the first job."""
    from workers.job_store import job_store

    try:
        job_store()
    except Exception as exc:
        import logging

        logging.getLogger(__name__).warning("the job store is not reachable yet: %s", str(exc).splitlines()[0])


@worker_ready.connect
def _announce(sender: Any = None, **_: Any) -> None:
    """The worker's name and queues, for ``/health`` (:mod:`workers.heartbeat`)."""
    import json

    from workers.heartbeat import process_key, worker_key
    from workers.redelivery import Sweeper

    _open_job_store()
    queues = sorted(q.name for q in sender.task_consumer.queues)
    _beat(worker_key(), json.dumps({"name": sender.hostname, "queues": queues}))
    _sweepers.append(Sweeper([_sweep_tasks, _sweep_jobs, _sweep_ensembles]).start())
    if "prefork" not in type(sender.pool).__module__:  # solo or threads: jobs run in this process
        from workers.tracing import set_up

        set_up("nonholonomic-worker")
        if get_settings().warm_up:
            from workers.jobs import warm_up

            warm_up()
        _beat(process_key(os.getpid()), "warm", measure=True)


def _send_again(name: str, args: Any, kwargs: Any, task_id: str, queue: str) -> None:
    from workers.metrics import sent_again

    app.send_task(name, args=args, kwargs=kwargs, task_id=task_id, queue=queue)
    sent_again(name)


def _sweep_tasks() -> None:
    """Tasks (ensemble chunks) held by a worker that died whole: sent again (workers.redelivery)."""
    from workers.redelivery import sweep

    sweep(_redis(), _send_again)


def _sweep_jobs() -> None:
    """Jobs whose message the broker lost or whose worker died: sent again (workers.job_store)."""
    from workers.job_store import job_store, resend_lost

    client = _redis()
    resend_lost(job_store(), client,
                lambda request, job_id, queue: _send_again(SIMULATE, [request], {}, job_id, queue),
                lambda worker: bool(client.exists(worker)))


def _sweep_ensembles() -> None:
    """Pending chunks of ensembles whose messages the broker lost: sent again (workers.job_store)."""
    from workers.ensembles import ENSEMBLE_CHUNK, chunk_task_id
    from workers.job_store import ensemble_store, resend_lost_chunks

    resend_lost_chunks(ensemble_store(), _redis(),
                       lambda ensemble_id, chunk, queue: _send_again(ENSEMBLE_CHUNK, [ensemble_id, chunk], {},
                                                                    chunk_task_id(ensemble_id, chunk), queue))


@task_received.connect
def _hold(request: Any = None, **_: Any) -> None:
    """Note the received task under this worker's heartbeat (:mod:`workers.redelivery`); not a job's:
    its row in the job store names its worker, and :func:`_sweep_jobs` sends it again."""
    from workers.heartbeat import worker_key
    from workers.redelivery import record_received

    if request.name == SIMULATE:
        return
    settings = get_settings()
    queue = (request.delivery_info or {}).get("routing_key") or settings.queue
    record_received(_redis(), worker_key(), request.id, request.name, request.args, request.kwargs, queue,
                    int(settings.visibility_timeout_s))


@task_postrun.connect
def _release(sender: Any = None, task_id: str | None = None, **_: Any) -> None:
    from workers.redelivery import record_ended

    if task_id and getattr(sender, "name", None) != SIMULATE:
        record_ended(_redis(), task_id)


@task_revoked.connect
def _release_revoked(request: Any = None, **_: Any) -> None:
    from workers.redelivery import record_ended

    if request is not None and request.name != SIMULATE:
        record_ended(_redis(), request.id)


@worker_process_shutdown.connect
def _silence_process(pid: int | None = None, **_: Any) -> None:
    from workers.metrics import process_ended

    while _heartbeats:
        _heartbeats.pop().stop()
    process_ended(pid or os.getpid())


@worker_shutdown.connect
def _silence(**_: Any) -> None:
    """A worker that stops (warm shutdown: its running tasks ended) gives back what it still held: the
    broker restores those messages, so they must not also be sent again."""
    from workers.heartbeat import worker_key
    from workers.redelivery import release_owned

    while _sweepers:
        _sweepers.pop().stop()
    release_owned(_redis(), worker_key())
    while _heartbeats:
        _heartbeats.pop().stop()
    from workers.metrics import remove

    while _metrics_dir:
        remove(_metrics_dir.pop())
