"""``GET /v1/maps`` and ``POST /v1/maps/{name}``: the paper's isomorphisms applied to given states."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

from fastapi import APIRouter

from nonholonomic.isomorphisms import MAPS, describe, get_map, map_states
from schemas.maps import MapList, MapRequest, MapResult
from schemas.problems import NOT_FOUND, FieldError
from service.errors import ProblemError, invalid_request, problem_responses
from service.openapi import operation_id

router = APIRouter(prefix="/v1/maps", tags=["maps"], generate_unique_id_function=operation_id)


@router.get("", operation_id="maps-list", response_model=MapList, response_model_exclude_unset=True,
            summary="The isomorphisms: source, target, time substitution, level set, corrections")
def list_maps() -> dict[str, Any]:
    return {"maps": [describe(get_map(name, (entry.potentials or ("zero",))[0])) | {
        "source_potentials": list(entry.potentials) if entry.potentials else "all of the source's"}
        for name, entry in MAPS.items()]}


@router.post("/{name}", operation_id="maps-apply", response_model=MapResult, response_model_exclude_unset=True,
             responses=problem_responses({404: "unknown map name",
                                          422: "invalid request, a source kind or potential the map does not take, "
                                               "or a state off the map's level set; `errors` names each field"}),
             summary="Map states through an isomorphism (synchronous)")
def apply_map(name: str, request: MapRequest) -> dict[str, Any]:
    if name not in MAPS:
        raise ProblemError(404, "Unknown map", f"no map {name!r}; known: {', '.join(MAPS)}", NOT_FOUND)
    kind: str = request.system.kind  # type: ignore[attr-defined]  # create_model's field
    if kind != MAPS[name].source:
        raise invalid_request([FieldError(field="system.kind", reason=(
            f"{name} maps from {MAPS[name].source}, not {kind}"))])
    potential: str = request.system.potential.kind  # type: ignore[attr-defined]  # create_model's field
    try:
        m = get_map(name, potential)
    except KeyError as exc:
        raise invalid_request([FieldError(field="system.potential.kind", reason=str(exc.args[0]))]) from None
    out = map_states(m, request.system.parameter_values(),  # refused states: a 422 (service.errors)
                     request.states,  # type: ignore[arg-type]  # nonholonomic.isomorphisms's annotation: not Mapping
                     inverse=request.inverse, project=request.project)
    infinite = list(_non_finite(out))
    if infinite:  # e.g. Theorem 3 with D = 0: alpha = -beta = det J / D
        raise invalid_request([FieldError(field="system", reason=(
            f"{name} gives non-finite values for these parameters ({', '.join(infinite[:6])}): the map is "
            "singular there (e.g. alpha = det J / D at D = 0) or its evaluation overflows"))])
    return out


def _non_finite(value: Any, path: str = "") -> Iterator[str]:
    """Paths of the non-finite numbers in a map's answer (JSON has none)."""
    if isinstance(value, float) and not math.isfinite(value):
        yield path
    elif isinstance(value, dict):
        for key, item in value.items():
            yield from _non_finite(item, f"{path}.{key}" if path else str(key))
    elif isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            yield from _non_finite(item, f"{path}[{i}]")
