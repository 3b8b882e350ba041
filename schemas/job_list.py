"""The job list (``GET /v1/jobs?status=&limit=&cursor=``)."""

from __future__ import annotations

from typing import Any, get_args

from pydantic import BaseModel, Field

from schemas.jobs import JobStatus
from schemas.report import REPORT_JOB

#: Items per page unless ``limit`` says otherwise, and the most a page holds.
DEFAULT_LIMIT = 50
MAX_LIMIT = 500
#: The values of ``status``.
STATUSES: tuple[str, ...] = get_args(JobStatus)


def job_kind(request: Any) -> str | None:
    """What a job computes: its system's kind, ``paper_report``, or None for a request naming neither
    (one a job-queue client sent that failed validation)."""
    if not isinstance(request, dict):
        return None
    if request.get("job") == REPORT_JOB:
        return REPORT_JOB
    system = request.get("system")
    kind = system.get("kind") if isinstance(system, dict) else None
    return kind if isinstance(kind, str) else None


class JobListItem(BaseModel):
    """One job of the list: no request and no result (``location`` has them)."""

    id: str
    status: JobStatus
    progress: float = Field(ge=0, le=1)
    created_at: str = Field(description="when the service first knew the job (ISO 8601, UTC)")
    kind: str | None = Field(description="the request's system kind, or 'paper_report'; null for a request that "
                                         "names neither (a job sent straight to the queue that failed validation)")
    location: str = Field(description="the job's URL, /v1/jobs/{id}")


class JobList(BaseModel):
    """A page of jobs, newest first."""

    model_config = {"json_schema_extra": {"examples": [{
        "items": [{"id": "0b8e…", "status": "succeeded", "progress": 1.0, "created_at": "2025-01-01T12:00:00+00:00",
                   "kind": "chaplygin_ball", "location": "/v1/jobs/0b8e…"}],
        "next_cursor": None}]}}

    items: list[JobListItem]
    next_cursor: str | None = Field(
        description="pass as `cursor` for the next page; null at the end. With a status filter a page may "
                    "hold fewer items than `limit` (even none) and still have a next cursor: the service "
                    "reads a bounded number of jobs per page")
