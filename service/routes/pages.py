"""Pages and plots: ``/v1/jobs/{id}/page``, ``/v1/jobs/{id}/plots/{name}.{format}`` and the same for
ensembles. Plots of finished jobs, and of an ensemble's finished chunks, are cached (they cannot change)."""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from collections.abc import Callable
from itertools import islice
from typing import Any, Literal

from fastapi import APIRouter, Query, Request, Response
from fastapi.responses import HTMLResponse

from schemas.problems import CONFLICT, FieldError
from schemas.report import REPORT_JOB
from service.access import ensemble_of, job_of
from service.backends import JobRecord
from service.deps import Backend, Owner
from service.ensembles import all_members, members_page, request_units, view
from service.errors import ProblemError, invalid_request, media_responses, problem_responses
from service.exports import download, download_responses
from service.pages import render_ensemble, render_job, render_report, render_report_status
from service.plot_orbit import TransientImage
from service.security import content_disposition

router = APIRouter()
#: Members listed on an ensemble's page (the rest through ``/members``).
PAGE_MEMBERS = 50
#: Rendered plots kept in memory (finished jobs and ensembles only).
PLOT_CACHE_SIZE = 64
JobPlotName = Literal["trajectory", "integrals", "poincare", "lyapunov", "periodic_orbit", "bifurcation"]
EnsemblePlotName = Literal["poincare", "exponents", "map", "orbit_diagram"]
PlotFormat = Literal["png", "svg"]
_HTML = media_responses(["text/html"], "the page")
_IMAGE = download_responses(["image/png", "image/svg+xml"], "the plot (PNG or SVG, as the path's suffix says)")
#: The trajectory plot's window (:mod:`service.plot_trajectory`), as the query documents it.
WINDOW_HELP = {"t_from": "the trajectory plot's window starts here [s] (default: the last stretch of a long run; "
                         "0 with t_to = t_final: the whole run)",
               "t_to": "the window ends here [s], at most the run's t_final (default t_final)"}


def _number(field: str, text: str | None) -> float | None:
    """A query's number (None when absent or empty), or a 422 naming ``field``."""
    if text is None or not text.strip():
        return None
    try:
        return float(text)
    except ValueError:
        raise invalid_request([FieldError(field=field, reason=f"must be a number of seconds, not {text[:40]!r}")]) \
            from None


def trajectory_window(t_from: float | None, t_to: float | None, result: dict[str, Any],
                      name: str) -> tuple[float, float] | None:
    """The window ``(t_from, t_to)`` asked for (None: the plot's default), or a 422 naming the parameter."""
    if t_from is None and t_to is None:
        return None
    if name != "trajectory":
        field = "t_from" if t_from is not None else "t_to"
        raise invalid_request([FieldError(field=field, reason=f"only the trajectory plot takes a window, not {name}")])
    t_final = float(result["trajectory"]["t"][-1])
    start = 0.0 if t_from is None else t_from
    end = t_final if t_to is None else t_to
    if not math.isfinite(start) or not 0 <= start < t_final:
        raise invalid_request([FieldError(field="t_from", reason=f"must be a number in [0, {t_final:g}) s (the run's "
                                                                 f"t_final is {t_final:g} s), not {start:g}")])
    if not math.isfinite(end) or not start < end <= t_final:
        raise invalid_request([FieldError(field="t_to", reason=f"must be a number in ({start:g}, {t_final:g}] s "
                                                               "(after t_from, at most the run's t_final), "
                                                               f"not {end:g}")])
    return start, end


class _PlotCache:
    """A small LRU of rendered plots, shared by the request threads."""

    def __init__(self, size: int) -> None:
        self.size, self.items, self.lock = size, OrderedDict[tuple[str, ...], bytes](), threading.Lock()

    def get(self, key: tuple[str, ...], make: Callable[[], bytes], keep: bool) -> bytes:
        with self.lock:
            if key in self.items:
                self.items.move_to_end(key)
                return self.items[key]
        data = make()
        if keep and not isinstance(data, TransientImage):  # a fallback a busy machine caused is drawn again
            with self.lock:
                self.items[key] = data
                while len(self.items) > self.size:
                    self.items.popitem(last=False)
        return data


_cache = _PlotCache(PLOT_CACHE_SIZE)


#: Media types of the plots (:data:`service.plots.FORMATS`, without importing matplotlib at start-up).
IMAGE_TYPES = {"png": "image/png", "svg": "image/svg+xml"}


def _image(data: bytes, fmt: str, filename: str, request: Request | None = None) -> Response:
    """The plot as its image type (``application/octet-stream`` when the request's Accept asks only for that)."""
    if request is not None:
        return download(request, data, IMAGE_TYPES[fmt], filename, "inline")
    return Response(data, media_type=IMAGE_TYPES[fmt], headers=content_disposition("inline", filename))


@router.get("/v1/jobs/{job_id}/page", tags=["jobs"], operation_id="jobs-page", response_class=HTMLResponse,
            responses={**_HTML, **problem_responses({404: "unknown job id",
                                                     422: "t_from or t_to is not a time within the run"})},
            summary="The job as a page: system, evidence tables with verdicts, plots, links to the exports")
