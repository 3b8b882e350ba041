"""HTML pages a person reads: a job, an ensemble and the paper report, from one set of Jinja2
templates (``service/templates``: ``base.html`` and its children). No JavaScript, no asset from the
internet; a page of something still running reloads itself every :data:`REFRESH_S` seconds."""

from __future__ import annotations

import re
from collections.abc import Sequence
from functools import lru_cache
from typing import Any

from jinja2 import Environment, PackageLoader, select_autoescape
from pydantic import ValidationError

import nonholonomic
from nonholonomic.analysis.lyapunov.result import CONVERGENCE_WARNING
from nonholonomic.systems import registered
from schemas.systems import system_spec

#: Seconds between reloads of a page whose job or ensemble is queued or running.
REFRESH_S = 2
#: Plots on a job's page: (name, caption); shown when the result has what they need.
JOB_PLOT_CAPTIONS = {
    "trajectory": "the orbit on its sphere or ellipsoid, and the momentum against t (drawn from the integrator's "
                  "dense output through the stored samples); a long run as a window over the whole run in grey: "
                  "by default its last 4 turns",
    "integrals": "relative drift |I(t) − I(0)| / max(|I(0)|, scale) of every first integral at the samples",
    "poincare": "the Poincaré section: the two coordinates asked for at each crossing",
    "lyapunov": "running finite-time estimates of the Lyapunov exponents (QR every interval); the title says "
                "whether they have converged",
    "periodic_orbit": "the periodic orbit's multipliers on the complex plane (on the unit circle: elliptic); the "
                      "continuation's trace against the swept parameter, or Newton's closing residual per step",
    "bifurcation": "the branch of periodic orbits: a section coordinate of the orbit, and the section map's trace, "
                   "against the continued value; solid where the orbit is elliptic (stable), dashed where not; the "
                   "located bifurcations marked (F fold, PD period doubling, R3/R4 resonances) and the period-2k "
                   "branches switched onto at the period doublings in their own colours",
}
ENSEMBLE_PLOT_CAPTIONS = {
    "poincare": "every member's section points, one colour per member",
    "exponents": "largest Lyapunov exponent of each member, a finite-time estimate (against the swept parameter, "
                 "or a histogram); the members not converged are drawn apart. The dotted line is ln T / T: a regular "
                 "orbit's finite-time exponent decays to 0 only like ln t / t, so an integrable system's members sit "
                 "near it at T, and still move (\"not converged\") however long the run",
    "map": "the chaos map: each indicator on the section plane, one cell per pixel (grey: outside the level, red: "
           "failed); the colour bar marks the threshold above which a cell is chaotic",
    "orbit_diagram": "the orbit diagram: every member's section points against the swept parameter (a periodic "
                     "orbit of period k: k points above its value; a torus: a segment; chaos: a smear)",
}
#: How to cite, on every page; the same data as ``CITATION.cff`` at the repository's root (a test compares them).
CITATION: dict[str, dict[str, Any]] = {
    "software": {"title": "nonholonomic: a computation service for nonholonomic mechanics with machine-checked "
                          "evidence",
                 "authors": "The nonholonomic developers", "version": nonholonomic.__version__, "license": "MIT"},
    "paper": {"title": "Hamiltonization of nonholonomic systems", "authors": ["A. V. Borisov", "I. S. Mamaev"]},
}


