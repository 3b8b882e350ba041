"""``GET /v1/maps`` and ``POST /v1/maps/{name}``: the paper's isomorphisms applied to given states."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from nonholonomic.isomorphisms import MAPS, SOURCE_KINDS, MapInputError, describe, get_map, map_states
from schemas.maps import MapRequest
from schemas.problems import NOT_FOUND, FieldError
from service.errors import ProblemError, invalid_request

router = APIRouter(prefix="/v1/maps", tags=["maps"])


@router.get("", summary="The isomorphisms: source, target, time substitution, level set, corrections")
def list_maps() -> dict[str, Any]:
    return {"maps": [describe(get_map(name, (MAPS[name][1] or ("zero",))[0])) | {
        "source_potentials": list(MAPS[name][1]) if MAPS[name][1] else "all of the source's"} for name in MAPS]}


@router.post("/{name}", summary="Map states through an isomorphism (synchronous)")
def apply_map(name: str, request: MapRequest) -> dict[str, Any]:
    if name not in MAPS:
        raise ProblemError(404, "Unknown map", f"no map {name!r}; known: {', '.join(MAPS)}", NOT_FOUND)
    if request.system.kind != SOURCE_KINDS[name]:  # type: ignore[attr-defined]
        raise invalid_request([FieldError(field="system.kind", reason=(
            f"{name} maps from {SOURCE_KINDS[name]}, not {request.system.kind}"))])  # type: ignore[attr-defined]
    potential = request.system.potential.kind  # type: ignore[attr-defined]
    try:
        m = get_map(name, potential)
    except KeyError as exc:
        raise invalid_request([FieldError(field="system.potential.kind", reason=str(exc.args[0]))]) from None
    try:
        return map_states(m, request.system.parameter_values(), request.states,
                          inverse=request.inverse, project=request.project)
    except MapInputError as exc:
        raise invalid_request([FieldError(field=f, reason=r) for f, r in exc.problems]) from None
