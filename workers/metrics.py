"""Prometheus metrics of the work: tasks, jobs ended, integrations, crossings, memory.

A Celery worker serves them on its own port (``NONHOLONOMIC_WORKER_METRICS_PORT``, default 9191;
0: off) from its main process, adding up what every pool process counted. Prefork pool processes
cannot each be scraped, so the counts go through prometheus-client's multiprocess mode: one file per
process in ``PROMETHEUS_MULTIPROC_DIR`` (made and emptied here when the worker starts if the
deployment did not set it; set before any metric is made, so the pool processes inherit it).

In embedded mode the API runs the jobs: the same metrics are in the API's own ``/metrics``.

The metrics are made on first use (:func:`metrics`), not at import: the multiprocess values must be
chosen before the first one is made.
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
import threading
import time
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, multiprocess, start_http_server, values

from nonholonomic.numerics import tally

log = logging.getLogger(__name__)

MULTIPROC_ENV = "PROMETHEUS_MULTIPROC_DIR"
#: Task durations (seconds): a small job takes 0.1-1 s, an ensemble chunk up to the hard time limit.
DURATION_BUCKETS = (0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0, 600.0, 1200.0)


@dataclass(frozen=True)
class WorkMetrics:
    """The metrics of the work (their names as Prometheus shows them)."""

    #: ``nonholonomic_task_duration_seconds{task,status}``: a task's run in a worker.
    task_duration: Histogram
    #: ``nonholonomic_tasks_total{task,status}``: ``succeeded``; ``job_failed`` (the job's own failure: its
    #: integration, its request, its time limit); ``failed`` (anything else raised: a bug, the database away);
    #: ``retried``; ``ignored`` (a message delivered again for a job that ended, was cancelled or quarantined).
    tasks: Counter
    #: ``nonholonomic_task_redeliveries_total{task,source}``: ``broker`` (the message came back
    #: redelivered) or ``sweeper`` (a live worker sent a dead or cut-off worker's task again).
    redeliveries: Counter
    #: ``nonholonomic_jobs_finished_total{kind,status}``: jobs ended here (succeeded, failed).
    jobs_finished: Counter
    #: ``nonholonomic_members_finished_total{status}``: ensemble members stored here.
    members_finished: Counter
    #: ``nonholonomic_integrations_total`` and ``nonholonomic_crossings_total``: trajectories integrated
    #: and section crossings found (:mod:`nonholonomic.numerics.tally`); ``rate()`` gives them per second.
    integrations: Counter
    crossings: Counter


_made_lock = threading.Lock()


def metrics() -> WorkMetrics:
    """The metrics, made once per process (after :func:`use_multiprocess` in a worker; under a lock: two
    threads making them at once would register each name twice)."""
    with _made_lock:
        return _make()


@lru_cache(maxsize=1)
def _make() -> WorkMetrics:
    return WorkMetrics(
        task_duration=Histogram("nonholonomic_task_duration_seconds", "Celery task run time in a worker",
                                ["task", "status"], buckets=DURATION_BUCKETS),
        tasks=Counter("nonholonomic_tasks", "Celery tasks run, by outcome", ["task", "status"]),
        redeliveries=Counter("nonholonomic_task_redeliveries", "Tasks delivered again", ["task", "source"]),
        jobs_finished=Counter("nonholonomic_jobs_finished", "Jobs ended by this process", ["kind", "status"]),
        members_finished=Counter("nonholonomic_members_finished", "Ensemble members stored by this process",
                                 ["status"]),
        integrations=Counter("nonholonomic_integrations", "Trajectories integrated"),
        crossings=Counter("nonholonomic_crossings", "Poincare-section crossings found"),
    )


def resident_memory() -> Gauge:
    """``nonholonomic_worker_resident_memory_bytes{pid}``: each live pool process's resident memory (made
    only in the processes that run work: the worker's main process has no series)."""
    with _made_lock:
        return _make_memory()


@lru_cache(maxsize=1)
def _make_memory() -> Gauge:
    return Gauge("nonholonomic_worker_resident_memory_bytes", "Resident memory of a pool process",
                 multiprocess_mode="liveall")


def job_kind(request: dict[str, Any]) -> str:
    """A job's kind for its metrics: the system's kind if it is one of the catalog's, ``paper_report``, or
    ``other`` (a label takes few values: a message sent straight to the broker may name anything)."""
    from nonholonomic.systems import KINDS

    system = request.get("system")
    if isinstance(system, dict):
        kind = system.get("kind")
        return kind if isinstance(kind, str) and kind in KINDS else "other"
    return "paper_report" if request.get("job") == "paper_report" else "other"


def job_finished(request: dict[str, Any], status: str) -> None:
    metrics().jobs_finished.labels(job_kind(request), status).inc()


_tally_lock = threading.Lock()
_tally_seen = [0, 0]


