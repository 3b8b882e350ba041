"""The OpenAPI document as the service really answers.

FastAPI documents a 422 ``HTTPValidationError`` as ``application/json`` on every route with
parameters; this service answers every error as ``application/problem+json`` (:mod:`service.errors`).
:func:`finalize` rewrites the generated document once per route set:

- FastAPI's default 422 becomes the ``Problem`` 422 where validation can fail (a body, a query,
  header or cookie parameter, a constrained path parameter) and is dropped where it cannot (only
  plain string path parameters: ``GET /v1/systems/{kind}`` answers 404 for an unknown kind);
- an error response declared with ``model=Problem`` (FastAPI puts it under ``application/json``)
  moves to ``application/problem+json``;
- ``Problem`` and ``FieldError`` are in the components, ``HTTPValidationError`` and
  ``ValidationError`` are not;
- every operation with a request body declares the 413 of :class:`service.limits.BodyLimit`;
- a success that may be bytes (a download, :func:`service.exports.download_responses`) lists
  ``application/octet-stream`` first, before the JSON model FastAPI puts there: a client generated from
  the document (openapi-python-client takes the first media type it knows) reads every format as bytes.

:func:`state_limits` then writes this deployment's limits (:class:`schemas.settings.Settings`:
``max_t_final``, ``max_samples`` ...) into the request schemas as ``maximum`` / ``maxItems``, so that
a body the document calls valid is not refused for a limit it did not state.

Operation ids are explicit on every route (``operation_id="<tag>-<verb>"``, e.g. ``jobs-submit``);
:func:`operation_id` is a fallback of the same shape for a route that forgets it.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

from fastapi import FastAPI
from fastapi.routing import APIRoute
from pydantic.json_schema import models_json_schema

from schemas.problems import PROBLEM_MEDIA_TYPE, FieldError, Problem
from schemas.settings import Settings

REF_PREFIX = "#/components/schemas/"
_FASTAPI_VALIDATION = REF_PREFIX + "HTTPValidationError"
_PROBLEM = REF_PREFIX + "Problem"
_BINARY = "application/octet-stream"
#: Keys of a path parameter's schema that let a value fail validation.
_CONSTRAINTS = frozenset({"enum", "const", "pattern", "minLength", "maxLength", "format", "anyOf", "oneOf", "allOf",
                          "$ref", "minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"})
#: The shape every operation id has: lower-case words joined by '-', the first the route's tag.
OPERATION_ID = re.compile(r"^[a-z]+(-[a-z]+)+$")


def operation_id(route: APIRoute) -> str:
    """``<tag>-<name>`` from the route's first tag (its first word) and its name (``_`` → ``-``).

    Only for routes without an explicit ``operation_id`` (FastAPI's ``generate_unique_id_function``).
    """
    tag = str(route.tags[0]).split()[0].lower() if route.tags else "api"
    words = [w for w in re.split(r"[^a-z]+", route.name.lower()) if w and w != tag]
    return "-".join([tag, *(words or [next(iter(sorted(route.methods or {"get"}))).lower()])])


#: The 413 every operation with a body may answer (:class:`service.limits.BodyLimit`).
TOO_LARGE_DESCRIPTION = "the request body is larger than this service accepts (NONHOLONOMIC_MAX_BODY_BYTES)"
#: Where each limit of the settings applies: (schema, property) -> (setting, JSON Schema keyword).
SETTING_LIMITS: dict[tuple[str, str], tuple[str, str]] = {
    ("JobRequest", "t_final"): ("max_t_final", "maximum"),
    ("JobRequest", "samples"): ("max_samples", "maximum"),
    ("EnsembleRequest", "t_final"): ("max_t_final", "maximum"),
    ("EnsembleRequest", "samples"): ("max_samples", "maximum"),
    ("PoincareRequest", "max_points"): ("max_section_points", "maximum"),
    ("SampleMembers", "count"): ("max_ensemble_members", "maximum"),
    ("SweepMembers", "values"): ("max_ensemble_members", "maxItems"),
    ("MembersSpec", "initial_states"): ("max_ensemble_members", "maxItems"),
}


def _can_fail_validation(operation: dict[str, Any]) -> bool:
    if "requestBody" in operation:
        return True
    for parameter in operation.get("parameters", []):
        schema = parameter.get("schema", {})
        if parameter.get("in") != "path" or schema.get("type") != "string" or _CONSTRAINTS & set(schema):
            return True
    return False


def _problem_content() -> dict[str, Any]:
    return {PROBLEM_MEDIA_TYPE: {"schema": {"$ref": _PROBLEM}}}


def finalize(document: dict[str, Any]) -> dict[str, Any]:
    """Rewrite ``document`` in place (idempotent) as described in the module docstring; returns it."""
    for item in document.get("paths", {}).values():
        for operation in item.values():
            if not isinstance(operation, dict) or "responses" not in operation:
                continue
            responses = operation["responses"]
            for status, response in list(responses.items()):
                content = response.get("content", {})
                if str(status).startswith("2") and _BINARY in content and next(iter(content)) != _BINARY:
                    response["content"] = content = {_BINARY: content[_BINARY],
                                                     **{k: v for k, v in content.items() if k != _BINARY}}
                schema = content.get("application/json", {}).get("schema", {})
                if schema.get("$ref") == _FASTAPI_VALIDATION:
                    if _can_fail_validation(operation):
                        responses[status] = {"description": "invalid request; `errors` names each offending field",
                                             "content": _problem_content()}
                    else:
                        del responses[status]
                elif schema.get("$ref") == _PROBLEM and not str(status).startswith("2"):
                    content[PROBLEM_MEDIA_TYPE] = content.pop("application/json")
            if "requestBody" in operation:
                responses.setdefault("413", {"description": TOO_LARGE_DESCRIPTION, "content": _problem_content()})
    schemas = document.setdefault("components", {}).setdefault("schemas", {})
    _, definitions = models_json_schema([(Problem, "serialization"), (FieldError, "serialization")],
                                        ref_template=REF_PREFIX + "{model}")
    for name, schema in definitions.get("$defs", {}).items():
        schemas.setdefault(name, schema)
    for name in ("HTTPValidationError", "ValidationError"):  # in this order: the first refers to the second
        others = {key: value for key, value in schemas.items() if key != name}
        if name in schemas and REF_PREFIX + name not in repr((document.get("paths"), others)):
            del schemas[name]
    return document


def state_limits(document: dict[str, Any], settings: Settings) -> dict[str, Any]:
    """Write the limits of ``settings`` into the request schemas of ``document`` (in place, idempotent;
    see :data:`SETTING_LIMITS`); returns it."""
    schemas = document.get("components", {}).get("schemas", {})
    for (name, prop), (setting, keyword) in SETTING_LIMITS.items():
        schema = schemas.get(name, {}).get("properties", {}).get(prop)
        if schema is None:
            continue
        limit = getattr(settings, setting)
        # the non-null branch of an optional field, else the field itself
        for target in [b for b in schema.get("anyOf", []) if b.get("type") != "null"] or [schema]:
            target[keyword] = min(target.get(keyword, limit), limit)
    return document


def install_openapi(app: FastAPI) -> None:
    """Serve the finalized document, with the limits of ``app.state.settings``, at ``/openapi.json``
    (and to ``/docs``)."""
    generate: Callable[[], dict[str, Any]] = app.openapi

    def openapi() -> dict[str, Any]:
        document = finalize(generate())
        settings = getattr(app.state, "settings", None)
        return state_limits(document, settings) if settings is not None else document

    app.openapi = openapi  # type: ignore[method-assign]  # FastAPI's documented way to extend the schema
