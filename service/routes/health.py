"""``GET /health``: status of the API, the broker and the workers."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse

import nonholonomic
from schemas.health import Health
from schemas.problems import PROBLEM_MEDIA_TYPE
from service.errors import PROBLEM_SCHEMA_REF
from service.openapi import operation_id

router = APIRouter(tags=["health"], generate_unique_id_function=operation_id)
_DEGRADED = {503: {"description": "jobs cannot run (queue mode: no broker, or no worker on the queue): the same "
                                  "body with status 'degraded'; a problem if the broker fails mid-check",
                   "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Health"}},
                               PROBLEM_MEDIA_TYPE: {"schema": {"$ref": PROBLEM_SCHEMA_REF}}}}}


@router.get("/health", operation_id="health-get", response_model=Health, responses=_DEGRADED,
            summary="Status of API, broker and workers")
def health(request: Request) -> JSONResponse:
    """200 when jobs can run (embedded mode, or a reachable broker with a worker on the queue), else 503."""
    parts: dict[str, Any] = request.app.state.backend.health()
    body = {"status": "ok" if parts["ok"] else "degraded", "api": "ok", "version": nonholonomic.__version__, **parts}
    body.pop("ok")
    return JSONResponse(body, status_code=200 if parts["ok"] else 503)
