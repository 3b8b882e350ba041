"""``/v1/paper``: the paper report as a job (JSON through ``/v1/jobs/{id}``) and as an HTML page."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Body, Request, Response
from fastapi.responses import HTMLResponse

from schemas.jobs import JobAccepted
from schemas.problems import NOT_FOUND, FieldError
from schemas.report import REPORT_JOB, ClaimList, PaperReportRequest
from service.errors import UNAVAILABLE_BACKEND, ProblemError, invalid_request, problem_responses
from service.openapi import operation_id
from service.routes.pages import report_html

#: Operation ids: ``paper-<verb>``.
router = APIRouter(prefix="/v1/paper", tags=["paper report"], generate_unique_id_function=operation_id)


@router.get("/claims", operation_id="paper-claims", response_model=ClaimList,
            summary="The claims the report checks (ids for POST /v1/paper/report)")
def list_claims() -> dict[str, Any]:
    from nonholonomic.report import claim_ids

    return {"claims": claim_ids()}


@router.post("/report", status_code=202, operation_id="paper-report-submit", response_model=JobAccepted,
             responses=problem_responses({422: "unknown claim ids (`errors` names each: claims[i]), or an invalid "
                                               "body", 503: UNAVAILABLE_BACKEND}),
             summary="Check every claim of the paper (a job; the HTML page is /v1/paper/report/{id})")
def submit_report(request: Request, response: Response,
                  body: PaperReportRequest | None = Body(None)) -> JobAccepted:  # noqa: B008
    job = body or PaperReportRequest()
    problems = job.problems()
    if problems:
        raise invalid_request([FieldError(field=f, reason=r) for f, r in problems])
    record = request.app.state.backend.submit(job.model_dump(mode="json"))
    location = f"/v1/jobs/{record.id}"
    response.headers["Location"] = location
    response.headers["Link"] = f'</v1/paper/report/{record.id}>; rel="alternate"; type="text/html"'
    return JobAccepted(id=record.id, status="queued", location=location)


@router.get("/report/{job_id}", operation_id="paper-report-page", response_class=HTMLResponse,
            responses=problem_responses({404: "no paper report job with this id", 503: UNAVAILABLE_BACKEND}),
            summary="The report as a page a person reads")
def report_page(job_id: str, request: Request) -> HTMLResponse:
    record = request.app.state.backend.get(job_id)
    if record is None or record.request.get("job") != REPORT_JOB:
        raise ProblemError(404, "Unknown report", f"no paper report job with id {job_id!r}", NOT_FOUND)
    return report_html(record)
