"""RFC 9457 problem+json for every error: validation (422), unknown job (404), conflicts (409) ..."""

from __future__ import annotations

import difflib
import json
import logging
import re
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import redis
from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from kombu.exceptions import OperationalError
from sqlalchemy.exc import OperationalError as DatabaseUnavailable
from starlette.exceptions import HTTPException as StarletteHTTPException

from nonholonomic.refusals import RefusedField
from schemas.problems import INTERNAL, INVALID_REQUEST, PROBLEM_MEDIA_TYPE, UNAVAILABLE, FieldError, Problem

log = logging.getLogger(__name__)

#: Descriptions shared by many routes (``problem_responses({422: INVALID, 503: UNAVAILABLE_BACKEND})``).
INVALID = "invalid request (nothing is done); `errors` names each offending field"
UNAVAILABLE_BACKEND = "queue mode: the job store or broker cannot be reached; retry later"
#: The schema every problem response declares (``Problem`` is put in the components by service.openapi).
PROBLEM_SCHEMA_REF = "#/components/schemas/Problem"
#: FastAPI's 400 for a JSON body it cannot read at all (not UTF-8): answered as the 422 of any bad JSON body.
_BODY_NOT_PARSED = "There was an error parsing the body"
#: Media types whose bodies are not text: declared as binary strings.
_BINARY_MEDIA_TYPES = ("application/octet-stream", "image/png")


def problem_responses(described: Mapping[int, str]) -> dict[int | str, dict[str, Any]]:
    """The ``responses=`` of a route for the problems it answers: each status with its description and
    an ``application/problem+json`` body of the ``Problem`` schema.

    >>> problem_responses({404: "unknown job id"})[404]["content"]
    {'application/problem+json': {'schema': {'$ref': '#/components/schemas/Problem'}}}
    """
    return {status: {"description": text, "content": {PROBLEM_MEDIA_TYPE: {"schema": {"$ref": PROBLEM_SCHEMA_REF}}}}
            for status, text in described.items()}


def media_responses(media_types: Iterable[str], description: str, status: int = 200) -> dict[int | str, dict[str, Any]]:
    """The ``responses=`` entry of a route answering non-JSON bodies (CSV, NPZ, PNG, SVG, HTML): one
    string schema per media type, binary where the body is not text. Give the route
    ``response_class=Response`` (unless it also answers JSON) so FastAPI adds no ``application/json``."""
    content = {media_type: {"schema": {"type": "string", **({"format": "binary"} if media_type in _BINARY_MEDIA_TYPES
                                                            else {})}}
               for media_type in media_types}
    return {status: {"description": description, "content": content}}


class ProblemError(Exception):
    """Raise to answer with a problem (any status)."""

    def __init__(self, status: int, title: str, detail: str, type_: str = "about:blank",
                 errors: Sequence[FieldError] = (), headers: Mapping[str, str] | None = None) -> None:
        super().__init__(detail)
        self.problem = Problem(type=type_, title=title, status=status, detail=detail, errors=list(errors))
        self.headers = dict(headers or {})


def invalid_request(errors: Sequence[FieldError]) -> ProblemError:
    """A 422 naming every offending field."""
    detail = "; ".join(f"{e.field}: {e.reason}" for e in errors)
    return ProblemError(422, "Invalid request", detail, INVALID_REQUEST, errors)


def field_path(loc: Sequence[Any], body: Any) -> str:
    """Dotted path of a pydantic error location in the request body.

    pydantic puts the tag of a discriminated union in the location (``system.chaplygin_ball.D``);
    walking the actual input drops such segments, giving ``system.D``.
    """
    parts: list[str] = []
    node = body
    for item in loc[1:] if loc and loc[0] == "body" else loc:
        if isinstance(item, int):
            parts.append(f"[{item}]")
            node = node[item] if isinstance(node, list) and -len(node) <= item < len(node) else None
            continue
        if isinstance(node, dict) and item not in node and node.get("kind") == item:
            continue  # a union tag, not a key
        parts.append(f".{item}" if parts else str(item))
        node = node.get(item) if isinstance(node, dict) else None
    return "".join(parts) or "body"


class ProblemResponse(JSONResponse):
    """``application/problem+json`` as ASCII JSON: a problem may quote the offending input, and a lone
    surrogate (``"\\ud800"`` as a key) cannot be encoded as UTF-8 but can be escaped."""

    media_type = PROBLEM_MEDIA_TYPE

    def render(self, content: Any) -> bytes:
        return json.dumps(content, ensure_ascii=True, allow_nan=False, separators=(",", ":")).encode("ascii")


def _respond(problem: Problem, request: Request, headers: Mapping[str, str] | None = None) -> JSONResponse:
    problem.instance = problem.instance or request.url.path
    return ProblemResponse(problem.model_dump(exclude_none=True), status_code=problem.status, headers=headers)


