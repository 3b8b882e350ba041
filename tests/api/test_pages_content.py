"""What the pages say (issue 21, item 7): no image of a plot that is not there yet, ``t_final`` once,
ensemble members linked to their data, the convergence of the exponents, a "How to cite" block from the
same data as ``CITATION.cff``, and /docs and /redoc that ask nothing from elsewhere. In a real browser:
tests/browser/test_pages.py."""

from __future__ import annotations

import re

import yaml

import nonholonomic
from service import main as service_main
from service.pages import (
    CITATION,
    citation_text,
    render_ensemble,
    render_job,
    render_report_status,
)
from tests.api.conftest import job
from tests.support import ROOT, poll_job

ENSEMBLE_REQUEST = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7,
                               "potential": {"kind": "zero"}},
                    "members": {"sample": {"count": 8, "seed": 1, "level": {"energy": 1.0}}}, "t_final": 50.0,
                    "poincare": {"surface": "gamma3", "value": 0.0, "direction": "increasing",
                                 "coordinates": ["gamma1", "M3"]},
                    "lyapunov": {"count": 1, "interval": 1.0}}


def _view(status: str, done: int, succeeded: int | None) -> dict:
    return {"id": "e1", "status": status, "progress": 0.25, "created_at": "now", "request": ENSEMBLE_REQUEST,
            "members": 8, "members_done": 2 + 4 * done,
            "chunks": {"total": 2, "done": done, "size": 4, "workers": {}, "reruns": 0},
            "summary": None if succeeded is None else {"succeeded": succeeded, "failed": 4 * done - succeeded,
                                                       "members_with_failed_checks": 0, "worst_integral_drift": {}}}


def test_a_running_ensemble_page_shows_no_image_of_a_plot_not_there_yet():
    # members of a chunk in progress are counted, but no chunk is done: the plot routes would answer 409
    page = render_ensemble(_view("running", 0, None), [], {})
    assert "<img" not in page
    assert page.count("not drawn yet: no chunk of members is done (this page reloads every 2 s)") == 2
    # a chunk done, every member of it failed: still nothing to draw
    page = render_ensemble(_view("running", 1, 0), [], {})
    assert "<img" not in page and page.count("not drawn yet: no member has succeeded yet") == 2
    # a chunk done with members that succeeded: the images
    page = render_ensemble(_view("running", 1, 4), [], {})
    assert "not drawn yet" not in page
    assert '<img src="/v1/ensembles/e1/plots/poincare.png"' in page and "plots/exponents.png" in page


def test_t_final_appears_once_and_the_ensemble_members_link_to_their_data(client):
    r = client.post("/v1/jobs", json=job(t_final=30.0, lyapunov={"interval": 1.0}))
    view = poll_job(client, r.headers["location"])
    page = client.get(f"{r.headers['location']}/page").text
    assert page.count(">t_final<") == 1 and "30 s" in page
    # the exponents: finite-time estimates, each said converged or not
    assert "Finite-time estimates at t = 30 s" in page
    flags = re.findall(r'<span class="v (?:passed|failed)">(yes|not converged)</span>', page.split('id="lyapunov"')[1])
    assert len(flags) == len(view["result"]["lyapunov"]["exponents"])
    assert ("not converged" in flags) == any(w.startswith("not converged")
                                             for w in view["result"]["lyapunov"]["warnings"])
    queued = render_job({"id": "j", "status": "queued", "progress": 0.0, "created_at": None, "error": None,
                         "request": job(), "result": None})
    assert queued.count(">t_final<") == 1 and "<img" not in queued

    r = client.post("/v1/ensembles", json=ENSEMBLE_REQUEST)
    location = r.headers["location"]
    assert poll_job(client, location)["status"] == "succeeded"
    page = client.get(f"{location}/page").text
    assert page.count(">t_final<") == 1
    links = re.findall(r'href="(/v1/ensembles/[^"]+/members\?offset=(\d+)&amp;limit=1)"', page)
    assert [int(i) for _, i in links] == list(range(8))
    for href, index in links[:2]:
        member = client.get(href.replace("&amp;", "&")).json()["members"]
        assert [m["index"] for m in member] == [int(index)] and member[0]["trajectory"]["t"]


def test_citation_cff_and_the_pages_cite_the_same():
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert cff["cff-version"] == "1.2.0" and cff["type"] == "software" and cff["message"]
    software, paper = CITATION["software"], CITATION["paper"]
    assert cff["title"] == software["title"] and str(cff["version"]) == software["version"] == nonholonomic.__version__
    assert cff["license"] == software["license"] and [a["name"] for a in cff["authors"]] == [software["authors"]]
    [reference] = cff["references"]
    assert reference["title"] == paper["title"] and "doi" not in reference  # no DOI we could not verify
    assert [f"{a['given-names']} {a['family-names']}" for a in reference["authors"]] == paper["authors"]
    text = citation_text()
    for page in (render_report_status("r1", "running", 0.5),
                 render_ensemble(_view("running", 0, None), [], {}),
                 render_job({"id": "j", "status": "queued", "progress": 0.0, "created_at": None, "error": None,
                             "request": job(), "result": None})):
        block = page.split('<footer id="cite">')[1]
        assert "How to cite" in block and "Borisov and I. S. Mamaev" in block
        assert "Hamiltonization of nonholonomic systems" in block and f"version {nonholonomic.__version__}" in block
        assert "@software{nonholonomic" in block and text["bibtex"].splitlines()[-2].strip() in block


def test_docs_and_redoc_ask_nothing_from_elsewhere(client):
    redoc = client.get("/redoc")
    assert redoc.status_code == 200 and "fonts.googleapis" not in redoc.text
    sources = re.findall(r'(?:src|href)="([^"]+)"', redoc.text)
    assert sources and all(s.startswith("/") for s in sources), sources
    bundle = client.get(service_main.REDOC_JS_URL)
    assert bundle.status_code == 200 and bundle.headers["content-type"].startswith("text/javascript")
    assert service_main.REDOC_LOGO.encode() not in bundle.content and b"cdn.redoc.ly" not in bundle.content
    docs = client.get("/docs").text
    assert '"validatorUrl": null' in docs  # no badge from validator.swagger.io on a host other than localhost
    assert all(s.startswith("/") for s in re.findall(r'(?:src|href)="([^"]+)"', docs))
