"""The paper report as an HTML page a person reads (no JavaScript, no external assets)."""

from __future__ import annotations

from html import escape
from typing import Any

_COLOURS = {"holds": "#1b7f3b", "holds after correction": "#9a6700", "fails": "#b42318", "unresolved": "#57606a"}
_STYLE = """
body{font-family:system-ui,sans-serif;margin:2rem auto;max-width:85rem;line-height:1.4;color:#1f2328}
table{border-collapse:collapse;width:100%;font-size:.9rem}th,td{border-bottom:1px solid #d0d7de;padding:.4rem;
vertical-align:top;text-align:left}th{background:#f6f8fa}code{font-size:.85rem}.v{font-weight:600}
details{font-size:.8rem;color:#57606a}.num{font-family:monospace;white-space:nowrap}h2{margin-top:2rem}
table{table-layout:fixed}td{overflow-wrap:anywhere}
"""
_COLUMNS = (("claim id", 12), ("claim", 27), ("equation", 8), ("verdict", 12), ("method", 8), ("residual", 7),
            ("tolerance", 7), ("correction", 19))


def _num(x: Any) -> str:
    if x is None:
        return "–"
    if isinstance(x, (int, float)):
        return f"{x:.3g}"
    return escape(str(x))


def _row(row: dict[str, Any]) -> str:
    colour = _COLOURS.get(row["verdict"], "#1f2328")
    fix = ""
    if row.get("printed"):
        fix += f"<div>printed: <code>{escape(row['printed'])}</code></div>"
    if row.get("corrected"):
        fix += f"<div>corrected: <code>{escape(row['corrected'])}</code></div>"
    if row.get("errata"):
        fix += f"<div>{escape(row['errata'])}</div>"
    checks = "".join(f"<li>[{escape(str(c['method']))}] {escape(str(c['detail']))}</li>" for c in row["checks"])
    if row.get("printed_check"):
        checks += f"<li>printed form: {escape(str(row['printed_check']['detail']))}</li>"
    if row.get("note"):
        checks += f"<li>note: {escape(row['note'])}</li>"
    return (f"<tr id=\"{escape(row['id'])}\"><td><code>{escape(row['id'])}</code></td>"
            f"<td>{escape(row['claim'])}<details><summary>checks</summary><ul>{checks}</ul></details></td>"
            f"<td>{escape(row['equation'])}</td><td class=\"v\" style=\"color:{colour}\">{escape(row['verdict'])}</td>"
            f"<td>{escape(str(row.get('method') or '–'))}</td>"
            f"<td class=\"num\">{_num(row['residual'])}</td><td class=\"num\">{_num(row['tolerance'])}</td>"
            f"<td>{fix}</td></tr>")


def render_report(report: dict[str, Any], job_id: str) -> str:
    """The report table, grouped by section, with the verdict counts on top."""
    summary = ", ".join(f"{n} {escape(v)}" for v, n in report["summary"].items())
    sections: dict[str, list[dict[str, Any]]] = {}
    for row in report["rows"]:
        sections.setdefault(row["section"], []).append(row)
    head = ("<colgroup>" + "".join(f'<col style="width:{w}%">' for _, w in _COLUMNS) + "</colgroup><tr>"
            + "".join(f"<th>{name}</th>" for name, _ in _COLUMNS) + "</tr>")
    body = "".join(f"<h2>{escape(name)}</h2><table>{head}{''.join(_row(r) for r in rows)}</table>"
                   for name, rows in sections.items())
    legend = "".join(f"<li><b>{escape(k)}</b>: {escape(v)}</li>" for k, v in report["verdicts"].items())
    return (f"<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>Paper report</title>"
            f"<style>{_STYLE}</style></head><body><h1>Paper report</h1><p>{escape(report['paper'])}: every claim "
            f"checked by the service's core ({report['seconds']:.1f} s). {summary}.</p><ul>{legend}</ul>"
            f"<p>JSON: <a href=\"/v1/jobs/{escape(job_id)}\">/v1/jobs/{escape(job_id)}</a></p>{body}</body></html>")


def render_status(job_id: str, status: str, progress: float, error: Any = None) -> str:
    """A page for a report that has not finished (it reloads itself every 2 s) or failed."""
    refresh = '<meta http-equiv="refresh" content="2">' if status in ("queued", "running") else ""
    detail = f"<pre>{escape(str(error))}</pre>" if error else ""
    return (f"<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\">{refresh}<title>Paper report</title>"
            f"<style>{_STYLE}</style></head><body><h1>Paper report</h1><p>Job <code>{escape(job_id)}</code>: "
            f"{escape(status)} ({progress:.0%}).</p>{detail}</body></html>")
