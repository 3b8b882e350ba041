"""The Celery app (``workers.celery_app:app``): Redis broker and result backend from ``REDIS_URL``.

Start a worker with::

    REDIS_URL=redis://127.0.0.1:6379/0 .venv/bin/celery -A workers.celery_app:app worker -Q nonholonomic
"""

from __future__ import annotations

from typing import Any

from celery import Celery
from celery.signals import worker_process_init, worker_process_shutdown, worker_ready, worker_shutdown

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
        task_track_started=True,
        task_default_queue=settings.queue,
        broker_connection_retry_on_startup=True,
        # The warm-up compiles every integrator in each child before it takes jobs.
        worker_proc_alive_timeout=300.0,
    )
    return celery


app = make_app()


_heartbeats: list[Any] = []


def _beat(key: str, value: str) -> None:
    from workers.heartbeat import Heartbeat

    _heartbeats.append(Heartbeat(get_settings().redis_url or DEFAULT_REDIS_URL, key, lambda: value).start())


@worker_process_init.connect
def _warm_up(**_: Any) -> None:
    """A pool process compiles every integrator before it takes jobs, then says it is warm."""
    from workers.heartbeat import process_key

    _heartbeats.clear()  # copies of the main process's, inherited by the fork: not ours to stop
    if get_settings().warm_up:
        from workers.jobs import warm_up

        warm_up()
    _beat(process_key(), "warm")


@worker_ready.connect
def _announce(sender: Any = None, **_: Any) -> None:
    """The worker's name and queues, for ``/health`` (:mod:`workers.heartbeat`)."""
    import json
    import os

    from workers.heartbeat import process_key, worker_key

    queues = sorted(q.name for q in sender.task_consumer.queues)
    _beat(worker_key(), json.dumps({"name": sender.hostname, "queues": queues}))
    if "prefork" not in type(sender.pool).__module__:  # solo or threads: jobs run in this process
        if get_settings().warm_up:
            from workers.jobs import warm_up

            warm_up()
        _beat(process_key(os.getpid()), "warm")


@worker_process_shutdown.connect
@worker_shutdown.connect
def _silence(**_: Any) -> None:
    while _heartbeats:
        _heartbeats.pop().stop()
