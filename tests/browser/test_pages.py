"""The pages in a real headless Chromium (Debian's, driven by Playwright): the job page, the ensemble
page, the paper report, /docs and /redoc render their expected elements, every image and script loads
from the service itself, and the browser logs no error. Each page comes with its Content-Security-Policy
(:mod:`service.security`) and the browser reports no violation of it (``securitypolicyviolation``
events and console errors). A screenshot of each goes to ``$NONHOLONOMIC_TEST_OUTPUT/browser/``
(``test-output/`` under ``scripts/test.py``)."""

from __future__ import annotations

import json
import os
import re
import time
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urlparse

import httpx
import pytest

from service.security import DOCS_POLICY, EXPLORE_POLICY, PAGE_POLICY, SVG_POLICY
from tests.support import (
    ROOT,
    free_port,
    hang_guard,
    poll_job,
    start_api,
    stop,
    wait_healthy,
)

pytestmark = pytest.mark.integration

CHROMIUM = os.environ.get("NONHOLONOMIC_CHROMIUM", "/usr/bin/chromium")
OUTPUT = Path(os.environ.get("NONHOLONOMIC_TEST_OUTPUT", ROOT / "test-output")) / "browser"
BALL = {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7,
        "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}}
JOB = {"system": BALL, "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 300.0,
       "samples": 301, "poincare": {"surface": "gamma3", "coordinates": ["gamma1", "M3"]},
       "lyapunov": {"interval": 1.0}}
ENSEMBLE = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
            "members": {"sample": {"count": 8, "seed": 1, "level": {"energy": 1.0, "area": 0.0}}},
            "t_final": 200.0, "chunk_size": 2,
            # on gamma3 = 0, (gamma1, gamma2) lies on the unit circle: (gamma1, M3) says where the orbit crosses
            "poincare": {"surface": "gamma3", "coordinates": ["gamma1", "M3"]},
            "lyapunov": {"count": 1}}
REPORT_CLAIMS = ["veselova.multiplier", "ball.measure", "ball.theorem_3"]
#: Hang guard (seconds) of each wait (an API's start, a job, a page drawn): far above the seconds each
#: needs on a quiet machine, never a result.
GUARD_S = 300.0
#: The same for what the browser waits for (milliseconds).
GUARD_MS = int(GUARD_S * 1000)
#: A name other than localhost for the service (Chromium maps it to 127.0.0.1): Swagger UI asks
#: validator.swagger.io for a badge only when the page is not on localhost.
NAMED_HOST = "docs.example.test"
#: Runs in every page before its own content: each CSP violation is kept and logged as an error.
CSP_LISTENER = """
window.__cspViolations = [];
document.addEventListener('securitypolicyviolation', e => {
  const what = `CSP violation: ${e.violatedDirective} blocked ${e.blockedURI || 'inline'} \
(${e.sourceFile}:${e.lineNumber})`;
  window.__cspViolations.push(what);
  console.error(what);
});
"""


@pytest.fixture(scope="module")
def api(tmp_path_factory) -> Iterator[str]:
    """The API under uvicorn in embedded mode."""
    port = free_port()
    log = tmp_path_factory.mktemp("browser") / "api.log"
    proc = start_api(port, log, {"NONHOLONOMIC_WARM_UP": "false"})
    base = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(base, timeout=GUARD_S)
        yield base
    finally:
        stop(proc)


