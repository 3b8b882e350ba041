"""The ASGI app: ``service.main:app``.

Embedded mode (jobs in-process) unless ``REDIS_URL`` is set, then jobs go to Celery workers.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI
from fastapi_offline import FastAPIOffline

import nonholonomic
from schemas.settings import Settings, get_settings
from service.admission import SymbolicPool
from service.backends import make_backend
from service.errors import install_error_handlers
from service.isolated import start_fork_server
from service.limits import BodyLimit
from service.routes import ensembles, health, jobs, maps, pages, report, symbolic, systems


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the app; the job backend is created at startup from ``settings``."""

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        chosen = settings or get_settings()
        start_fork_server()  # for the symbolic requests' child processes
        app.state.symbolic_pool = SymbolicPool(chosen.symbolic_workers, chosen.symbolic_queue)
        app.state.backend = make_backend(chosen)
        try:
            yield
        finally:
            app.state.backend.close()

    app = FastAPIOffline(  # /docs and /redoc from files in the package, no CDN
        title="nonholonomic",
        version=nonholonomic.__version__,
        summary="Nonholonomic mechanics with machine-checked evidence (Borisov & Mamaev, "
                "'Hamiltonization of nonholonomic systems').",
        lifespan=lifespan,
    )
    install_error_handlers(app)
    app.add_middleware(BodyLimit, limit=(settings or get_settings()).max_body_bytes)
    app.include_router(health.router)
    app.include_router(systems.router)
    app.include_router(jobs.router)
    app.include_router(ensembles.router)
    app.include_router(symbolic.router)
    app.include_router(maps.router)
    app.include_router(report.router)
    app.include_router(pages.router)
    return app


app = create_app()
