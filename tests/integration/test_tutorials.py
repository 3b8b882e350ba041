"""The notebook tutorials (``docs/tutorials/*.ipynb``) executed top to bottom against a live embedded
API, each in a fresh Jupyter kernel, by ``scripts/tutorials.py`` (what a maintainer runs with
``--write`` to store their outputs for the docs). The notebooks assert their own numbers (drifts,
the spectrum's sum against the measure, a verdict), so a change that breaks the physics or the client
fails here."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator

import nbformat
import pytest

from tests.support import ROOT, embedded_api

pytestmark = pytest.mark.integration

TUTORIALS = sorted((ROOT / "docs" / "tutorials").glob("*.ipynb"))


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Iterator[str]:
    with embedded_api(tmp_path_factory.mktemp("tutorials-api")) as url:
        yield url


def test_there_are_the_seven_tutorials_the_docs_list():
    names = [p.stem for p in TUTORIALS]
    assert names == ["chaos-map", "ensemble", "first-job", "paper-report", "section-and-exponents", "theorem-1",
                     "your-own-lagrangian"]
    nav = (ROOT / "mkdocs.yml").read_text()
    assert all(f"tutorials/{p.name}" in nav for p in TUTORIALS)


def test_every_tutorial_runs_against_a_live_server(base, tmp_path):
    run = subprocess.run([sys.executable, str(ROOT / "scripts" / "tutorials.py"), "--url", base, "--out", str(tmp_path)],
                         capture_output=True, text=True, timeout=1200, check=False)
    assert run.returncode == 0, run.stderr[-4000:]
    assert [line.split()[1] for line in run.stdout.splitlines() if line.startswith("ok ")] == [p.name for p in TUTORIALS]
    for path in TUTORIALS:
        book = nbformat.read(tmp_path / path.name, as_version=4)
        outputs = [o for c in book.cells if c.cell_type == "code" for o in c.outputs]
        assert not [o for o in outputs if o.output_type == "error"], path.name
        assert any(o.output_type == "execute_result" for o in outputs), path.name
    section = nbformat.read(tmp_path / "section-and-exponents.ipynb", as_version=4)
    pictures = [o for c in section.cells for o in getattr(c, "outputs", []) if "image/png" in o.get("data", {})]
    assert len(pictures) == 2  # the section and the running estimates, drawn