def add_tally() -> None:
    """Move what the core counted since the last call (:func:`nonholonomic.numerics.tally.totals`) into
    the integration and crossing counters."""
    with _tally_lock:  # read and moved at once: two scrapes (or tasks) would otherwise move a count twice
        integrations, crossings = tally.totals()
        new = integrations - _tally_seen[0], crossings - _tally_seen[1]
        _tally_seen[:] = [integrations, crossings]
        m = metrics()
        if new[0]:
            m.integrations.inc(new[0])
        if new[1]:
            m.crossings.inc(new[1])


def resident_memory_bytes() -> int:
    """This process's resident memory now (``/proc/self/statm``; peak RSS where there is no /proc)."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
        return pages * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        import resource

        return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024


def note_memory() -> None:
    resident_memory().set(resident_memory_bytes())


# -- a worker's main process ---------------------------------------------------------------------------


def use_multiprocess() -> Path:
    """Count in files shared by the worker's processes: ``PROMETHEUS_MULTIPROC_DIR`` if set (emptied: the
    files of a previous run would add up), else a new temporary directory, exported to the pool."""
    chosen = os.environ.get(MULTIPROC_ENV)
    if chosen:
        path = Path(chosen)
        path.mkdir(parents=True, exist_ok=True)
        for stale in path.glob("*.db"):
            stale.unlink(missing_ok=True)
    else:
        path = Path(tempfile.mkdtemp(prefix="nonholonomic-metrics-"))
        os.environ[MULTIPROC_ENV] = str(path)
    values.ValueClass = values.get_value_class()  # the env var is read once, at import: choose again
    return path


def serve(port: int, address: str = "0.0.0.0") -> bool:  # noqa: S104 - scraped from other hosts
    """Serve the worker's metrics (every process's, added up) on ``address:port``; False (logged) if the
    port is taken."""
    registry = CollectorRegistry()
    registry.register(_LiveProcessesCollector())
    try:
        start_http_server(port, addr=address, registry=registry)
    except OSError as exc:
        log.warning("worker metrics not served on port %d: %s", port, exc)
        return False
    log.info("worker metrics on http://%s:%d/metrics", address, port)
    return True


class _LiveProcessesCollector(multiprocess.MultiProcessCollector):
    """The sum over the processes' files, once the live gauges of processes that died without a word (a
    hard time limit, an OOM kill: no ``worker_process_shutdown``) are removed."""

    def __init__(self) -> None:
        super().__init__(None)  # not registered by the base: the caller registers this one

    def collect(self) -> Any:
        for path in Path(os.environ[MULTIPROC_ENV]).glob("gauge_live*_*.db"):
            pid = path.stem.rsplit("_", 1)[-1]
            if pid.isdigit() and not _alive(int(pid)):
                multiprocess.mark_process_dead(int(pid))
        return super().collect()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def process_ended(pid: int) -> None:
    """A pool process ended: its live gauges leave the sums."""
    if os.environ.get(MULTIPROC_ENV):
        multiprocess.mark_process_dead(pid)


def remove(path: Path) -> None:
    """The worker stops: the directory :func:`use_multiprocess` made goes with it."""
    if path.name.startswith("nonholonomic-metrics-"):
        shutil.rmtree(path, ignore_errors=True)


# -- a task's run --------------------------------------------------------------------------------------

_started: dict[str, float] = {}
_job_failures: set[str] = set()


def job_failed_in_task(task_id: str, exc: BaseException) -> None:
    """The task raised ``exc``: if it is a job's own failure (its integration stopped, its request was
    invalid, its time limit passed: the job's error, reported to its client), the task's outcome is
    ``job_failed``, not ``failed`` (kept for the unexpected: a bug, a database away)."""
    from nonholonomic.numerics.integration import IntegrationError
    from workers.jobs import InvalidJob, NonFiniteResult
    from workers.limits import JobTimeout

    if isinstance(exc, IntegrationError | InvalidJob | NonFiniteResult | JobTimeout):
        _job_failures.add(task_id)


def task_started(task_id: str, task: str, redelivered: bool) -> None:
    _started[task_id] = time.perf_counter()
    if redelivered:
        metrics().redeliveries.labels(task, "broker").inc()


def task_ended(task_id: str, task: str, state: str | None) -> None:
    """A task's run ended with Celery state ``state``: its duration and outcome, the work's tally and
    the process's memory."""
    start = _started.pop(task_id, None)
    status = {"SUCCESS": "succeeded", "RETRY": "retried", "IGNORED": "ignored"}.get(state or "", "failed")
    if status == "failed" and task_id in _job_failures:
        status = "job_failed"
    _job_failures.discard(task_id)
    m = metrics()
    if start is not None:
        m.task_duration.labels(task, status).observe(time.perf_counter() - start)
    if status != "retried":  # counted by the retry signal
        m.tasks.labels(task, status).inc()
    add_tally()
    note_memory()


def task_retried(task: str) -> None:
    metrics().tasks.labels(task, "retried").inc()


def sent_again(task: str) -> None:
    """A live worker's sweep sent a task of a dead or cut-off worker again."""
    metrics().redeliveries.labels(task, "sweeper").inc()