@pytest.fixture(scope="module")
def browser():
    if not Path(CHROMIUM).exists():
        message = f"no Chromium at {CHROMIUM} (scripts/test.py installs Debian's chromium)"
        if os.environ.get("NONHOLONOMIC_REQUIRE_BROWSER"):
            pytest.fail(message)
        pytest.skip(message)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=CHROMIUM, headless=True,
                                     args=["--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                                           f"--host-resolver-rules=MAP {NAMED_HOST} 127.0.0.1"])
        yield chromium
        chromium.close()


class Visit:
    """One page load: console errors, failed requests and every host asked."""

    def __init__(self, browser, url: str, policy: str = PAGE_POLICY, width: int = 1400) -> None:
        self.errors: list[str] = []
        self.hosts: set[str] = set()
        self.page = browser.new_page(viewport={"width": width, "height": 1000})
        self.page.add_init_script(CSP_LISTENER)
        self.page.on("console", lambda m: self.errors.append(f"console: {m.text}") if m.type == "error" else None)
        self.page.on("pageerror", lambda e: self.errors.append(f"page error: {e}"))
        self.page.on("requestfailed", lambda r: self.errors.append(f"request failed: {r.url} {r.failure}"))
        self.page.on("request", lambda r: self.hosts.add(urlparse(r.url).netloc)
                     if urlparse(r.url).scheme in ("http", "https") else None)  # not data: or blob:
        self.page.on("response", lambda r: self.errors.append(f"{r.status} for {r.url}") if r.status >= 400 else None)
        response = self.page.goto(url, wait_until="networkidle", timeout=GUARD_MS)
        assert response is not None and response.status == 200, url
        headers = response.headers
        assert headers.get("content-security-policy", "").startswith(policy.split("{")[0]), headers
        assert headers.get("x-content-type-options") == "nosniff" and headers.get("x-frame-options") == "DENY"
        assert headers.get("referrer-policy") == "no-referrer"

    def images_loaded(self) -> list[tuple[str, int]]:
        return self.page.eval_on_selector_all("img", "els => els.map(e => [e.getAttribute('src'), e.naturalWidth])")

    def finish(self, name: str, base: str, screenshot: bool = True) -> None:
        OUTPUT.mkdir(parents=True, exist_ok=True)
        if screenshot:  # (Chromium takes none of a bare SVG document)
            self.page.screenshot(path=str(OUTPUT / f"{name}.png"), full_page=True)
        violations = self.page.evaluate("window.__cspViolations")
        self.page.close()
        assert violations == [], violations
        assert not self.errors, self.errors
        assert self.hosts <= {urlparse(base).netloc}, f"asked hosts other than the service: {self.hosts}"


def _submit(base: str, path: str, body: dict) -> str:
    r = httpx.post(base + path, json=body, timeout=30)
    assert r.status_code == 202, r.text
    return r.headers["location"]


def _wait_ensemble(base: str, location: str) -> dict:
    with httpx.Client(base_url=base, timeout=30) as client:
        return poll_job(client, location, timeout=GUARD_S, interval=0.2)


def test_job_page_shows_system_evidence_plots_and_exports(api, browser):
    location = _submit(api, "/v1/jobs", JOB)
    with httpx.Client(base_url=api, timeout=30) as client:
        job = poll_job(client, location, timeout=GUARD_S, interval=0.1)
    assert job["status"] == "succeeded", job
    result = job["result"]
    visit = Visit(browser, f"{api}{location}/page")
    page = visit.page
    assert job["id"] in page.title()
    assert "Chaplygin" in page.locator("h1").inner_text()
    # one row per integral and per check, each with its verdict
    assert page.locator("#integrals tr").count() == 1 + len(result["integrals"])
    assert page.locator("#integrals .passed").count() == len(result["integrals"])
    assert page.locator("#checks tr").count() == 1 + len(result["checks"])
    assert page.locator("#system").inner_text().count("kg m^2") >= 2  # parameters with their units
    assert page.locator("#lyapunov tr").count() == 1 + len(result["lyapunov"]["exponents"])
    assert str(result["poincare"]["count"]) in page.locator("#poincare").inner_text()
    images = visit.images_loaded()
    assert sorted(src.split("/")[-1] for src, _ in images) == ["integrals.png", "lyapunov.png", "poincare.png",
                                                                "trajectory.png"]
    assert all(width > 300 for _, width in images), images
    hrefs = page.eval_on_selector_all("#links a", "els => els.map(e => e.getAttribute('href'))")
    assert f"{location}/trajectory?format=csv" in hrefs and f"{location}/trajectory?format=npz" in hrefs
    assert page.locator("meta[http-equiv=refresh]").count() == 0  # finished: no reload
    # the stylesheet (served by the service, no inline style) applies, column widths included
    assert page.eval_on_selector("#integrals", "e => getComputedStyle(e).borderCollapse") == "collapse"
    assert page.eval_on_selector("#checks col", "e => getComputedStyle(e).width") != "auto"
    assert page.locator("dt", has_text="t_final").count() == 1
    assert "Hamiltonization of nonholonomic systems" in page.locator("#cite").inner_text()
    # a long run (about 23 turns of gamma): the trajectory plot is full width, its window chosen below it
    assert page.eval_on_selector("img[alt=trajectory]", "e => e.closest('figure').className") == "wide"
    assert page.locator("#window input[name=t_from]").get_attribute("placeholder") == "last stretch"
    visit.finish("job", api)
    # the reader's window: the form asks for the page again, whose plot draws t in [100, 130]
    visit = Visit(browser, f"{api}{location}/page")
    page = visit.page
    page.fill("#window input[name=t_from]", "100")
    page.fill("#window input[name=t_to]", "130")
    with page.expect_navigation(timeout=GUARD_MS):
        page.click("#window button[type=submit]")
    page.wait_for_load_state("networkidle", timeout=GUARD_MS)
    assert "t_from=100" in page.url and "t_to=130" in page.url
    windowed = [(src, width) for src, width in visit.images_loaded() if "trajectory.png" in src]
    assert windowed == [(f"{location}/plots/trajectory.png?t_from=100.0&t_to=130.0", windowed[0][1])], windowed
    assert windowed[0][1] > 1000  # drawn, full width (11 inches at 110 dpi)
    assert page.input_value("#window input[name=t_from]") == "100.0"
    svg = httpx.get(f"{api}{location}/plots/trajectory.svg?t_from=100.0&t_to=130.0", timeout=GUARD_S).text
    assert "window t in [100, 130] of [0, 300] s" in svg and "whole run" in svg
    visit.finish("job-window", api)
    # a plot's SVG opened on its own draws under its own policy
    svg = Visit(browser, f"{api}{location}/plots/trajectory.svg", SVG_POLICY)
    assert svg.page.locator("svg path").count() > 0
    svg.finish("job-trajectory-svg", api, screenshot=False)


def test_long_formulas_wrap_in_a_narrow_window(api, browser):
    """A potential of the user's, 12 terms long, and the states: nothing is wider than a 900 px window
    (without the wrapping rules the page is ~1100 px wide)."""
    terms = " + ".join(f"k{i}*gamma{1 + i % 3}*gamma{1 + (i + 1) % 3}" for i in range(1, 13))
    potential = {"kind": "expression", "U": terms, "parameters": {f"k{i}": 0.01 for i in range(1, 13)}}
    location = _submit(api, "/v1/jobs", {**JOB, "system": {**BALL, "potential": potential}, "t_final": 20.0,
                                         "poincare": None, "lyapunov": None})
    with httpx.Client(base_url=api, timeout=30) as client:
        assert poll_job(client, location, timeout=GUARD_S, interval=0.1)["status"] == "succeeded"
    visit = Visit(browser, f"{api}{location}/page", width=900)
    assert "k12*gamma1*gamma2" in visit.page.locator("#system").inner_text()
    assert visit.page.evaluate("document.documentElement.scrollWidth <= window.innerWidth")
    visit.finish("job-long-formula", api)


def test_lagrangian_job_page_shows_its_system_and_the_structure_verdicts(api, browser):
    """A system of one's own (the nonholonomic particle, a catalog classic): L and the constraint, the Structure
    section with each verdict and formula, the Hamiltonian-flow checks, and the plots with their own caption."""
    classic = httpx.get(f"{api}/v1/systems/lagrangian", timeout=30).json()["classics"]["nonholonomic_particle"]
    location = _submit(api, "/v1/jobs", classic["job"])
    with httpx.Client(base_url=api, timeout=30) as client:
        job = poll_job(client, location, timeout=GUARD_S, interval=0.1)
    assert job["status"] == "succeeded", job
    visit = Visit(browser, f"{api}{location}/page", width=900)
    page = visit.page
    system = page.locator("#system").inner_text()
    assert "z_dot - y*x_dot = 0" in system and "(x_dot**2 + y_dot**2 + z_dot**2)/2" in system
    structure = page.locator("#structure").inner_text()
    assert "ρ = sqrt(y**2 + 1)" in structure and "N = 1/sqrt(y**2 + 1)" in structure
    assert structure.count("found") >= 2 and "F1 = y**2 + y_dot**2" in structure
    assert page.locator("#checks tr", has_text="hamiltonian_flow").count() >= 2
    assert page.locator("#checks .passed").count() == len(job["result"]["checks"])
    assert "the coordinates q in space" in page.locator("#plots").inner_text()
    page.locator("#plots").scroll_into_view_if_needed()  # the plots load lazily, below the evidence
    # (wait_for_function evaluates a string: the page's CSP refuses it)
    _until(page, "(i => i.length > 0 && [...i].every(e => e.naturalWidth > 0))(document.images)")
    images = visit.images_loaded()
    assert len(images) == 2 and all(width > 300 for _, width in images), images
    assert visit.page.evaluate("document.documentElement.scrollWidth <= window.innerWidth")
    visit.finish("job-lagrangian", api)


def test_ensemble_page_shows_summary_members_and_plots(api, browser):
    location = _submit(api, "/v1/ensembles", ENSEMBLE)
    # while it runs: the plots not there yet are said to be so, no image fails (Visit fails on any 4xx)
    running = Visit(browser, f"{api}{location}/page")
    shown = running.images_loaded()
    assert all(width > 300 for _, width in shown), shown
    assert len(shown) + running.page.locator("figure.pending").count() == 2
    running.finish("ensemble-running", api)
    ensemble = _wait_ensemble(api, location)
    assert ensemble["status"] == "succeeded", ensemble
    visit = Visit(browser, f"{api}{location}/page")
    page = visit.page
    assert page.locator("#members tr").count() == 1 + ENSEMBLE["members"]["sample"]["count"]
    summary = page.locator("#summary").inner_text()
    assert "members succeeded\t8" in summary or "members succeeded 8" in summary, summary
    assert f"{ensemble['summary']['section_points']['total']}" in summary
    images = visit.images_loaded()
    assert sorted(src.split("/")[-1] for src, _ in images) == ["exponents.png", "poincare.png"]
    assert all(width > 300 for _, width in images), images
    assert page.locator("dt", has_text="t_final").count() == 1
    links = page.eval_on_selector_all("#members a", "els => els.map(e => e.getAttribute('href'))")
    assert links == [f"{location}/members?offset={i}&limit=1" for i in range(ENSEMBLE["members"]["sample"]["count"])]
    visit.finish("ensemble", api)


def test_a_chaos_maps_page_shows_the_map_its_summary_and_its_exports(api, browser):
    body = {"system": BALL, "t_final": 150.0, "indicators": ["megno", "fli"],
            "members": {"grid": {"surface": "gamma3", "coordinates": ["gamma1", "M3"],
                                 "level": {"energy": 2.0, "area": 0.0}, "shape": [24, 18]}}}
    location = _submit(api, "/v1/ensembles", body)
    ensemble = _wait_ensemble(api, location)
    assert ensemble["status"] == "succeeded", ensemble
    visit = Visit(browser, f"{api}{location}/page")
    page = visit.page
    summary = page.locator("#map-summary").inner_text()
    m = ensemble["summary"]["map"]
    assert f"{m['regular']} regular" in summary and f"{m['chaotic']} chaotic" in summary, summary
    assert "independent recomputation" in summary
    images = visit.images_loaded()
    assert [src.split("/")[-1] for src, _ in images] == ["map.png"] and images[0][1] > 800, images
    links = page.eval_on_selector_all("#links a", "els => els.map(e => e.getAttribute('href'))")
    for fmt in ("csv", "json", "netcdf"):
        assert f"{location}/map?format={fmt}" in links
    assert page.locator("#cells tr").count() > 1
    visit.finish("chaos-map", api)


def test_a_branch_page_shows_its_bifurcation_diagram_and_table(api, browser):
    """Issue 36: the island's centre continued in a3 through its period doubling, the period-2 branch followed."""
    body = {"system": {**BALL, "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}},
            "initial_state": {"M": [-3.436852983, -0.70154468, 0.0], "gamma": [-0.2, 0.9797958971, 0.0]},
            "project_initial_state": True, "t_final": 20.0, "samples": 11,
            "periodic_orbit": {"surface": "gamma3", "coordinates": ["gamma1", "M3"],
                               "branch": {"in": "potential.a[2]", "to": 1.2, "switch_points": 12}}}
    location = _submit(api, "/v1/jobs", body)
    job = _wait_ensemble(api, location)
    assert job["status"] == "succeeded", job
    visit = Visit(browser, f"{api}{location}/page")
    page = visit.page
    images = dict(visit.images_loaded())
    diagram = [src for src in images if "bifurcation" in src]
    assert diagram and images[diagram[0]] > 1000, images  # the full-width figure, drawn
    rows = page.locator("#bifurcations tr")
    assert rows.count() == 1 + 1 + len(job["result"]["periodic_orbit"]["branch"]["switched"][0]["bifurcations"])
    assert "period doubling" in rows.nth(1).inner_text()
    assert page.locator("#branch-points tr").count() == 1 + len(job["result"]["periodic_orbit"]["branch"]["points"])
    links = page.eval_on_selector_all("#branch ~ p a", "els => els.map(e => e.getAttribute('href'))")
    assert f"{location}/branch?format=csv" in links and f"{location}/branch?format=netcdf" in links
    page.locator("#bifurcations").scroll_into_view_if_needed()
    visit.finish("job-branch", api)


def test_report_page_shows_every_claim_with_its_verdict(api, browser):
    location = _submit(api, "/v1/paper/report", {"claims": REPORT_CLAIMS})
    with httpx.Client(base_url=api, timeout=30) as client:
        job = poll_job(client, location, timeout=2 * GUARD_S, interval=0.2)
    assert job["status"] == "succeeded", job
    job_id = job["id"]
    for url in (f"{api}/v1/paper/report/{job_id}", f"{api}/v1/jobs/{job_id}/page"):
        visit = Visit(browser, url)
        page = visit.page
        rows = page.locator("table.report tr[id]")
        assert rows.count() == len(REPORT_CLAIMS)
        for row in job["result"]["rows"]:
            cell = page.locator(f"tr[id='{row['id']}'] td.v")
            assert cell.inner_text() == row["verdict"]
        visit.finish("report", api)


def test_docs_render_offline_with_every_operation(api, browser):
    spec = httpx.get(f"{api}/openapi.json").json()
    operations = sum(1 for methods in spec["paths"].values() for m in methods if m in ("get", "post", "delete"))
    visit = Visit(browser, f"{api}/docs", DOCS_POLICY)
    page = visit.page
    page.wait_for_selector(".swagger-ui .info .title", timeout=GUARD_MS)
    assert "nonholonomic" in page.locator(".swagger-ui .info .title").inner_text()
    page.wait_for_selector(".opblock", timeout=GUARD_MS)
    assert page.locator(".opblock").count() == operations
    visit.finish("docs", api)


def test_redoc_renders_offline_under_its_policy(api, browser):
    """ReDoc's bundle draws the "API docs by Redocly" logo from cdn.redoc.ly whatever its options: the
    service serves it with an empty image instead (service.main.redoc_bundle), and no Google Fonts."""
    visit = Visit(browser, f"{api}/redoc", DOCS_POLICY)
    page = visit.page
    page.wait_for_selector(".api-info h1", timeout=GUARD_MS)
    assert "nonholonomic" in page.locator(".api-info h1").inner_text()
    assert page.locator("[data-section-id]").count() > 10  # the operations are drawn
    visit.finish("redoc", api)  # no CSP violation, no error, no host but the service


def test_docs_and_redoc_on_a_named_host_ask_nothing_from_elsewhere(api, browser):
    named = api.replace("127.0.0.1", NAMED_HOST)
    docs = Visit(browser, f"{named}/docs", DOCS_POLICY)
    docs.page.wait_for_selector(".opblock", timeout=GUARD_MS)
    docs.page.wait_for_timeout(500)
    docs.finish("docs-named-host", named)
    redoc = Visit(browser, f"{named}/redoc", DOCS_POLICY)
    redoc.page.wait_for_selector("[data-section-id]", timeout=GUARD_MS)
    redoc.finish("redoc-named-host", named)


def _until(page, expression: str, timeout: float = GUARD_S) -> float:
    """Seconds until ``expression`` is true in the page (polled every 10 ms: ``wait_for_function`` evaluates a
    string, which the page's CSP refuses); ``timeout`` is a hang guard."""
    start = time.perf_counter()
    with hang_guard(timeout, f"waiting for {expression}"):
        while not page.evaluate(expression):
            page.wait_for_timeout(10)
    return time.perf_counter() - start


def _click(page, u: float, v: float, shift: bool = False) -> None:
    """Click the plane at the point (u, v) of its coordinates (the page says where it draws it)."""
    x, y = page.evaluate(f"window.explorer.pixelOf({u}, {v})")
    scale = page.evaluate("(c => c.clientWidth / c.width)(document.getElementById('plane'))")
    page.locator("#plane").click(position={"x": x * scale + 1, "y": y * scale + 1},  # + its 1 px border
                                 modifiers=["Shift"] if shift else [])


def test_explore_page_draws_a_clicked_orbit_and_a_shift_clicked_periodic_orbit(api, browser):
    """The ball in a linear field on gamma3 = 0 in (gamma1, M3): the page draws the plane, a click inside the
    island draws its crossings as they stream in (at least 100 of them; the time to the 100th is written to
    the test output, the 1-s figure is measured by bench/bench_explore.py), a shift-click marks the island's
    centre with its multipliers; no error, no CSP violation."""
    visit = Visit(browser, f"{api}/explore?kind=chaplygin_ball&potential=linear", EXPLORE_POLICY)
    page = visit.page
    _until(page, "document.getElementById('plane').dataset.ready === '1'")
    assert page.locator("#surface").input_value() == "gamma3" and page.locator("#coord1").input_value() == "M3"
    done = ("(li => li !== null && li.textContent.includes('crossings') && !li.textContent.includes('…'))"
            "(document.querySelector('#orbits li:nth-child({})'))")
    _click(page, -0.2, 0.0)  # a first click: warms the service's integrator
    _until(page, done.format(1))
    before = int(page.evaluate("document.getElementById('plane').dataset.points"))
    assert before > 300  # t = 2000: ~387 crossings
    _click(page, -0.5, 1.0)
    seconds = _until(page, f"Number(document.getElementById('plane').dataset.points) >= {before + 100}")
    _until(page, done.format(2))
    second = page.locator("#orbits li").nth(1).inner_text()
    u, v = (float(c) for c in re.search(r"from \(([-\d.e]+), ([-\d.e]+)\)", second).groups())
    assert abs(u + 0.5) < 0.01 and abs(v - 1.0) < 0.04, second  # within two pixels of the click
    assert "crossings, t = 2000" in second, second
    # "copy as request" (issue 35, item 7): the orbit's job, run through POST /v1/jobs, gives the same crossings
    crossings = int(re.search(r"(\d+) crossings", second).group(1))
    shown = page.locator("#orbits li").nth(1).locator("pre.request").text_content()
    job = json.loads(shown)
    assert job["poincare"]["surface"] == "gamma3" and job["t_final"] == 2000
    r = httpx.post(f"{api}/v1/jobs", json=job, timeout=60)
    assert r.status_code == 202, r.text
    view = poll_job(httpx.Client(base_url=api, timeout=60), r.headers["location"], timeout=GUARD_S)
    assert view["status"] == "succeeded", view["error"]
    assert abs(view["result"]["poincare"]["count"] - crossings) <= 1, (view["result"]["poincare"]["count"], crossings)
    _click(page, -0.2, 0.0, shift=True)
    _until(page, "document.querySelectorAll('#orbits li').length >= 3")
    star = page.locator("#orbits li").nth(2).inner_text()
    # drag a box: a chaos map of it, submitted as an ensemble and linked (issue 35, item 7)
    scale = page.evaluate("(c => c.clientWidth / c.width)(document.getElementById('plane'))")
    box = page.locator("#plane").bounding_box()
    (xa, ya), (xb, yb) = (page.evaluate(f"window.explorer.pixelOf({u}, {v})") for u, v in ((-0.6, -1.5), (-0.1, 1.5)))
    page.mouse.move(box["x"] + xa * scale + 1, box["y"] + ya * scale + 1)
    page.mouse.down()
    page.mouse.move(box["x"] + (xa + xb) / 2 * scale + 1, box["y"] + (ya + yb) / 2 * scale + 1, steps=4)
    page.mouse.move(box["x"] + xb * scale + 1, box["y"] + yb * scale + 1, steps=4)
    page.mouse.up()
    _until(page, "document.querySelector('#orbits a.map-link') !== null")
    assert page.locator("#orbits li").count() == 4  # the drag drew no orbit
    href = page.locator("#orbits a.map-link").get_attribute("href")
    assert re.fullmatch(r"/v1/ensembles/[0-9a-f-]{36}/page", href), href
    ensemble = httpx.get(f"{api}{href.removesuffix('/page')}", timeout=30).json()
    grid = ensemble["request"]["members"]["grid"]
    assert grid["shape"] == [16, 16] and grid["coordinates"] == ["gamma1", "M3"] and ensemble["members"] == 256
    (u0, u1), (v0, v1) = grid["ranges"]
    assert abs(u0 + 0.6) < 0.01 and abs(u1 + 0.1) < 0.01 and abs(v0 + 1.5) < 0.04 and abs(v1 - 1.5) < 0.04, grid
    assert ensemble["request"]["indicators"] == ["megno"]
    assert "period-1 orbit (found)" in star and "elliptic" in star and "T = 5.1598 s" in star, star
    OUTPUT.mkdir(parents=True, exist_ok=True)
    (OUTPUT / "explore-latency.txt").write_text(f"100 crossings drawn {seconds:.3f} s after a click (warm)\n")
    visit.finish("explore", api)
