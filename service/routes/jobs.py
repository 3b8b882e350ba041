"""``/v1/jobs``: submit, poll and cancel simulation jobs."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter, Query, Request, Response
from fastapi.responses import JSONResponse, StreamingResponse

from schemas.jobs import JobAccepted, JobRequest, JobView
from schemas.problems import CONFLICT, NOT_FOUND, FieldError, Problem
from service.backends import JobBackend, JobRecord
from service.errors import ProblemError, invalid_request
from service.exports import trajectory_csv, trajectory_npz

router = APIRouter(prefix="/v1/jobs", tags=["jobs"])
_ERRORS: dict[int | str, dict[str, Any]] = {
    404: {"model": Problem, "description": "unknown job id"},
    422: {"model": Problem, "description": "invalid request; `errors` names each field"},
}


def _backend(request: Request) -> JobBackend:
    return request.app.state.backend


def _view(record: JobRecord) -> dict[str, Any]:
    return {"id": record.id, "status": record.status, "progress": record.progress, "created_at": record.created_at,
            "request": record.request, "result": record.result, "error": record.error}


def _found(record: JobRecord | None, job_id: str) -> JobRecord:
    if record is None:
        raise ProblemError(404, "Unknown job", f"no job with id {job_id!r}", NOT_FOUND)
    return record


@router.post("", status_code=202, response_model=JobAccepted, responses=_ERRORS,
             summary="Submit a simulation job")
def submit_job(job: JobRequest, request: Request, response: Response) -> JobAccepted:
    """Validate (shape, ranges, |γ| = 1, state names) and queue; nothing is queued if invalid."""
    problems = job.problems()
    if problems:
        raise invalid_request([FieldError(field=p.field, reason=p.reason) for p in problems])
    record = _backend(request).submit(job.model_dump(mode="json"))
    location = f"/v1/jobs/{record.id}"
    response.headers["Location"] = location
    return JobAccepted(id=record.id, status="queued", location=location)


@router.get("/{job_id}", response_model=JobView, responses=_ERRORS, summary="Status, progress and result of a job")
def get_job(job_id: str, request: Request) -> JSONResponse:
    return JSONResponse(_view(_found(_backend(request).get(job_id), job_id)))


@router.get("/{job_id}/trajectory", responses={**_ERRORS, 409: {"model": Problem, "description": "the job has not "
                                                                                              "succeeded (yet)"}},
            summary="The sampled trajectory as JSON, CSV (a header with units; t and tau first) or NPZ")
def get_trajectory(job_id: str, request: Request,
                   format: Literal["json", "csv", "npz"] = Query("json")) -> Response:  # noqa: A002
    record = _found(_backend(request).get(job_id), job_id)
    if record.status != "succeeded" or record.result is None:
        raise ProblemError(409, "No trajectory yet", f"job {job_id} is {record.status}; its trajectory is there once "
                                                     "it succeeded", CONFLICT)
    if "trajectory" not in record.result:
        raise ProblemError(409, "No trajectory", f"job {job_id} is a paper report, not a simulation", CONFLICT)
    headers = {"Content-Disposition": f'attachment; filename="job-{job_id}-trajectory.{format}"'}
    if format == "csv":
        return StreamingResponse(trajectory_csv(record.result), media_type="text/csv", headers=headers)
    if format == "npz":
        return Response(trajectory_npz(record.result, record.request), media_type="application/octet-stream",
                        headers=headers)
    return JSONResponse({"units": record.result["system"]["units"], **record.result["trajectory"]})


@router.delete("/{job_id}", response_model=JobView,
               responses={**_ERRORS, 409: {"model": Problem, "description": "the job already finished"}},
               summary="Cancel a job")
def cancel_job(job_id: str, request: Request) -> JSONResponse:
    """A queued job never starts; a running one stops at its next progress report (≤ 0.2 s)."""
    backend = _backend(request)
    before = _found(backend.get(job_id), job_id)
    if before.status in ("succeeded", "failed"):
        raise ProblemError(409, "Job already finished", f"job {job_id} already {before.status}", CONFLICT)
    return JSONResponse(_view(_found(backend.cancel(job_id), job_id)), status_code=202)
