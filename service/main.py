"""The ASGI app: ``service.main:app``.

Embedded mode (jobs in-process) unless ``REDIS_URL`` is set, then jobs go to Celery workers.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import Depends, FastAPI
from fastapi.middleware.cors import CORSMiddleware
from fastapi.staticfiles import StaticFiles
from fastapi_offline import FastAPIOffline

import nonholonomic
from schemas.settings import Settings, get_settings
from service.access import Access, caller
from service.admission import SymbolicPool
from service.backends import make_backend
from service.errors import install_error_handlers, problem_responses
from service.idempotency import idempotency_store
from service.isolated import start_fork_server
from service.limits import BodyLimit
from service.routes import ensembles, health, jobs, maps, pages, report, symbolic, systems
from service.security import SecurityHeaders
from workers.disk_memo import install_disk_memo

#: Where the pages' stylesheet and icon are served (``service/static``; no API key needed).
STATIC_URL = "/static"
#: Swagger UI and ReDoc (their own, looser content security policy: :data:`service.security.DOCS_POLICY`).
DOCS_URL, REDOC_URL = "/docs", "/redoc"


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the app; the job backend is created at startup from ``settings``."""
    chosen = settings or get_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        install_disk_memo(chosen.cache_dir, chosen.cache_max_mib)  # symbolic results remembered between runs
        if chosen.symbolic_prestart:
            start_fork_server()  # for the symbolic requests' child processes (in the background)
        app.state.symbolic_pool = SymbolicPool(chosen.symbolic_workers, chosen.symbolic_queue)
        app.state.backend = make_backend(chosen)
        app.state.idempotency = idempotency_store(app.state.backend, chosen.job_ttl_s)
        try:
            yield
        finally:
            app.state.backend.close()

    app = FastAPIOffline(  # /docs and /redoc from files in the package, no CDN
        docs_url=DOCS_URL,
        redoc_url=REDOC_URL,
        title="nonholonomic",
        version=nonholonomic.__version__,
        summary="Nonholonomic mechanics with machine-checked evidence (Borisov & Mamaev, "
                "'Hamiltonization of nonholonomic systems').",
        lifespan=lifespan,
    )
    install_error_handlers(app)
    app.state.settings = chosen
    app.state.access = Access(chosen)
    app.add_middleware(BodyLimit, limit=chosen.max_body_bytes)
    origins = [o.strip() for o in chosen.cors_origins.split(",") if o.strip()]
    if origins:
        app.add_middleware(CORSMiddleware, allow_origins=origins, allow_methods=["GET", "POST", "DELETE"],
                           allow_headers=["Authorization", "X-API-Key", "Content-Type", "Idempotency-Key"],
                           expose_headers=["Location", "Retry-After", "Link", "Idempotent-Replayed"])
    app.include_router(health.router)
    # every /v1 route: the caller's key (when keys are configured) and its rate
    keyed = {"dependencies": [Depends(caller)],
             "responses": problem_responses({401: "API keys are on and none, or an unknown one, was sent",
                                             429: "the key's rate limit; `Retry-After` says when to retry"})}
    for router in (systems.router, jobs.router, ensembles.router, symbolic.router, maps.router, report.router,
                   pages.router):
        app.include_router(router, **keyed)  # type: ignore[arg-type]
    app.mount(STATIC_URL, StaticFiles(packages=[("service", "static")]), name="static")
    _secure(app)
    return app


def _secure(app: FastAPI) -> None:
    """Security headers (:mod:`service.security`) on every answer, the 500s included: the middleware
    wraps the whole stack, outside Starlette's ServerErrorMiddleware (``add_middleware`` would sit inside it)."""
    docs = frozenset(p for p in (DOCS_URL, REDOC_URL, app.swagger_ui_oauth2_redirect_url) if p)
    build = app.build_middleware_stack
    app.build_middleware_stack = lambda: SecurityHeaders(build(), docs)  # type: ignore[method-assign]


app = create_app()
