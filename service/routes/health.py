"""``GET /health``: status of the API, the broker and the workers."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse

import nonholonomic

router = APIRouter(tags=["health"])


@router.get("/health", summary="Status of API, broker and workers")
def health(request: Request) -> JSONResponse:
    """200 when jobs can run (embedded mode, or a reachable broker with a worker on the queue), else 503."""
    parts: dict[str, Any] = request.app.state.backend.health()
    body = {"status": "ok" if parts["ok"] else "degraded", "api": "ok", "version": nonholonomic.__version__, **parts}
    body.pop("ok")
    return JSONResponse(body, status_code=200 if parts["ok"] else 503)
