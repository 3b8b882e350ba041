"""``/v1/jobs``: submit, poll and cancel simulation jobs."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter, Query, Request, Response
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool

from schemas.analysis import SectionExport
from schemas.branches import OrbitBranchResult
from schemas.job_list import DEFAULT_LIMIT, MAX_LIMIT, STATUSES, JobList, JobListItem, job_kind
from schemas.jobs import JobAccepted, JobRequest, JobView
from schemas.problems import CONFLICT, NOT_FOUND, FieldError
from schemas.results import TrajectoryExport
from service import metrics
from service.access import job_of
from service.admission import admit_job
from service.backends import JobRecord
from service.backends.base import InvalidCursor
from service.branch_table import branch_csv
from service.deps import AppSettings, Backend, Owner
from service.errors import (
    INVALID,
    UNAVAILABLE_BACKEND,
    ProblemError,
    invalid_request,
    problem_responses,
)
from service.exports import (
    MEDIA_TYPES,
    SUFFIXES,
    download,
    download_responses,
    json_download,
    result_components,
    section_csv,
    section_npz,
    trajectory_csv,
    trajectory_npz,
)
from service.idempotency import IDEMPOTENCY_IN_PROGRESS, IDEMPOTENCY_MISMATCH, QUEUE_BOUNDS, idempotent
from service.openapi import operation_id
from service.validation import POOL_FULL, validated
from store.idempotency import KeyBinding

#: Operation ids are explicit, ``jobs-<verb>``; a route without one gets ``jobs-<its name>``.
router = APIRouter(prefix="/v1/jobs", tags=["jobs"], generate_unique_id_function=operation_id)
#: The problems of a route that reads one job.
_ERRORS: dict[int | str, dict[str, Any]] = problem_responses({404: "unknown job id", 503: UNAVAILABLE_BACKEND})


def _view(record: JobRecord, trajectory: bool = True) -> dict[str, Any]:
    """The job as JSON; ``trajectory=False``: the summary view, a simulation's samples left out of
    ``result`` (``result.trajectory_location`` says where they are)."""
    result = record.result
    if not trajectory and isinstance(result, dict) and "trajectory" in result:
        result = {k: v for k, v in result.items() if k != "trajectory"}
        result["trajectory_location"] = f"/v1/jobs/{record.id}/trajectory"
    return {"id": record.id, "status": record.status, "progress": record.progress, "created_at": record.created_at,
            "request": record.request, "result": result, "error": record.error}


@router.post("", status_code=202, operation_id="jobs-submit", response_model=JobAccepted,
             responses=problem_responses({409: IDEMPOTENCY_IN_PROGRESS, 422: INVALID + IDEMPOTENCY_MISMATCH,
                                          429: QUEUE_BOUNDS, 503: UNAVAILABLE_BACKEND + POOL_FULL}),
             summary="Submit a simulation job")
async def submit_job(job: JobRequest, request: Request, backend: Backend, owner: Owner,
                     settings: AppSettings) -> JSONResponse:
    """Validate (shape, ranges, |γ| = 1, state names; expressions by deterministic size measures, then read
    off the event loop) and queue; nothing is queued if invalid. With an ``Idempotency-Key`` a retry answers the
    first response again."""
    await validated(request, "job", job)
    body = job.model_dump(mode="json")

    def create(binding: KeyBinding | None) -> str:
        return admit_job(backend, owner, settings, body, binding).id

    def respond(job_id: str) -> tuple[dict[str, Any], dict[str, str]]:
        location = f"/v1/jobs/{job_id}"
        accepted = JobAccepted(id=job_id, status="queued", location=location, deprecations=job.deprecations())
        return accepted.model_dump(), {"Location": location}

    return await run_in_threadpool(idempotent, request, owner, body, create, respond)


@router.get("/{job_id}", operation_id="jobs-get", response_model=JobView, responses=_ERRORS,
            summary="Status, progress and result of a job")
def get_job(job_id: str, backend: Backend, owner: Owner,
            trajectory: bool = Query(True, description="false: the summary view, without the sampled trajectory "
                                                       "(result.trajectory_location says where it is)"),
            ) -> JSONResponse:
    """The job; a finished simulation's whole result, samples included, unless ``trajectory=false``."""
    return JSONResponse(_view(job_of(backend, owner, job_id), trajectory))


#: The formats of a download (``?format=``): JSON, or a file (:data:`service.exports.MEDIA_TYPES`).
ExportFormat = Literal["json", "csv", "npz", "netcdf"]
_FORMAT = Query("json", description="json (the default), csv (a header row naming each column and its unit), "
                                    "npz (numpy arrays, the request and versions as JSON) or netcdf (NetCDF-4, "
                                    "CF-1.10 names, units and provenance attributes)")
#: The files' media types (the JSON's, with its model, is FastAPI's ``response_model``).
_FILE_TYPES = tuple(MEDIA_TYPES.values())


