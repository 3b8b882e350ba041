"""Security headers on every answer (:mod:`service.security`): JSON, problem+json (404, 405, 413,
422, 500), HTML pages, downloads, plots, the docs, the static files; the pages' policy is strict (no
inline script or style, nothing from elsewhere); download names built from ids are safe, even for a
job whose id holds CR LF (a job-queue client may send any task id to the broker)."""

from __future__ import annotations

import base64
import hashlib
import re
import time
from urllib.parse import quote

import pytest
from fastapi.testclient import TestClient

from service.pages import REPORT_COLUMNS
from service.security import API_POLICY, PAGE_POLICY, SVG_POLICY, content_disposition, safe_filename
from tests.api.conftest import job
from tests.support import ROOT

COMMON = {"x-content-type-options": "nosniff", "referrer-policy": "no-referrer", "x-frame-options": "DENY"}
TEMPLATES = ROOT / "service" / "templates"
STYLESHEET = ROOT / "service" / "static" / "pages.css"
#: A job id as a job-queue client could send it straight to the broker.
CRLF_ID = 'sent\r\nX-Injected: 1\r\n\r\n<b>"id'


def _secured(response, policy: str | None = API_POLICY) -> None:
    for name, value in COMMON.items():
        assert response.headers.get(name) == value, (response.request.url, name, response.headers)
    csp = response.headers.get("content-security-policy", "")
    assert "frame-ancestors 'none'" in csp, csp
    if policy is not None:
        assert csp == policy, (response.request.url, csp)


def _finished(client: TestClient) -> dict:
    location = client.post("/v1/jobs", json=job(t_final=5.0, samples=11)).headers["location"]
    deadline = time.monotonic() + 120
    while (view := client.get(location).json())["status"] not in ("succeeded", "failed", "cancelled"):
        assert time.monotonic() < deadline, view
        time.sleep(0.05)
    assert view["status"] == "succeeded", view
    return view


def test_json_problems_and_the_docs_carry_the_headers(client):
    for path in ("/health", "/v1/systems", "/openapi.json", "/v1/paper/claims"):
        r = client.get(path)
        assert r.status_code == 200 and r.headers["content-type"].startswith("application/json")
        _secured(r)
    problems = [client.get("/v1/jobs/no-such-job"),  # 404
                client.delete("/health"),  # 405
                client.post("/v1/jobs", json={"system": {"kind": "nope"}}),  # 422
                client.post("/v1/jobs", content=b"{}", headers={"content-length": str(1 << 30),
                                                                 "content-type": "application/json"})]  # 413
    assert [r.status_code for r in problems] == [404, 405, 422, 413]
    for r in problems:
        assert r.headers["content-type"] == "application/problem+json"
        _secured(r)
    for path in ("/docs", "/redoc"):
        r = client.get(path)
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
        _secured(r, None)
        assert "'unsafe-inline'" not in re.search(r"script-src ([^;]*)", r.headers["content-security-policy"])[1]
    # the static files of the pages and of the docs
    for path in ("/static/pages.css", "/static/favicon.svg", "/static-offline-docs/swagger-ui.css"):
        r = client.get(path)
        assert r.status_code == 200, path
        _secured(r, SVG_POLICY if path.endswith(".svg") else API_POLICY)


def test_swagger_ui_may_run_exactly_its_inline_script(client):
    r = client.get("/docs")
    inline = re.findall(rb"<script>(.*?)</script>", r.content, re.S)
    assert len(inline) == 1
    digest = base64.b64encode(hashlib.sha256(inline[0]).digest()).decode()
    script_src = re.search(r"script-src ([^;]*)", r.headers["content-security-policy"])[1].split()
    assert script_src == ["'self'", f"'sha256-{digest}'"]


def test_a_server_error_carries_the_headers(client):
    app = client.app

    @app.get("/boom", include_in_schema=False)
    def boom() -> None:
        raise RuntimeError("boom")

    app.middleware_stack = None  # rebuilt with the new route
    with TestClient(app, raise_server_exceptions=False) as c:
        r = c.get("/boom")
    assert r.status_code == 500 and r.headers["content-type"] == "application/problem+json"
    _secured(r)


def test_pages_downloads_and_plots_carry_the_headers(client):
    view = _finished(client)
    base = f"/v1/jobs/{view['id']}"
    page = client.get(f"{base}/page")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    _secured(page, PAGE_POLICY)
    for fmt in ("csv", "npz", "json"):
        r = client.get(f"{base}/trajectory", params={"format": fmt})
        assert r.status_code == 200
        _secured(r)
    png = client.get(f"{base}/plots/integrals.png")
    svg = client.get(f"{base}/plots/integrals.svg")
    assert png.status_code == svg.status_code == 200
    _secured(png)
    _secured(svg, SVG_POLICY)
    assert b"<script" not in svg.content  # the SVG's own policy allows its <style>, never a script


