"""``GET /health``: status of the API, the broker and the workers, within :data:`DEADLINE_S`.

The route runs on the event loop, and the backend's check in a thread of its own: it needs none of
the request threads, so it answers under any load of the other routes. A check slower than
:data:`DEADLINE_S` (an interpreter busy with warm-up threads) is answered from the last one, if recent.
"""

from __future__ import annotations

import asyncio
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse

import nonholonomic
from schemas.health import Health
from schemas.problems import PROBLEM_MEDIA_TYPE
from service.errors import PROBLEM_SCHEMA_REF
from service.openapi import operation_id

router = APIRouter(tags=["health"], generate_unique_id_function=operation_id)
_DEGRADED = {503: {"description": "a job would not start now (no broker, no worker on the queue, or workers still "
                                  "warming up): the same body with status 'degraded' and a detail",
                   "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Health"}},
                               PROBLEM_MEDIA_TYPE: {"schema": {"$ref": PROBLEM_SCHEMA_REF}}}}}
#: Seconds /health waits for the backend's check; past it, it answers with the last check if that is
#: younger than :data:`STALE_S`, else 503.
DEADLINE_S = 0.08
STALE_S = 5.0
_checks = ThreadPoolExecutor(max_workers=2, thread_name_prefix="health")


@router.get("/health", operation_id="health-get", response_model=Health, responses=_DEGRADED,
            summary="Status of API, broker and workers")
async def health(request: Request) -> JSONResponse:
    """200 when a job would start now (embedded mode warmed up, or a reachable broker with a warm worker on
    the queue), else 503. Names no host or credential."""
    backend, state = request.app.state.backend, request.app.state

    def remember(done: asyncio.Future[dict[str, Any]]) -> None:
        if not done.cancelled() and done.exception() is None:
            state.health_checked = (time.monotonic(), done.result())

    check = getattr(state, "health_inflight", None)
    if check is None or check.done():  # one check at a time: a stuck backend does not pile them up
        check = state.health_inflight = asyncio.get_running_loop().run_in_executor(_checks, backend.health)
        check.add_done_callback(remember)
    try:
        parts: dict[str, Any] = await asyncio.wait_for(asyncio.shield(check), DEADLINE_S)
    except asyncio.TimeoutError:  # a busy interpreter (warm-up threads, load): the last check, if recent
        checked_at, last = getattr(state, "health_checked", (None, None))
        if checked_at is not None and time.monotonic() - checked_at < STALE_S:
            parts = last
        else:
            parts = {"ok": False, "mode": backend.mode, "broker": f"unreachable: no answer within {DEADLINE_S:g} s",
                     "store": "unknown", "workers": {},
                     "detail": f"the broker or the job store does not answer within {DEADLINE_S:g} s"}
            if backend.mode == "queue":
                parts["queue"] = backend.settings.queue
    body = {"status": "ok" if parts["ok"] else "degraded", "api": "ok", "version": nonholonomic.__version__,
            **{k: v for k, v in parts.items() if k != "ok"},
            "symbolic": request.app.state.symbolic_pool.status()}
    return JSONResponse(body, status_code=200 if parts["ok"] else 503)
