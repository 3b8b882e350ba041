"""``GET /v1/systems``: the catalog of systems."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from nonholonomic.catalog import catalog, describe
from nonholonomic.systems import KINDS, SYSTEMS
from schemas.catalog import Catalog, CatalogGeneralizedChaplygin, CatalogLagrangian, SystemDescription
from schemas.problems import NOT_FOUND
from service.errors import ProblemError, did_you_mean, problem_responses
from service.explore import explorable
from service.openapi import operation_id

router = APIRouter(prefix="/v1/systems", tags=["systems"], generate_unique_id_function=operation_id)


@router.get("", operation_id="systems-list", response_model=Catalog, response_model_exclude_unset=True,
            summary="The catalog: kinds, parameters, state, potentials, integrals, checks")
def list_systems() -> dict[str, Any]:
    whole = catalog()
    return {**whole, "systems": [_linked(entry) for entry in whole["systems"]]}


def _linked(entry: dict[str, Any]) -> dict[str, Any]:
    """A kind's entry with, for each potential the explorer can draw, the link to its page (``/explore``)."""
    drawable = explorable().get(entry["kind"], [])
    return {**entry, "potentials": [{**pot, "explore": f"/explore?kind={entry['kind']}&potential={pot['kind']}"}
                                    if pot["kind"] in drawable else pot for pot in entry["potentials"]]}


@router.get("/{kind}", operation_id="systems-get",
            # CatalogLagrangian before CatalogGeneralizedChaplygin: a generated client tries the union in order, and the
            # Lagrangian entry holds every field the other requires (not the other way round)
            response_model=SystemDescription | CatalogLagrangian | CatalogGeneralizedChaplygin,
            response_model_exclude_unset=True, responses=problem_responses({404: "unknown system kind"}),
            summary="One kind of the catalog (generalized_chaplygin, lagrangian: how to pose a system of one's own)")
def get_system(kind: str) -> dict[str, Any]:
    """A catalog kind as a ``SystemDescription``; a kind written by the user (``generalized_chaplygin``,
    ``lagrangian``: systems the request writes itself) as the catalog's entry of that name, a
    ``CatalogGeneralizedChaplygin`` and a ``CatalogLagrangian``."""
    if kind in SYSTEMS:
        return _linked(describe(kind))
    entry = KINDS[kind].catalog_entry if kind in KINDS else None
    if entry is not None:  # a kind written by the user: its own entry, not the whole catalog built for it
        return entry()
    raise ProblemError(404, "Unknown system kind",
                       f"no system kind {kind!r}{did_you_mean(kind, list(KINDS))}; known: {sorted(KINDS)}", NOT_FOUND)