def job_page(job_id: str, backend: Backend, owner: Owner,
             t_from: str | None = Query(None, description=WINDOW_HELP["t_from"] + "; empty: the default"),
             t_to: str | None = Query(None, description=WINDOW_HELP["t_to"] + "; empty: the default")
             ) -> HTMLResponse:
    """Reloads itself every 2 s while the job is queued or running."""
    record = job_of(backend, owner, job_id)
    if record.request.get("job") == REPORT_JOB:
        return report_html(record)
    window = None
    if record.result is not None and "trajectory" in record.result:  # the page's form sends empty fields
        window = trajectory_window(_number("t_from", t_from), _number("t_to", t_to), record.result, "trajectory")
    return HTMLResponse(render_job({"id": record.id, "status": record.status, "progress": record.progress,
                                    "created_at": record.created_at, "request": record.request,
                                    "result": record.result, "error": record.error}, window))


def report_html(record: JobRecord) -> HTMLResponse:
    """The paper report's page (also ``GET /v1/paper/report/{id}``)."""
    if record.status == "succeeded" and record.result is not None:
        return HTMLResponse(render_report(record.result, record.id))
    return HTMLResponse(render_report_status(record.id, record.status, record.progress, record.error,
                                             record.created_at))


@router.get("/v1/jobs/{job_id}/plots/{name}.{fmt}", tags=["jobs"], operation_id="jobs-plot",
            response_class=Response,
            responses={**_IMAGE, **problem_responses({404: "unknown job id",
                                                      409: "the job has not succeeded, or asked for no such analysis",
                                                      422: "unknown plot name or format"})},
            summary="A plot of a job's result (matplotlib): trajectory, integrals, poincare, lyapunov, "
                    "periodic_orbit or bifurcation, PNG or SVG")
def job_plot_route(job_id: str, name: JobPlotName, fmt: PlotFormat, request: Request, backend: Backend,
                   owner: Owner, t_from: float | None = Query(None, description=WINDOW_HELP["t_from"]),
                   t_to: float | None = Query(None, description=WINDOW_HELP["t_to"])) -> Response:
    record = job_of(backend, owner, job_id)
    job_id = record.id
    result = record.result
    if record.status != "succeeded" or result is None:
        raise ProblemError(409, "No result yet", f"job {job_id} is {record.status}; its plots are there once it "
                                                 "succeeded", CONFLICT)
    if "trajectory" not in result:
        raise ProblemError(409, "No plots", f"job {job_id} is a paper report, not a simulation", CONFLICT)
    window = trajectory_window(t_from, t_to, result, name)
    from service.plots import PlotUnavailable, job_plot  # matplotlib: imported when the first plot is drawn

    try:
        data = _cache.get(("job", job_id, name, fmt, repr(window)),
                          lambda: job_plot(name, result, record.request, fmt, window), keep=True)
    except PlotUnavailable as exc:
        raise ProblemError(409, "Plot unavailable", str(exc), CONFLICT) from None
    return _image(data, fmt, f"job-{job_id}-{name}.{fmt}", request)


@router.get("/v1/ensembles/{ensemble_id}/page", tags=["ensembles"], operation_id="ensembles-page",
            response_class=HTMLResponse, responses={**_HTML, **problem_responses({404: "unknown ensemble id"})},
            summary="The ensemble as a page: progress, summary, plots, the first members, links to the exports")
def ensemble_page(ensemble_id: str, backend: Backend, owner: Owner) -> HTMLResponse:
    """Reloads itself every 2 s while chunks are queued or running."""
    record = ensemble_of(backend, owner, ensemble_id)
    ensemble_id = record["id"]
    if record["request"].get("indicators"):  # a chaos map: its cells inside the level first (issue 35, item 6)
        members = list(islice((m for m in all_members(backend.ensembles, ensemble_id, record)
                               if (m.get("cell") or {}).get("status", m.get("status")) != "outside"), PAGE_MEMBERS))
    else:
        members = members_page(backend.ensembles, ensemble_id, record, 0, PAGE_MEMBERS)
    return HTMLResponse(render_ensemble(view(ensemble_id, record), members, request_units(record["request"])))


@router.get("/v1/ensembles/{ensemble_id}/plots/{name}.{fmt}", tags=["ensembles"], operation_id="ensembles-plot",
            response_class=Response,
            responses={**_IMAGE, **problem_responses({404: "unknown ensemble id",
                                                      409: "no member done yet, or no such analysis asked for",
                                                      422: "unknown plot name or format"})},
            summary="A plot of an ensemble (matplotlib): every member's poincare points, the exponents, or a chaos map")
def ensemble_plot_route(ensemble_id: str, name: EnsemblePlotName, fmt: PlotFormat, request: Request,
                        backend: Backend, owner: Owner) -> Response:
    """Drawn from the members of the chunks done so far; cached by that set of chunks."""
    record = ensemble_of(backend, owner, ensemble_id)
    ensemble_id = record["id"]
    current = view(ensemble_id, record)
    if not record["done"]:
        raise ProblemError(409, "No members yet", f"ensemble {ensemble_id} is {current['status']} and no chunk has "
                                                  "finished yet", CONFLICT)
    from service.plots import PlotUnavailable, ensemble_plot  # matplotlib: imported when the first plot is drawn

    done = ",".join(str(i) for i in sorted(record["done"]))  # finished chunks do not change: neither does the plot
    try:
        data = _cache.get(("ensemble", ensemble_id, name, fmt, done),
                          lambda: ensemble_plot(name, current, all_members(backend.ensembles, ensemble_id, record),
                                                fmt),
                          keep=True)
    except PlotUnavailable as exc:
        raise ProblemError(409, "Plot unavailable", str(exc), CONFLICT) from None
    return _image(data, fmt, f"ensemble-{ensemble_id}-{name}.{fmt}", request)
