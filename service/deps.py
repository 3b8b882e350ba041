"""What a route depends on, declared in its signature: the job backend and the caller's owner.

``backend: Backend`` and ``owner: Owner`` in a route's parameters give the app's
:class:`~service.backends.base.JobBackend` and the caller's owner id (:func:`service.access.caller`:
401/429 problems without a valid key; None when keys are off). FastAPI resolves each once per request.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from schemas.settings import Settings
from service.access import caller
from service.backends.base import JobBackend


async def job_backend(request: Request) -> JobBackend:
    """The app's job backend (made at start-up, :func:`service.main.create_app`). Async: it does not block."""
    backend: JobBackend = request.app.state.backend
    return backend


async def app_settings(request: Request) -> Settings:
    """The settings the app was started with."""
    settings: Settings = request.app.state.settings
    return settings


Backend = Annotated[JobBackend, Depends(job_backend)]
Owner = Annotated[str | None, Depends(caller)]
AppSettings = Annotated[Settings, Depends(app_settings)]
