"""The ASGI app: ``service.main:app``.

Embedded mode (jobs in-process) unless ``REDIS_URL`` is set, then jobs go to Celery workers.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from functools import lru_cache
from pathlib import Path

import fastapi_offline
from fastapi import Depends, FastAPI, Request, Response
from fastapi.middleware.cors import CORSMiddleware
from fastapi.openapi.docs import get_redoc_html
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles
from fastapi_offline import FastAPIOffline

import nonholonomic
from schemas.settings import Settings, get_settings
from service import metrics
from service.access import Access, caller
from service.admission import SymbolicPool
from service.backends import make_backend
from service.errors import install_error_handlers, problem_responses
from service.isolated import start_fork_server
from service.limits import BodyLimit
from service.request_id import RequestId
from service.routes import (
    ensembles,
    explore,
    health,
    jobs,
    maps,
    pages,
    report,
    symbolic,
    systems,
)
from service.security import SecurityHeaders
from workers import tracing
from workers.disk_memo import install_disk_memo
from workers.logs import HEADER, configure_api

#: Where the pages' stylesheet and icon are served (``service/static``; no API key needed).
STATIC_URL = "/static"
#: Swagger UI and ReDoc (their own, looser content security policy: :data:`service.security.DOCS_POLICY`).
DOCS_URL, REDOC_URL = "/docs", "/redoc"
#: ReDoc's bundle as /redoc loads it: fastapi-offline's file with its one address on the internet (the
#: "API docs by Redocly" logo, drawn whatever the options) replaced by an empty image.
REDOC_JS_URL = "/docs-assets/redoc.standalone.js"
REDOC_LOGO = "https://cdn.redoc.ly/redoc/logo-mini.svg"
_EMPTY_IMAGE = "data:image/gif;base64,R0lGODlhAQABAIAAAAAAAP///yH5BAEAAAAALAAAAAABAAEAAAIBRAA7"
#: Swagger UI asks validator.swagger.io for a badge when the service is not on localhost: not asked.
SWAGGER_UI_PARAMETERS = {"validatorUrl": None}


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
        try:
            yield
        finally:
            app.state.backend.close()

    app = FastAPIOffline(  # /docs from files in the package, no CDN; /redoc: ours, below
        docs_url=DOCS_URL,
        redoc_url=None,
        swagger_ui_parameters=SWAGGER_UI_PARAMETERS,
        title="nonholonomic",
        version=nonholonomic.__version__,
        summary="Nonholonomic mechanics with machine-checked evidence (Borisov & Mamaev, "
                "'Hamiltonization of nonholonomic systems').",
        lifespan=lifespan,
    )
    install_error_handlers(app)
    configure_api(chosen.log_format)
    app.state.settings = chosen
    app.state.access = Access(chosen)
    app.add_middleware(BodyLimit, limit=chosen.max_body_bytes)
    origins = [o.strip() for o in chosen.cors_origins.split(",") if o.strip()]
    if origins:
        app.add_middleware(CORSMiddleware, allow_origins=origins, allow_methods=["GET", "POST", "DELETE"],
                           allow_headers=["Authorization", "X-API-Key", "Content-Type", "Idempotency-Key", HEADER],
                           expose_headers=["Location", "Retry-After", "Link", "Idempotent-Replayed", HEADER])
    app.include_router(health.router)
    # every /v1 route: the caller's key (when keys are configured) and its rate
    dependencies = [Depends(caller)]
    responses = problem_responses({401: "API keys are on and none, or an unknown one, was sent",
                                   429: "the key's rate limit; `Retry-After` says when to retry"})
    for router in (systems.router, jobs.router, ensembles.router, symbolic.router, maps.router, report.router,
                   pages.router, explore.router):
        app.include_router(router, dependencies=dependencies, responses=responses)
    metrics.install(app, chosen)
    tracing.instrument_app(app)  # only when the OTEL_* variables ask for traces
    app.mount(STATIC_URL, StaticFiles(packages=[("service", "static")]), name="static")
    _redoc(app)
    _secure(app)
    return app


@lru_cache(maxsize=1)
def redoc_bundle() -> bytes:
    """fastapi-offline's ReDoc bundle with the Redocly logo's address replaced by an empty ``data:`` image,
    so that /redoc asks nothing from elsewhere (its fonts are the system's: no Google Fonts link)."""
    text = (Path(fastapi_offline.__file__).parent / "static" / "redoc.standalone.js").read_text(encoding="utf-8")
    return text.replace(REDOC_LOGO, _EMPTY_IMAGE).encode()


def _redoc(app: FastAPI) -> None:
    """``/redoc``: ReDoc with the patched bundle (:func:`redoc_bundle`), no Google Fonts."""

    @app.get(REDOC_URL, include_in_schema=False)
    async def redoc_html(request: Request) -> HTMLResponse:
        root = request.scope.get("root_path", "")
        return get_redoc_html(openapi_url=f"{root}{app.openapi_url}", title=f"{app.title} - ReDoc",
                              redoc_js_url=f"{root}{REDOC_JS_URL}", redoc_favicon_url=f"{root}{STATIC_URL}/favicon.svg",
                              with_google_fonts=False)

    @app.get(REDOC_JS_URL, include_in_schema=False)
    async def redoc_js() -> Response:
        return Response(redoc_bundle(), media_type="text/javascript",
                        headers={"Cache-Control": "public, max-age=86400"})


def _secure(app: FastAPI) -> None:
    """Security headers (:mod:`service.security`) and the request id (:mod:`service.request_id`) on every
    answer, the 500s included: the middlewares wrap the whole stack, outside Starlette's
    ServerErrorMiddleware (``add_middleware`` would sit inside it)."""
    docs = frozenset(p for p in (DOCS_URL, REDOC_URL, app.swagger_ui_oauth2_redirect_url) if p)
    build = app.build_middleware_stack
    app.build_middleware_stack = lambda: RequestId(SecurityHeaders(build(), docs))  # type: ignore[method-assign]


app = create_app()
