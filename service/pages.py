"""HTML pages a person reads: a job, an ensemble and the paper report, from one set of Jinja2
templates (``service/templates``: ``base.html`` and its children). No JavaScript, no asset from the
internet; a page of something still running reloads itself every :data:`REFRESH_S` seconds."""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from typing import Any

from jinja2 import Environment, PackageLoader, select_autoescape

import nonholonomic

#: Seconds between reloads of a page whose job or ensemble is queued or running.
REFRESH_S = 2
#: Plots on a job's page: (name, caption); shown when the result has what they need.
JOB_PLOT_CAPTIONS = {
    "trajectory": "the orbit on its sphere or ellipsoid, and the momentum against t",
    "integrals": "relative drift |I(t) − I(0)| / max(|I(0)|, scale) of every first integral at the samples",
    "poincare": "the Poincaré section: the two coordinates asked for at each crossing",
    "lyapunov": "running estimates of the Lyapunov exponents (QR every interval)",
}
ENSEMBLE_PLOT_CAPTIONS = {
    "poincare": "every member's section points, one colour per member",
    "exponents": "largest Lyapunov exponent of each member (against the swept parameter, or a histogram)",
}
#: The report's columns: (header, width in %).
REPORT_COLUMNS = (("claim id", 12), ("claim", 27), ("equation", 8), ("verdict", 12), ("method", 8), ("residual", 7),
                  ("tolerance", 7), ("correction", 19))
_VERDICT_CLASS = {"holds": "holds", "holds after correction": "corrected", "fails": "fails", "unresolved": "unresolved"}


def _num(x: Any, digits: int = 3) -> str:
    """A number as ``digits`` significant digits; None as a dash; anything else as text."""
    if x is None:
        return "–"
    if isinstance(x, bool):
        return str(x).lower()
    if isinstance(x, (int, float)):
        return f"{x:.{digits}g}"
    return str(x)


def _vec(x: Any) -> str:
    """A parameter or state vector: ``[0.5, -0.2, 0.1]`` with 6 significant digits."""
    if isinstance(x, (list, tuple)):
        return "[" + ", ".join(_vec(v) for v in x) + "]"
    if isinstance(x, dict):
        return ", ".join(f"{k} = {_vec(v)}" for k, v in x.items())
    return _num(x, 6)


@lru_cache(maxsize=1)
def environment() -> Environment:
    """The template environment (autoescaped HTML), built once."""
    env = Environment(loader=PackageLoader("service", "templates"), autoescape=select_autoescape(["html"]),
                      trim_blocks=True, lstrip_blocks=True)
    env.filters["num"] = _num
    env.filters["vec"] = _vec
    env.filters["verdict_class"] = lambda v: _VERDICT_CLASS.get(v, "")
    env.globals["version"] = nonholonomic.__version__
    return env


def _refresh(status: str) -> int | None:
    return REFRESH_S if status in ("queued", "running") else None


def job_plots(result: dict[str, Any] | None) -> list[tuple[str, str]]:
    """The plots a job's result can draw, with their captions."""
    if not result or "trajectory" not in result:
        return []
    return [(name, caption) for name, caption in JOB_PLOT_CAPTIONS.items()
            if name in ("trajectory", "integrals") or result.get(name)]


def ensemble_plots(view: dict[str, Any]) -> list[tuple[str, str]]:
    """The plots an ensemble can draw once members are done."""
    if not view["members_done"]:
        return []
    wanted = {"poincare": bool(view["request"].get("poincare")), "exponents": bool(view["request"].get("lyapunov"))}
    return [(name, caption) for name, caption in ENSEMBLE_PLOT_CAPTIONS.items() if wanted[name]]


def render_job(job: dict[str, Any]) -> str:
    """``GET /v1/jobs/{id}/page``: the system, the evidence tables with verdicts, the plots, the exports.

    ``job`` is the job view (``GET /v1/jobs/{id}``) of a simulation job.
    """
    result = job.get("result")
    return environment().get_template("job.html").render(
        job=job, result=result, system=(result or {}).get("system"), plots=job_plots(result),
        refresh=_refresh(job["status"]))


def render_ensemble(view: dict[str, Any], members: Sequence[dict[str, Any]], units: dict[str, str]) -> str:
    """``GET /v1/ensembles/{id}/page``: progress, the summary, the plots, the first members, the exports."""
    return environment().get_template("ensemble.html").render(
        e=view, members=members, units=units, plots=ensemble_plots(view), refresh=_refresh(view["status"]))


def render_report(report: dict[str, Any], job_id: str) -> str:
    """The paper report: the verdict counts, then one table per section of the paper."""
    sections: dict[str, list[dict[str, Any]]] = {}
    for row in report["rows"]:
        sections.setdefault(row["section"], []).append(row)
    return environment().get_template("report.html").render(
        report=report, job_id=job_id, sections=list(sections.items()), columns=REPORT_COLUMNS, refresh=None)


def render_report_status(job_id: str, status: str, progress: float, error: Any = None,
                         created_at: str | None = None) -> str:
    """The report's page before it finished (reloads itself) or after it failed."""
    return environment().get_template("report.html").render(
        report=None, job_id=job_id, status=status, progress=progress, error=error, created_at=created_at,
        refresh=_refresh(status))