def _succeeded(backend: Backend, owner: Owner, job_id: str, what: str) -> JobRecord:
    record = job_of(backend, owner, job_id)
    if record.status != "succeeded" or record.result is None:
        raise ProblemError(409, f"No {what} yet", f"job {job_id} is {record.status}; its {what} is there once "
                                                  "it succeeded", CONFLICT)
    if "trajectory" not in record.result:
        raise ProblemError(409, f"No {what}", f"job {job_id} is a paper report, not a simulation", CONFLICT)
    return record


@router.get("/{job_id}/trajectory", operation_id="jobs-trajectory", response_model=TrajectoryExport,
            responses={**download_responses(_FILE_TYPES, "the samples: JSON (format=json, TrajectoryExport), CSV "
                                                         "(format=csv), NPZ (format=npz) or NetCDF-4 (format=netcdf)"),
                       **problem_responses({404: "unknown job id", 409: "the job has not succeeded (yet), or is a "
                                                                        "paper report",
                                            422: "unknown format", 503: UNAVAILABLE_BACKEND})},
            summary="The sampled trajectory as JSON, CSV (a header with units; t and tau first), NPZ or NetCDF")
def get_trajectory(job_id: str, request: Request, backend: Backend, owner: Owner,
                   format: ExportFormat = _FORMAT) -> Response:  # noqa: A002
    """CSV columns: ``t [s]``, ``tau [unit]`` (systems with a reduced time), then every component of every
    state and derived vector, ``M1 [kg m^2/s]`` ... NetCDF: dimension ``t``, coordinates ``t`` and ``tau``,
    one variable per component named as the CSV's columns (``M1`` ...) with ``units`` and ``long_name``."""
    record = _succeeded(backend, owner, job_id, "trajectory")
    job_id = record.id  # the whole id, also when the path gave its first characters
    result = record.result
    assert result is not None
    filename = f"job-{job_id}-trajectory.{SUFFIXES[format]}"  # the id as a safe name
    if format == "csv":
        return download(request, trajectory_csv(result, result_components(result, record.request)),
                        MEDIA_TYPES[format], filename)
    if format == "npz":
        return download(request, trajectory_npz(result, record.request), MEDIA_TYPES[format], filename)
    if format == "netcdf":
        from service.exports_netcdf import trajectory_netcdf

        body = trajectory_netcdf(job_id, record.created_at, result, record.request)
        return download(request, body, MEDIA_TYPES[format], filename)
    return json_download(request, {"units": result["system"]["units"], **result["trajectory"]}, filename)


@router.get("/{job_id}/section", operation_id="jobs-section", response_model=SectionExport,
            responses={**download_responses(_FILE_TYPES, "the crossings: JSON (format=json, SectionExport), CSV "
                                                         "(format=csv), NPZ (format=npz) or NetCDF-4 (format=netcdf)"),
                       **problem_responses({404: "unknown job id", 409: "the job has not succeeded (yet), is a paper "
                                                                        "report or asked for no poincare section",
                                            422: "unknown format", 503: UNAVAILABLE_BACKEND})},
            summary="The job's Poincare crossings as JSON, CSV (one row per crossing: t, tau, every state "
                    "component), NPZ or NetCDF")
def get_section(job_id: str, request: Request, backend: Backend, owner: Owner,
                format: ExportFormat = _FORMAT) -> Response:  # noqa: A002
    """The section a job asked for (``poincare`` in the request), one row per crossing in time order. CSV
    columns as the trajectory's: ``t [s]``, ``tau [unit]``, then every component of every state and derived
    vector at the crossing (``M1 [kg m^2/s]`` ... ``gamma3 [1]`` ... ``omega3 [rad/s]``). NPZ: ``t``, ``tau``,
    each vector ``(count, 3)``, ``coordinates`` ``(count, 2)``, ``units_json``, ``request_json``,
    ``versions_json``, ``section_json``. NetCDF: dimension ``crossing``, coordinates ``t`` and ``tau``."""
    record = _succeeded(backend, owner, job_id, "section")
    job_id = record.id
    result = record.result
    assert result is not None
    if not result.get("poincare"):
        raise ProblemError(409, "No section", f"job {job_id} asked for no poincare section", CONFLICT)
    filename = f"job-{job_id}-section.{SUFFIXES[format]}"
    units = result["system"]["units"]
    if format == "csv":
        names = result_components(result, record.request)
        return download(request, section_csv(result["poincare"], units, names), MEDIA_TYPES[format], filename)
    if format == "npz":
        return download(request, section_npz(result, record.request), MEDIA_TYPES[format], filename)
    if format == "netcdf":
        from service.exports_netcdf import section_netcdf

        body = section_netcdf(job_id, record.created_at, result, record.request)
        return download(request, body, MEDIA_TYPES[format], filename)
    return json_download(request, {"units": units, **result["poincare"]}, filename)