def citation_text() -> dict[str, str]:
    """The software's and the paper's citation as text, and both as BibTeX."""
    software, paper = CITATION["software"], CITATION["paper"]
    authors = " and ".join(paper["authors"])
    bib_authors = " and ".join("{}, {}".format(*reversed(a.rsplit(" ", 1))) for a in paper["authors"])
    return {
        "software": f"{software['authors']}, {software['title']}, version {software['version']} "
                    f"({software['license']} license).",
        "paper": f"{authors}, \u201c{paper['title']}\u201d.",
        "bibtex": (f"@software{{nonholonomic,\n  author  = {{{{{software['authors']}}}}},\n"
                   f"  title   = {{{software['title']}}},\n  version = {{{software['version']}}},\n"
                   f"  license = {{{software['license']}}}\n}}\n"
                   f"@misc{{borisov_mamaev_hamiltonization,\n  author = {{{bib_authors}}},\n"
                   f"  title  = {{{paper['title']}}}\n}}"),
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
    env.globals["citation"] = citation_text()
    env.globals["convergence_warning"] = CONVERGENCE_WARNING
    return env


def _refresh(status: str) -> int | None:
    return REFRESH_S if status in ("queued", "running") else None


#: The trajectory plot's caption for a system written by the user (its state is (q, q_dot)).
TRAJECTORY_CAPTION_OWN = ("the coordinates q in space (the first three) and the velocities q_dot against t (drawn "
                          "from the integrator's dense output)")


def job_plots(result: dict[str, Any] | None, status: str = "succeeded") -> list[tuple[str, str]]:
    """The plots a job's result can draw, with their captions (none before it succeeded: the plot routes
    answer 409 until then)."""
    if status != "succeeded" or not result or "trajectory" not in result:
        return []
    record = registered(str((result.get("system") or {}).get("kind")))
    own = record is not None and record.written_by_user
    return [(name, TRAJECTORY_CAPTION_OWN if own and name == "trajectory" else caption)
            for name, caption in JOB_PLOT_CAPTIONS.items() if name in ("trajectory", "integrals") or result.get(name)
            or (name == "bifurcation" and (result.get("periodic_orbit") or {}).get("branch"))]


def ensemble_plots(view: dict[str, Any]) -> list[tuple[str, str, str | None]]:
    """The plots an ensemble asked for: (name, caption, why it is not there yet or None). A plot is drawn
    from the finished chunks' members; before one chunk finished with a member that succeeded, the page
    shows the reason in its place, not an image that would answer 409."""
    wanted = {"poincare": bool(view["request"].get("poincare")), "exponents": bool(view["request"].get("lyapunov")),
              "map": bool(view["request"].get("indicators")),
              "orbit_diagram": bool(view["request"].get("poincare"))
              and bool((view["request"].get("members") or {}).get("sweep"))}
    if not view["chunks"]["done"]:
        pending: str | None = ("no chunk of members is done" +
                               (" (this page reloads every 2 s)" if view["status"] in ("queued", "running") else ""))
    elif not (view.get("summary") or {}).get("succeeded"):
        pending = "no member has succeeded" + (" yet" if view["status"] in ("queued", "running") else "")
    else:
        pending = None
    return [(name, caption, pending) for name, caption in ENSEMBLE_PLOT_CAPTIONS.items() if wanted[name]]


def render_job(job: dict[str, Any], window: tuple[float, float] | None = None) -> str:
    """``GET /v1/jobs/{id}/page``: the system, the evidence tables with verdicts, the plots, the exports.

    ``job`` is the job view (``GET /v1/jobs/{id}``) of a simulation job; ``window`` the trajectory plot's
    ``(t_from, t_to)`` (None: its default, the last stretch of a long run).
    """
    result = job.get("result")
    query = "" if window is None else f"?t_from={window[0]!r}&t_to={window[1]!r}"
    return environment().get_template("job.html").render(
        job=job, result=result, system=(result or {}).get("system"), written=written_system(job.get("request")),
        plots=job_plots(result, job["status"]), refresh=_refresh(job["status"]), window=window,
        window_query=query)


def written_system(request: Any) -> dict[str, Any] | None:
    """What the user wrote of a system of their own (a kind written by the user): the names of the state's
    components and each expression by field (``L``, ``a1``, ``constraints[0]`` ...); None for a catalog kind,
    or a request no kind's model reads (one sent straight to the broker)."""
    block = request.get("system") if isinstance(request, dict) else None
    if not isinstance(block, dict):
        return None
    record = registered(str(block.get("kind")))
    if record is None or not record.written_by_user:
        return None
    try:
        spec = system_spec(block)
    except ValidationError:
        return None
    return {"components": spec.component_names(),
            "expressions": [(_entry_label(field.removeprefix("system.")), text) for field, text in spec.expressions()]}


def _entry_label(field: str) -> str:
    """A field as the page names it: ``constraints[0]`` → ``constraint 1`` (as the result names its integral)."""
    match = re.fullmatch(r"(\w+?)s\[(\d+)\]", field)
    return field if match is None else f"{match[1]} {int(match[2]) + 1}"


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