def test_the_page_policy_is_strict():
    directives = dict(d.strip().split(" ", 1) for d in PAGE_POLICY.split(";"))
    assert directives["default-src"] == "'none'" and "script-src" not in directives  # no script at all
    assert directives["style-src"] == directives["img-src"] == "'self'"
    assert directives["frame-ancestors"] == directives["base-uri"] == "'none'"
    assert directives["form-action"] == "'self'"  # the trajectory plot's window asks this service for the page
    assert "unsafe" not in PAGE_POLICY and "data:" not in PAGE_POLICY and "http" not in PAGE_POLICY


def test_the_templates_have_no_inline_script_or_style():
    for template in TEMPLATES.glob("*.html"):
        text = template.read_text()
        # a script only from a file of the service's (the explorer's), never inline
        assert not re.search(r"<script(?![^>]*\ssrc=\"/static/)|<style|\sstyle\s*=|\son[a-z]+\s*=|javascript:", text,
                             re.I), template.name
    css = STYLESHEET.read_text()
    widths = {w for _, w in REPORT_COLUMNS} | {int(w) for w in re.findall(r'class="w(\d+)"',
                                                                            (TEMPLATES / "_macros.html").read_text())}
    assert {w for w in widths if f"col.w{w}{{width:{w}%}}" not in css} == set()


@pytest.mark.parametrize("name,expected", [
    ("job-1b4e28ba-2fa1-41d2-883f-0016d3cca427-trajectory.csv",
     "job-1b4e28ba-2fa1-41d2-883f-0016d3cca427-trajectory.csv"),
    (f"job-{CRLF_ID}-trajectory.csv", "job-sent__X-Injected__1_____b__id-trajectory.csv"),
    ("../../etc/passwd", "_.._etc_passwd"),
    ("..", "download"),
    ("ж" * 300, "_" * 120),
])
def test_safe_filename_keeps_only_plain_characters(name, expected):
    assert safe_filename(name) == expected
    header = content_disposition("attachment", name)["Content-Disposition"]
    assert re.fullmatch(r'attachment; filename="[A-Za-z0-9._-]+"', header), header


def test_a_job_id_with_crlf_reaches_no_header(client):
    """A succeeded job recorded under an id with CR LF (as a queue client may send it): its downloads
    answer 200 with a safe file name; no header carries the id as it is."""
    view = _finished(client)
    store = client.app.state.backend.store
    store.create(CRLF_ID, view["request"])
    assert store.finish(CRLF_ID, "succeeded", view["result"])
    base = f"/v1/jobs/{quote(CRLF_ID, safe='')}"
    assert client.get(base).json()["id"] == CRLF_ID
    answers = {"csv": client.get(f"{base}/trajectory", params={"format": "csv"}),
               "npz": client.get(f"{base}/trajectory", params={"format": "npz"}),
               "png": client.get(f"{base}/plots/trajectory.png"),
               "page": client.get(f"{base}/page")}
    for name, r in answers.items():
        assert r.status_code == 200, (name, r.text[:300])
        assert all("\r" not in v and "\n" not in v and "X-Injected" not in k for k, v in r.headers.items()), r.headers
        assert "x-injected" not in r.headers
        _secured(r, PAGE_POLICY if name == "page" else API_POLICY)
    assert answers["csv"].headers["content-disposition"] == \
        'attachment; filename="job-sent__X-Injected__1_____b__id-trajectory.csv"'
    assert answers["png"].headers["content-disposition"] == \
        'inline; filename="job-sent__X-Injected__1_____b__id-trajectory.png"'


def test_a_sent_job_with_a_hostile_request_renders_escaped_under_the_policy(client):
    """A job a queue client sent with a request that is not JSON (the worker records it as ``raw``)
    and an error quoting it: its page answers 200 (not a 500), shows the text escaped, and links to
    the job by its URL-encoded id."""
    store = client.app.state.backend.store
    hostile = "<script>alert(1)</script>"
    store.create(CRLF_ID, {"raw": hostile})
    assert store.finish(CRLF_ID, "failed", error={"type": "InvalidJob",
                                                  "message": 'not valid JSON: <img src=x onerror="alert(2)">'})
    page = client.get(f"/v1/jobs/{quote(CRLF_ID, safe='')}/page")
    assert page.status_code == 200, page.text[-500:]
    _secured(page, PAGE_POLICY)
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in page.text and "&lt;img src=x" in page.text
    assert "<script" not in page.text and "<img" not in page.text
    assert f'href="/v1/jobs/{quote(CRLF_ID, safe="/")}"' in page.text
