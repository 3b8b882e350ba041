"""``/v1/ensembles``: many orbits of one system, fanned out to the workers in chunks."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter, Query, Request, Response
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool

from schemas.ensembles import (
    EnsembleAccepted,
    EnsembleList,
    EnsembleListItem,
    EnsembleRequest,
    EnsembleView,
    MembersPage,
)
from schemas.job_list import DEFAULT_LIMIT, MAX_LIMIT, STATUSES
from schemas.problems import CONFLICT, FieldError
from service import metrics
from service.access import ensemble_of
from service.admission import admit_ensemble
from service.backends.base import InvalidCursor, decode_cursor, encode_cursor
from service.deps import AppSettings, Backend, Owner
from service.ensembles import (
    all_members,
    list_item,
    members_page,
    request_units,
    section_csv,
    section_members,
    section_netcdf,
    section_npz,
    view,
)
from service.errors import (
    INVALID,
    UNAVAILABLE_BACKEND,
    ProblemError,
    invalid_request,
    problem_responses,
)
from service.exports import MEDIA_TYPES, SUFFIXES, download, download_responses, json_download, vector_components
from service.idempotency import IDEMPOTENCY_IN_PROGRESS, IDEMPOTENCY_MISMATCH, QUEUE_BOUNDS, idempotent
from service.members_table import members_csv, members_netcdf
from service.openapi import operation_id
from service.validation import POOL_FULL, validated
from store.idempotency import KeyBinding

#: Operation ids are explicit, ``ensembles-<verb>``; a route without one gets ``ensembles-<its name>``.
router = APIRouter(prefix="/v1/ensembles", tags=["ensembles"], generate_unique_id_function=operation_id)
#: The problems of a route that reads one ensemble.
_ERRORS: dict[int | str, dict[str, Any]] = problem_responses({404: "unknown ensemble id", 503: UNAVAILABLE_BACKEND})
#: Most members one page returns.
MAX_PAGE = 1000


@router.post("", status_code=202, operation_id="ensembles-submit", response_model=EnsembleAccepted,
             responses=problem_responses({409: IDEMPOTENCY_IN_PROGRESS, 422: INVALID + IDEMPOTENCY_MISMATCH,
                                          429: QUEUE_BOUNDS, 503: UNAVAILABLE_BACKEND + POOL_FULL}),
             summary="Submit an ensemble (members from a list, a level set or a parameter sweep)")
async def submit_ensemble(body: EnsembleRequest, request: Request, backend: Backend, owner: Owner,
                          settings: AppSettings) -> JSONResponse:
    """Every member is validated before anything is queued (expressions by deterministic size measures, then
    read off the event loop); then the chunks go to the workers."""
    chunks = await validated(request, "ensemble", body)
    assert chunks is not None
    if body.members.grid is not None and body.members.grid.ranges is None:  # resolved once, kept with the request
        body.members.grid.ranges = [list(r) for r in await run_in_threadpool(body.grid_ranges)]
    spec = body.model_dump(mode="json")

    def create(binding: KeyBinding | None) -> str:
        return admit_ensemble(backend, owner, settings, spec, chunks, binding)

    def respond(ensemble_id: str) -> tuple[dict[str, Any], dict[str, str]]:
        location = f"/v1/ensembles/{ensemble_id}"
        accepted = EnsembleAccepted(id=ensemble_id, status="queued", location=location, members=body.members.count,
                                    chunks=len(chunks), deprecations=body.deprecations())
        return accepted.model_dump(), {"Location": location}

    return await run_in_threadpool(idempotent, request, owner, spec, create, respond)


@router.get("", operation_id="ensembles-list", response_model=EnsembleList,
            responses=problem_responses({422: "invalid `status`, `limit` or `cursor`; `errors` names the field",
                                         503: UNAVAILABLE_BACKEND}),
            summary="List ensembles, newest first (no requests, no summaries; page with next_cursor)")
def list_ensembles(backend: Backend, owner: Owner,
                   status: str | None = Query(None, description=f"only ensembles with this status: "
                                                                f"{', '.join(STATUSES)}",
                                              json_schema_extra={"enum": list(STATUSES)}),
                   limit: int = Query(DEFAULT_LIMIT, ge=1, le=MAX_LIMIT, description="ensembles read for the page"),
                   cursor: str | None = Query(None, description="a previous page's next_cursor, as it is"),
                   ) -> EnsembleList:
    """Every ensemble the caller may see (with API keys: the key's own), newest first: id, status,
    progress, created_at, kind, members, what varies across them (``label``), location. An ensemble is
    also found by the first characters of its id: ``GET /v1/ensembles/168413ee``."""
    if status is not None and status not in STATUSES:
        raise invalid_request([FieldError(field="status", reason=f"{status!r} is not an ensemble status; one of "
                                                                 f"{', '.join(STATUSES)}")])
    try:
        after = decode_cursor(cursor) if cursor is not None else None
    except InvalidCursor as exc:
        raise invalid_request([FieldError(field="cursor", reason=str(exc))]) from None
    records, more = backend.ensembles.page(limit, after, owner)
    items = [list_item(r) for r in records]
    next_cursor = encode_cursor(records[-1]["created"], records[-1]["id"]) if more else None
    return EnsembleList(items=[EnsembleListItem(**i) for i in items if status is None or i["status"] == status],
                        next_cursor=next_cursor)


@router.get("/{ensemble_id}", operation_id="ensembles-get", response_model=EnsembleView, responses=_ERRORS,
            summary="Status, progress (members done / total) and summary of an ensemble")
def get_ensemble(ensemble_id: str, backend: Backend, owner: Owner) -> JSONResponse:
    record = ensemble_of(backend, owner, ensemble_id)  # by its id, or the first characters of it
    return JSONResponse(view(record["id"], record))


@router.get("/{ensemble_id}/members", operation_id="ensembles-members", response_model=MembersPage,
            responses={**_ERRORS,  # JSON (the model) first: a generated client reads pages; CSV with format=csv
                       200: {"description": "a page of members (JSON), or every member done as one table (format=csv "
                                            "or netcdf)",
                             "content": {MEDIA_TYPES["csv"]: {"schema": {"type": "string"}},
                                         MEDIA_TYPES["netcdf"]: {"schema": {"type": "string", "format": "binary"}}}},
                       **problem_responses({422: f"offset < 0, limit outside 1 .. {MAX_PAGE}, or an unknown format"})},
            summary="A page of member results (JSON), or every member as a table (CSV or NetCDF)")
def get_members(ensemble_id: str, request: Request, backend: Backend, owner: Owner, offset: int = Query(0, ge=0),
                limit: int = Query(100, ge=1, le=MAX_PAGE),
                format: Literal["json", "csv", "netcdf"] = Query(  # noqa: A002
                    "json", description="json: members offset .. offset + limit - 1; csv: every member done, one row "
                                        "each, with what sets it apart (a sweep's value named after its parameter, a "
                                        "map cell's indices and coordinates); netcdf: the same table, dimension "
                                        "member, each column a variable with its units")) -> Response:
    """Members ``offset .. offset + limit - 1`` that are done, each with its index, label, status and
    the same result fields as a job; or (``format=csv``, ``format=netcdf``) every member done as one table
    (:mod:`service.members_table`)."""
    record = ensemble_of(backend, owner, ensemble_id)
    ensemble_id = record["id"]  # the whole id, also when the path gave its first characters
    components = vector_components(record["request"]["system"])
    if format == "csv":
        rows = members_csv(all_members(backend.ensembles, ensemble_id, record), components,
                           request_units(record["request"]))
        return download(request, rows, MEDIA_TYPES["csv"], f"ensemble-{ensemble_id}-members.csv")
    if format == "netcdf":
        data = members_netcdf(ensemble_id, record, all_members(backend.ensembles, ensemble_id, record), components,
                              request_units(record["request"]))
        return download(request, data, MEDIA_TYPES["netcdf"], f"ensemble-{ensemble_id}-members.nc")
    page = members_page(backend.ensembles, ensemble_id, record, offset, limit)
    total = sum(stop - start for start, stop in record["chunks"])
    return JSONResponse({"offset": offset, "limit": limit, "total": total, "components": components, "members": page})


@router.get("/{ensemble_id}/poincare", operation_id="ensembles-section", response_class=Response,
            responses={**download_responses(MEDIA_TYPES.values(), "every member's crossings: CSV (format=csv), NPZ "
                                                                  "(format=npz) or NetCDF-4 (format=netcdf)"),
                       **_ERRORS, **problem_responses({409: "the ensemble asked for no section",
                                                       422: "unknown format"})},
            summary="Every member's Poincare crossings, with the member index (CSV, NPZ or NetCDF)")
def get_section(ensemble_id: str, request: Request, backend: Backend, owner: Owner,
                format: Literal["csv", "npz", "netcdf"] = Query(  # noqa: A002
                    "csv", description="csv (member, then t, tau and every component, a header with units), npz "
                                       "or netcdf (dimension crossing; coordinates member, t, tau)")) -> Response:
    """The members done so far, in index order, each member's crossings in time order."""
    record = ensemble_of(backend, owner, ensemble_id)
    ensemble_id = record["id"]  # the whole id, also when the path gave its first characters
    if not record["request"].get("poincare"):
        raise ProblemError(409, "No section", "this ensemble did not ask for a poincare section", CONFLICT)
    store = backend.ensembles
    filename = f"ensemble-{ensemble_id}-poincare.{SUFFIXES[format]}"  # the id as a safe name
    if format == "csv":
        return download(request, section_csv(store, ensemble_id, record), MEDIA_TYPES[format], filename)
    if format == "npz":
        return download(request, section_npz(store, ensemble_id, record), MEDIA_TYPES[format], filename)
    return download(request, section_netcdf(store, ensemble_id, record), MEDIA_TYPES[format], filename)


@router.get("/{ensemble_id}/orbit-diagram", operation_id="ensembles-orbit-diagram", response_class=Response,
            responses={**download_responses([MEDIA_TYPES["csv"], "application/json"],
                                            "the orbit diagram: CSV (format=csv) or JSON (format=json)"),
                       **_ERRORS, **problem_responses({409: "the ensemble is not a sweep with a poincare section",
                                                       422: "unknown format"})},
            summary="A sweep's orbit diagram: every member's section points against the swept value (CSV or JSON)")
def get_orbit_diagram(ensemble_id: str, request: Request, backend: Backend, owner: Owner,
                      format: Literal["csv", "json"] = Query(  # noqa: A002
                          "csv", description="csv (one row per crossing: member, the swept value with its unit, "
                                             "crossing, the section's two coordinates) or json (one array per "
                                             "column)")) -> Response:
    """The members done so far, in index order, each member's crossings in time order."""
    from service.orbit_diagram import NoOrbitDiagram, diagram_csv, diagram_json, sweep_of

    record = ensemble_of(backend, owner, ensemble_id)
    ensemble_id = record["id"]
    try:
        sweep_of(record["request"])
    except NoOrbitDiagram as exc:
        raise ProblemError(409, "No orbit diagram", str(exc), CONFLICT) from None
    units = request_units(record["request"])
    members = section_members(backend.ensembles, ensemble_id, record)
    filename = f"ensemble-{ensemble_id}-orbit-diagram.{'csv' if format == 'csv' else 'json'}"
    if format == "csv":
        return download(request, diagram_csv(record["request"], members, units), MEDIA_TYPES["csv"], filename)
    return json_download(request, diagram_json(record["request"], members, units), filename)


@router.get("/{ensemble_id}/map", operation_id="ensembles-map", response_class=Response,
            responses={**download_responses([MEDIA_TYPES["csv"], "application/json", MEDIA_TYPES["netcdf"]],
                                            "the chaos map: CSV (format=csv), JSON (format=json) or NetCDF-4 "
                                            "(format=netcdf)"),
                       **_ERRORS, **problem_responses({409: "the ensemble is not a chaos map", 422: "unknown format"})},
            summary="A chaos map's cells: status, indicators and integral drift on the grid (CSV, JSON or NetCDF)")
def get_map(ensemble_id: str, request: Request, backend: Backend, owner: Owner,
            format: Literal["csv", "json", "netcdf"] = Query(  # noqa: A002
                "csv", description="csv (one row per cell: i, j, the coordinates, status, branches, each indicator, "
                                   "each integral's drift; a header with units), json (2-D arrays [i][j]) or netcdf "
                                   "(dimensions the two coordinates)")) -> Response:
    """Cells of unfinished chunks are ``outside`` with empty values until their chunk is done."""
    from service.map_exports import map_csv, map_json, map_netcdf

    record = ensemble_of(backend, owner, ensemble_id)
    ensemble_id = record["id"]  # the whole id, also when the path gave its first characters
    if not record["request"].get("indicators"):
        raise ProblemError(409, "Not a map", "this ensemble is not a chaos map (no members.grid and indicators)",
                           CONFLICT)
    store = backend.ensembles
    members = all_members(store, ensemble_id, record)
    filename = f"ensemble-{ensemble_id}-map.{SUFFIXES[format]}"
    if format == "csv":
        return download(request, map_csv(record, members), MEDIA_TYPES["csv"], filename)
    summary = view(ensemble_id, record)["summary"]
    if format == "json":
        return JSONResponse(map_json(record, members, summary))
    return download(request, map_netcdf(ensemble_id, record, members, summary), MEDIA_TYPES["netcdf"], filename)


@router.delete("/{ensemble_id}", status_code=202, operation_id="ensembles-cancel", response_model=EnsembleView,
               responses={**_ERRORS, **problem_responses({409: "the ensemble already finished"})},
               summary="Cancel every chunk of an ensemble")
def cancel_ensemble(ensemble_id: str, backend: Backend, owner: Owner) -> JSONResponse:
    record = ensemble_of(backend, owner, ensemble_id)
    ensemble_id = record["id"]  # the whole id, also when the path gave its first characters
    before = view(ensemble_id, record)
    if before["status"] in ("succeeded", "failed"):
        raise ProblemError(409, "Ensemble already finished", f"ensemble {ensemble_id} already {before['status']}",
                           CONFLICT)
    backend.cancel_ensemble(ensemble_id)
    metrics.ENSEMBLES_CANCELLED.inc()
    return JSONResponse(view(ensemble_id, ensemble_of(backend, owner, ensemble_id)), status_code=202)
