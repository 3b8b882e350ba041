"""Plain-text summaries the command line prints: the catalog, a job's result, an ensemble, a report."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any


def _num(x: Any) -> str:
    return f"{x:.6g}" if isinstance(x, (int, float)) and not isinstance(x, bool) else str(x)


def _verdict(item: Mapping[str, Any]) -> str:
    passed = item.get("passed")
    return "passed" if passed is True else "FAILED" if passed is False else str(item.get("verdict", "-"))


def _table(rows: Sequence[Sequence[str]], indent: str = "") -> list[str]:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return [indent + "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows]


def listing_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """``nonholonomic list``'s table: a header in capitals, then one row per job or ensemble."""
    return "\n".join(_table([tuple(h.upper() for h in header), *rows]))


def systems_table(catalog: Mapping[str, Any]) -> str:
    """The catalog as a table: kind, state vectors, title.

    Parameters
    ----------
    catalog : dict
        The answer of ``GET /v1/systems``.

    Returns
    -------
    str
    """
    rows = [("KIND", "STATE", "TITLE")]
    entries = list(catalog.get("systems", []))
    # beside "systems", one entry per kind written by the user (each its own shape), under the kind's name
    entries += [entry for key, entry in catalog.items()
                if key != "systems" and isinstance(entry, Mapping) and entry.get("kind") == key]
    for s in entries:
        state = [str(v.get("name")) if isinstance(v, Mapping) else str(v) for v in s.get("state", [])]
        rows.append((str(s.get("kind")), ", ".join(state), str(s.get("title", ""))))
    return "\n".join(_table(rows))


def job_summary(view: Mapping[str, Any]) -> str:
    """A short account of a finished simulation job.

    Parameters
    ----------
    view : dict
        The job view (``GET /v1/jobs/{id}``).

    Returns
    -------
    str
        Status; t_final and tau_final; each integral's verdict and max_rel_drift; each check's
        verdict and residual; section and exponents if asked for; the wall time; warnings.
    """
    lines = [f"job {view.get('id')} {view.get('status')}"]
    result = view.get("result") or {}
    if not result:
        error = view.get("error") or {}
        if error:
            lines.append(f"  error: {error.get('type')}: {error.get('message')}")
        return "\n".join(lines)
    lines.append(f"  t_final {_num(result.get('t_final'))}, tau_final {_num(result.get('tau_final'))}")
    integration = result.get("integration") or {}
    if integration:
        lines.append(f"  wall time {_num(integration.get('wall_time_s'))} s ({integration.get('engine')}, "
                     f"{integration.get('steps')} steps)")
    integrals = result.get("integrals") or []
    if integrals:
        lines.append("integrals")
        lines += _table([("name", "verdict", "max_rel_drift")]
                        + [(str(i.get("name")), _verdict(i), _num(i.get("max_rel_drift"))) for i in integrals], "  ")
    checks = result.get("checks") or []
    if checks:
        lines.append("checks")
        lines += _table([("name", "method", "verdict", "residual")]
                        + [(str(c.get("name")), str(c.get("method", "")), _verdict(c), _num(c.get("residual")))
                           for c in checks], "  ")
    section = result.get("poincare")
    if section:
        lines.append(f"poincare: {section.get('count')} points")
    spectrum = result.get("lyapunov")
    if spectrum:
        lines.append("lyapunov exponents: " + ", ".join(_num(x) for x in spectrum.get("exponents", [])))
    for warning in result.get("warnings") or []:
        lines.append(f"warning: {warning}")
    return "\n".join(lines)


def ensemble_summary(view: Mapping[str, Any]) -> str:
    """A short account of a finished ensemble.

    Parameters
    ----------
    view : dict
        The ensemble view (``GET /v1/ensembles/{id}``).

    Returns
    -------
    str
        Members succeeded/failed, statistics of the largest exponents, section points, the worst
        integral drifts and the first failures.
    """
    lines = [f"ensemble {view.get('id')} {view.get('status')}"]
    summary = view.get("summary") or {}
    if not summary:
        lines.append(f"  members {view.get('members')}, done {view.get('members_done')}")
        return "\n".join(lines)
    lines.append(f"  members {summary.get('members')}: {summary.get('succeeded')} succeeded, "
                 f"{summary.get('failed')} failed, {summary.get('members_with_failed_checks', 0)} with a failed check")
    exponent = summary.get("largest_exponent")
    if exponent:
        lines.append(f"  largest exponent over {exponent.get('count')} members [1/s]: min {_num(exponent.get('min'))},"
                     f" median {_num(exponent.get('median'))}, mean {_num(exponent.get('mean'))},"
                     f" max {_num(exponent.get('max'))}")
    chaos = summary.get("map")
    if chaos:
        fraction = chaos.get("chaotic_fraction")
        lines.append(f"  map {chaos.get('cells')} cells: {chaos.get('regular')} regular, "
                     f"{chaos.get('chaotic')} chaotic, "
                     f"{chaos.get('outside')} outside, {chaos.get('failed')} failed; chaotic fraction "
                     f"{_num(fraction)} (by {chaos.get('status_by')} > "
                     f"{_num((chaos.get('thresholds') or {}).get(chaos.get('status_by')))})")
    points = summary.get("section_points")
    if points:
        lines.append(f"  section points {points.get('total')} ({points.get('min_per_member')} .. "
                     f"{points.get('max_per_member')} per member)")
    drift = summary.get("worst_integral_drift") or {}
    if drift:
        lines.append("  worst integral drift: " + ", ".join(f"{k} {'not finite' if v is None else _num(v)}"
                                                          for k, v in drift.items()))
    for failure in summary.get("failures") or []:
        lines.append(f"  member {failure.get('index')} failed: {failure.get('error')}")
    return "\n".join(lines)


def report_summary(view: Mapping[str, Any]) -> str:
    """The verdict counts of a finished paper report.

    Parameters
    ----------
    view : dict
        The report job's view.

    Returns
    -------
    str
        E.g. ``"paper report <id> succeeded: holds 23, holds after correction 14, fails 0, unresolved 0"``.
    """
    result = view.get("result") or {}
    counts = ", ".join(f"{k} {v}" for k, v in (result.get("summary") or {}).items())
    seconds = f" ({_num(result['seconds'])} s)" if "seconds" in result else ""
    return f"paper report {view.get('id')} {view.get('status')}: {counts}{seconds}"
