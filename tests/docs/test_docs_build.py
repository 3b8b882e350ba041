"""The documentation site builds with ``mkdocs build --strict`` (the venv's mkdocs, from the repository
root): every page of the table of contents is there, the HTTP reference generated from the OpenAPI
document lists the routes, and no page asks anything of another host (fonts, CDNs)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MKDOCS = Path(sys.executable).parent / "mkdocs"
#: Pages of the navigation (directory URLs: each is <page>/index.html in the site).
PAGES = ("index.html", "getting-started/index.html", "first-job/index.html", "sections-ensembles/index.html",
         "results-and-client/index.html", "tutorials/index.html", "science/index.html", "errata/index.html",
         "api/index.html", "reference/http/index.html", "reference/python/index.html",
         "reference/client/index.html", "queue-mode/index.html", "layout/index.html", "testing/index.html",
         "benchmarks/index.html")
#: A URL on another host that a page would fetch or link to for its looks or scripts.
ELSEWHERE = re.compile(r"https?://[^\s\"'<>]*(?:fonts\.googleapis|fonts\.gstatic|cdn|jsdelivr|unpkg)", re.IGNORECASE)


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if not MKDOCS.exists():
        pytest.fail(f"{MKDOCS} is missing: install the docs extra (pip install -e '.[docs]')")
    out = tmp_path_factory.mktemp("site")
    done = subprocess.run([str(MKDOCS), "build", "--strict", "--site-dir", str(out)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300,  # a hang guard only
                          env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert done.returncode == 0, f"mkdocs build --strict failed:\n{done.stdout}\n{done.stderr}"
    return out


def test_every_page_of_the_table_of_contents_is_built(site: Path) -> None:
    missing = [page for page in PAGES if not (site / page).is_file()]
    assert not missing, missing
    home = (site / "index.html").read_text(encoding="utf-8")
    for title in ("Getting started", "First job", "Sections and ensembles", "Results and the Python client",
                  "Tutorials", "Science", "Misprints in the paper", "API reference", "Queue mode", "Layout",
                  "Testing", "Benchmarks"):
        assert title in home, f"navigation lacks {title!r}"


def test_no_page_requests_anything_from_elsewhere(site: Path) -> None:
    offenders = {str(page.relative_to(site)): sorted(set(ELSEWHERE.findall(page.read_text(encoding="utf-8"))))
                 for page in site.rglob("*.html")}
    assert not {page: urls for page, urls in offenders.items() if urls}
    # MathJax is served by the site itself, and pages with formulas load that copy.
    assert (site / "assets/mathjax/MathJax.js").is_file()
    assert ('<script src="../assets/mathjax/MathJax.js?config=TeX-AMS-MML_HTMLorMML-full">'
            in (site / "errata/index.html").read_text(encoding="utf-8"))


def test_http_reference_lists_the_routes_from_the_openapi_document(site: Path) -> None:
    page = (site / "reference/http/index.html").read_text(encoding="utf-8")
    assert "POST /v1/jobs" in page and 'id="jobs-submit"' in page
    for route in ("GET /v1/jobs/{job_id}", "POST /v1/ensembles", "GET /health"):
        assert route in page, route
    assert "application/problem+json" in page and "JobRequest" in page


def test_python_reference_documents_the_front_doors(site: Path) -> None:
    core = (site / "reference/python/index.html").read_text(encoding="utf-8")
    for anchor in ("nonholonomic.simulate", "nonholonomic.get_system",
                   "nonholonomic.hamiltonization.reducing_multiplier.hamiltonize"):
        assert f'id="{anchor}"' in core, anchor
    client = (site / "reference/client/index.html").read_text(encoding="utf-8")
    assert 'id="nonholonomic_client.api.Client.submit"' in client
