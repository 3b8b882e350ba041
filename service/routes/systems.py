"""``GET /v1/systems``: the catalog of systems."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from nonholonomic.catalog import catalog, describe
from nonholonomic.systems import SYSTEMS
from schemas.problems import NOT_FOUND
from service.errors import ProblemError

router = APIRouter(prefix="/v1/systems", tags=["systems"])


@router.get("", summary="The catalog: kinds, parameters, state, potentials, integrals, checks")
def list_systems() -> dict[str, Any]:
    return catalog()


@router.get("/{kind}", summary="One kind of the catalog")
def get_system(kind: str) -> dict[str, Any]:
    if kind not in SYSTEMS:
        raise ProblemError(404, "Unknown system kind", f"no system kind {kind!r}; known: {sorted(SYSTEMS)}", NOT_FOUND)
    return describe(kind)