def _allowed_methods(request: Request) -> list[str]:
    """Every method some route answers on this path (for a 405's ``Allow``): the routes are asked as
    if the request had each method."""
    from starlette.routing import Match

    routes = request.app.router.routes
    return [method for method in ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE")
            if any(route.matches({**request.scope, "method": method})[0] == Match.FULL for route in routes)]


def did_you_mean(given: str, known: Sequence[str]) -> str:
    """``"; did you mean 'x'?"`` for the known name closest to a misspelled ``given`` (difflib's ratio
    at least 0.6), else ``""``."""
    close = difflib.get_close_matches(given, list(known), n=1, cutoff=0.6) if given else []
    return f"; did you mean {close[0]!r}?" if close else ""


def install_error_handlers(app: FastAPI) -> None:
    """Answer every error as ``application/problem+json`` (and say so in the OpenAPI document)."""
    from service.openapi import install_openapi

    install_openapi(app)

    @app.exception_handler(ProblemError)
    async def _problem(request: Request, exc: ProblemError) -> JSONResponse:
        return _respond(exc.problem.model_copy(), request, exc.headers)

    @app.exception_handler(RefusedField)
    async def _refused(request: Request, exc: RefusedField) -> JSONResponse:
        """Every refusal of the core, of any layer, as one 422 naming each field."""
        fields = [FieldError(field=field, reason=reason) for field, reason in exc.problems()]
        return _respond(invalid_request(fields).problem, request)

    @app.exception_handler(RequestValidationError)
    async def _validation(request: Request, exc: RequestValidationError) -> JSONResponse:
        body = exc.body
        errors = []
        for err in exc.errors():
            if err["type"] == "json_invalid":  # loc is ("body", character position)
                position = err["loc"][-1]
                errors.append(FieldError(field="body", reason=f"body is not valid JSON at character {position}: "
                                                               f"{err.get('ctx', {}).get('error', err['msg'])}"))
                continue
            path = field_path(err["loc"], body)
            reason = err["msg"]
            if err["type"] in ("union_tag_invalid", "union_tag_not_found"):
                path += ".kind"  # the discriminator itself is the offending field
                ctx = err.get("ctx") or {}
                expected = re.findall(r"'([^']*)'", str(ctx.get("expected_tags", "")))
                reason += did_you_mean(str(ctx.get("tag", "")), expected)
            errors.append(FieldError(field=path, reason=reason))
        return _respond(invalid_request(errors).problem, request)

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        if exc.status_code == 400 and exc.detail == _BODY_NOT_PARSED:  # e.g. bytes that are not UTF-8
            cause = exc.__cause__
            reason = "body is not valid JSON" + (f": {cause}" if cause is not None else "")
            return _respond(invalid_request([FieldError(field="body", reason=reason)]).problem, request)
        title = {404: "Not Found", 405: "Method Not Allowed"}.get(exc.status_code, "HTTP error")
        headers = dict(exc.headers or {})
        if exc.status_code == 405:  # Starlette names the first matching route's methods only
            headers["Allow"] = ", ".join(_allowed_methods(request))
        return _respond(Problem(title=title, status=exc.status_code, detail=str(exc.detail)), request, headers)

    @app.exception_handler(redis.RedisError)
    @app.exception_handler(OperationalError)
    @app.exception_handler(DatabaseUnavailable)
    async def _unavailable(request: Request, exc: Exception) -> JSONResponse:
        log.warning("job store or broker unavailable: %s", str(exc).splitlines()[0] if str(exc) else exc)
        return _respond(Problem(type=UNAVAILABLE, title="Service unavailable", status=503,
                                detail=f"the job store or broker cannot be reached ({type(exc).__name__}); "
                                       "retry later"),
                        request)

    @app.exception_handler(OverflowError)
    @app.exception_handler(MemoryError)
    @app.exception_handler(FloatingPointError)
    async def _numeric(request: Request, exc: Exception) -> JSONResponse:
        """The safety net of issue 34, item 2: the numbers of a request (its expressions' values) that leave
        the floating-point range or the memory where no route named the field more precisely."""
        log.warning("numeric failure on %s: %s: %s", request.url.path, type(exc).__name__, exc)
        return _respond(invalid_request([FieldError(field="body", reason=(
            f"evaluating the request's expressions or numbers left the floating-point range or the memory "
            f"({type(exc).__name__}): values that grow too fast (a tower of exponentials, say) or constants too "
            "large or too small"))]).problem, request)

    @app.exception_handler(Exception)
    async def _internal(request: Request, exc: Exception) -> JSONResponse:
        log.exception("unhandled error on %s", request.url.path)
        return _respond(Problem(type=INTERNAL, title="Internal error", status=500,
                                detail=f"{type(exc).__name__}: the server failed; this is a bug"), request)
