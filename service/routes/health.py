"""``GET /health``: status of the API, the broker and the workers, answered on the event loop within
:data:`DEADLINE_S` under any load of the other routes.

The backend's check (broker, heartbeats, job store) runs in threads of its own, never in the request
threads: the route starts one and waits for it up to :data:`DEADLINE_S` (an idle machine answers
within it: the answer is current). Past it, the route answers with the latest check, which a monitor
on the event loop keeps at most :data:`REFRESH_S` old (``age_s`` in the body says how old); an answer
older than :data:`STALE_S` is a 503. So a loaded API answers at once and an outage shows within
about ``REFRESH_S`` + the check's own timeouts.

Two things in the router's lifespan keep the event loop itself answering under load (profiled with
``bench/bench_load.py``): a bound on the threads of blocking request work (:func:`limit_request_threads`;
Starlette's default of 40 lets forty submissions contend for the GIL with the loop), and the objects
alive after start-up (sympy, heyoka, the app: ~230,000) frozen out of the garbage collector
(:func:`gc.freeze`), whose full collections held the GIL for 0.4-1.5 s on a loaded machine.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import time
from collections.abc import AsyncIterator
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import anyio.to_thread
from fastapi import APIRouter, FastAPI, Request
from fastapi.responses import JSONResponse

import nonholonomic
from schemas.health import Health
from schemas.problems import PROBLEM_MEDIA_TYPE
from service.errors import PROBLEM_SCHEMA_REF
from service.openapi import operation_id

#: Seconds the route waits for a check of its own before answering with the monitor's latest.
DEADLINE_S = 0.025
#: Seconds between the monitor's checks (none while the route's own checks are more recent).
REFRESH_S = 0.25
#: A latest check older than this is no answer: 503 (the backend's check hangs).
STALE_S = 2.0
#: Checks running at once, at most: a backend that hangs does not pile them up.
MAX_CHECKS = 2


class HealthMonitor:
    """The backend's checks in threads of their own, and the latest result.

    Parameters
    ----------
    backend
        The job backend; its ``health()`` returns the parts of the answer (``ok``, ``broker`` ...).
    """

    def __init__(self, backend: Any) -> None:
        self.backend = backend
        self.latest: tuple[float, dict[str, Any]] | None = None  # (monotonic start of the check, its parts)
        self._started = float("-inf")
        self._running: set[asyncio.Future[dict[str, Any]]] = set()
        self._threads = ThreadPoolExecutor(max_workers=MAX_CHECKS, thread_name_prefix="health")

    def check(self) -> asyncio.Future[dict[str, Any]] | None:
        """Start a check (None when :data:`MAX_CHECKS` are running); its result becomes the latest unless
        a check started later has finished first."""
        if len(self._running) >= MAX_CHECKS:
            return None
        started = self._started = time.monotonic()
        check = asyncio.get_running_loop().run_in_executor(self._threads, self.backend.health)
        self._running.add(check)

        def remember(done: asyncio.Future[dict[str, Any]]) -> None:
            self._running.discard(done)
            if done.cancelled() or done.exception() is not None:
                return  # no answer: the latest ages, and past STALE_S the route says 503
            if self.latest is None or started >= self.latest[0]:
                self.latest = (started, done.result())

        check.add_done_callback(remember)
        return check

    def recent(self) -> tuple[float, dict[str, Any]] | None:
        """The latest check's age in seconds and its parts, if younger than :data:`STALE_S`."""
        if self.latest is None:
            return None
        age = time.monotonic() - self.latest[0]
        return (age, self.latest[1]) if age < STALE_S else None

    async def run(self) -> None:
        """Check every :data:`REFRESH_S` unless a request's check started meanwhile (until cancelled)."""
        while True:
            wait = self._started + REFRESH_S - time.monotonic()
            if wait <= 0:
                self.check()
                wait = REFRESH_S
            await asyncio.sleep(wait)

    def close(self) -> None:
        self._threads.shutdown(wait=False, cancel_futures=True)


