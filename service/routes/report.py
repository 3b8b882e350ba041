"""``/v1/paper``: the paper report as a job (JSON through ``/v1/jobs/{id}``) and as an HTML page."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Body, Request
from fastapi.responses import HTMLResponse, JSONResponse

from schemas.jobs import JobAccepted
from schemas.problems import NOT_FOUND, FieldError
from schemas.report import REPORT_JOB, ClaimList, PaperReportRequest
from service.access import job_of
from service.admission import admit_job
from service.deps import AppSettings, Backend, Owner
from service.errors import UNAVAILABLE_BACKEND, ProblemError, invalid_request, problem_responses
from service.idempotency import IDEMPOTENCY_IN_PROGRESS, IDEMPOTENCY_MISMATCH, QUEUE_BOUNDS, idempotent
from service.openapi import operation_id
from service.routes.pages import report_html
from store.idempotency import KeyBinding

#: Operation ids: ``paper-<verb>``.
router = APIRouter(prefix="/v1/paper", tags=["paper report"], generate_unique_id_function=operation_id)


@router.get("/claims", operation_id="paper-claims", response_model=ClaimList,
            summary="The claims the report checks (ids for POST /v1/paper/report)")
def list_claims() -> dict[str, Any]:
    from nonholonomic.report import claim_ids

    return {"claims": claim_ids()}


@router.post("/report", status_code=202, operation_id="paper-report-submit", response_model=JobAccepted,
             responses=problem_responses({409: IDEMPOTENCY_IN_PROGRESS,
                                          422: "unknown claim ids (`errors` names each: claims[i]), or an invalid "
                                               "body" + IDEMPOTENCY_MISMATCH,
                                          429: QUEUE_BOUNDS, 503: UNAVAILABLE_BACKEND}),
             summary="Check every claim of the paper (a job; the HTML page is /v1/paper/report/{id})")
def submit_report(request: Request, backend: Backend, owner: Owner, settings: AppSettings,
                  body: PaperReportRequest | None = Body(None)) -> JSONResponse:
    job = body or PaperReportRequest()
    problems = job.problems()
    if problems:
        raise invalid_request([FieldError(field=f, reason=r) for f, r in problems])
    spec = job.model_dump(mode="json")

    def create(binding: KeyBinding | None) -> str:
        return admit_job(backend, owner, settings, spec, binding).id

    def respond(job_id: str) -> tuple[dict[str, Any], dict[str, str]]:
        location = f"/v1/jobs/{job_id}"
        return (JobAccepted(id=job_id, status="queued", location=location).model_dump(),
                {"Location": location, "Link": f'</v1/paper/report/{job_id}>; rel="alternate"; type="text/html"'})

    return idempotent(request, owner, spec, create, respond)


@router.get("/report/{job_id}", operation_id="paper-report-page", response_class=HTMLResponse,
            responses=problem_responses({404: "no paper report job with this id", 503: UNAVAILABLE_BACKEND}),
            summary="The report as a page a person reads")
def report_page(job_id: str, backend: Backend, owner: Owner) -> HTMLResponse:
    try:
        record = job_of(backend, owner, job_id)
    except ProblemError:
        record = None
    if record is None or record.request.get("job") != REPORT_JOB:
        raise ProblemError(404, "Unknown report", f"no paper report job with id {job_id!r}", NOT_FOUND)
    return report_html(record)