BranchFormat = Literal["json", "csv", "netcdf"]


@router.get("/{job_id}/branch", operation_id="jobs-branch", response_model=OrbitBranchResult,
            responses={**download_responses(_FILE_TYPES, "the branch: JSON (format=json, the result's "
                                                         "periodic_orbit.branch), CSV (format=csv, one row per "
                                                         "point and per bifurcation) or NetCDF-4 (format=netcdf)"),
                       **problem_responses({404: "unknown job id", 409: "the job has not succeeded (yet), or asked "
                                                                        "for no branch (periodic_orbit.branch)",
                                            422: "unknown format", 503: UNAVAILABLE_BACKEND})},
            summary="The job's branch of periodic orbits as JSON, CSV or NetCDF (points and located bifurcations)")
def get_branch(job_id: str, request: Request, backend: Backend, owner: Owner,
               format: BranchFormat = Query("json", description="json, csv or netcdf")) -> Response:  # noqa: A002
    """The branch a job asked for (``periodic_orbit.branch``), with the branches switched onto at its period
    doublings. CSV and NetCDF: one row per point and per located bifurcation (``kind`` says which), columns
    ``branch``, ``period``, ``index``, the continued value named after it with its unit, ``arclength``,
    ``period_t [s]``, ``period_tau``, the section coordinates, ``trace``, ``stability``, the section multipliers,
    ``residual``, ``residual_independent``, ``checks_passed``, ``located``, ``test_function``."""
    record = _succeeded(backend, owner, job_id, "branch")
    job_id = record.id
    result = record.result
    assert result is not None
    branch = (result.get("periodic_orbit") or {}).get("branch")
    if not branch:
        raise ProblemError(409, "No branch", f"job {job_id} asked for no branch (periodic_orbit.branch), or its "
                                             "orbit was not found", CONFLICT)
    filename = f"job-{job_id}-branch.{SUFFIXES[format]}"
    if format == "csv":
        return download(request, branch_csv(result, record.request), MEDIA_TYPES[format], filename)
    if format == "netcdf":
        from service.branch_table import branch_netcdf

        return download(request, branch_netcdf(job_id, record.created_at, result, record.request),
                        MEDIA_TYPES[format], filename)
    return json_download(request, branch, filename)


@router.delete("/{job_id}", status_code=202, operation_id="jobs-cancel", response_model=JobView,
               responses={**_ERRORS, **problem_responses({409: "the job already finished"})},
               summary="Cancel a job (202 with the job's view)")
def cancel_job(job_id: str, backend: Backend, owner: Owner) -> JSONResponse:
    """A queued job never starts; a running one stops at its next progress report (≤ 0.2 s)."""
    before = job_of(backend, owner, job_id)
    job_id = before.id  # the whole id, also when the path gave its first characters
    if before.status in ("succeeded", "failed"):
        raise ProblemError(409, "Job already finished", f"job {job_id} already {before.status}", CONFLICT)
    after = backend.cancel(job_id)
    if after is None:
        raise ProblemError(404, "Unknown job", f"no job with id {job_id!r}", NOT_FOUND)
    if after.status == "cancelled":
        metrics.cancelled(after.request)
    return JSONResponse(_view(after), status_code=202)


@router.get("", operation_id="jobs-list", response_model=JobList,
            responses=problem_responses({422: "invalid `status`, `limit` or `cursor`; `errors` names the field",
                                         503: UNAVAILABLE_BACKEND}),
            summary="List jobs, newest first (no results; page with next_cursor)")
def list_jobs(backend: Backend, owner: Owner,
              status: str | None = Query(None, description=f"only jobs with this status: {', '.join(STATUSES)}",
                                         json_schema_extra={"enum": list(STATUSES)}),
              limit: int = Query(DEFAULT_LIMIT, ge=1, le=MAX_LIMIT, description="most items on the page"),
              cursor: str | None = Query(None, description="a previous page's next_cursor, as it is")) -> JobList:
    """Every job this service knows (posted, or sent straight to the queue by a job-queue client),
    newest first: id, status, progress, created_at, kind, location. With API keys: the key's jobs and
    those sent straight to the queue."""
    if status is not None and status not in STATUSES:
        raise invalid_request([FieldError(field="status", reason=f"{status!r} is not a job status; one of "
                                                                 f"{', '.join(STATUSES)}")])
    try:
        records, next_cursor = backend.list_jobs(status, limit, cursor, owner)
    except InvalidCursor as exc:
        raise invalid_request([FieldError(field="cursor", reason=str(exc))]) from None
    return JobList(items=[JobListItem(id=r.id, status=r.status, progress=r.progress, created_at=r.created_at,
                                      kind=job_kind(r.request), location=f"/v1/jobs/{r.id}") for r in records],
                   next_cursor=next_cursor)