def limit_request_threads(app: FastAPI) -> None:
    """Bound the threads of blocking request work (sync routes, ``run_in_threadpool``) to the setting
    ``request_threads`` plus the symbolic pool's slots (each of which holds a thread while its child
    runs); requests beyond wait on the event loop, which keeps the GIL often enough to answer."""
    settings = app.state.settings
    tokens = settings.request_threads + settings.symbolic_workers
    anyio.to_thread.current_default_thread_limiter().total_tokens = tokens


_frozen = False


def _freeze_start_up() -> None:
    """Collect, then move what start-up made out of the garbage collector's full collections: once per
    process (a second app in the same process, as in the tests, finds it done; a full collection of
    a large heap costs a second)."""
    global _frozen
    if not _frozen:
        _frozen = True
        gc.collect()
        gc.freeze()


@contextlib.asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    """Start the monitor (the app's lifespan made the backend already), bound the request threads and
    freeze what start-up made out of the garbage collector's full collections."""
    limit_request_threads(app)
    _freeze_start_up()
    monitor = app.state.health_monitor = HealthMonitor(app.state.backend)
    task = asyncio.create_task(monitor.run(), name="health-monitor")
    try:
        yield
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        monitor.close()


router = APIRouter(tags=["health"], generate_unique_id_function=operation_id, lifespan=lifespan)
_DEGRADED: dict[int | str, dict[str, Any]] = {
    503: {"description": "a job would not start now (no broker, no worker on the queue, or workers still "
                         "warming up): the same body with status 'degraded' and a detail",
          "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Health"}},
                      PROBLEM_MEDIA_TYPE: {"schema": {"$ref": PROBLEM_SCHEMA_REF}}}}}


def _no_answer(backend: Any) -> dict[str, Any]:
    """The parts of a 503 when no check answered within :data:`STALE_S`."""
    parts = {"ok": False, "mode": backend.mode, "broker": f"unreachable: no answer within {STALE_S:g} s",
             "store": "unknown", "workers": {},
             "detail": f"the broker or the job store does not answer within {STALE_S:g} s"}
    if backend.mode == "queue":
        parts["queue"] = backend.settings.queue
    return parts


@router.get("/health", operation_id="health-get", response_model=Health, responses=_DEGRADED,
            summary="Status of API, broker and workers")
async def health(request: Request) -> JSONResponse:
    """200 when a job would start now (embedded mode warmed up, or a reachable broker with a warm worker on
    the queue), else 503. Names no host or credential."""
    state = request.app.state
    monitor: HealthMonitor | None = getattr(state, "health_monitor", None)
    if monitor is None:  # an app whose lifespan did not run this router's (mounted elsewhere)
        monitor = state.health_monitor = HealthMonitor(state.backend)
    parts: dict[str, Any] | None = None
    age = 0.0
    check = monitor.check()
    if check is not None:
        try:
            parts = await asyncio.wait_for(asyncio.shield(check), DEADLINE_S)
        except Exception:  # noqa: BLE001 - a late (or failed) check: the latest one, if recent
            parts = None
    if parts is None:
        recent = monitor.recent()
        age, parts = recent if recent is not None else (0.0, _no_answer(state.backend))
    body = {"status": "ok" if parts["ok"] else "degraded", "api": "ok", "version": nonholonomic.__version__,
            **{k: v for k, v in parts.items() if k != "ok"}, "age_s": round(age, 3),
            "symbolic": state.symbolic_pool.status()}
    return JSONResponse(body, status_code=200 if parts["ok"] else 503)


@router.get("/health/live", operation_id="health-live", summary="The API process answers (for probes)",
            responses={200: {"content": {"application/json": {"example": {"status": "ok"}}}}})
async def live() -> dict[str, str]:
    """200 as long as this process's event loop answers: for a container's liveness and readiness probes.
    Unlike ``/health`` it does not ask the broker, the store or the workers: an API whose workers scaled to
    zero (no warm worker: ``/health`` is 503) must still take the submissions that wake them."""
    return {"status": "ok"}
