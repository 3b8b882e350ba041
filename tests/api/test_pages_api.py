"""Pages and plots through the API (embedded mode): what each answers before, during and after a
job, and the problems for what cannot be drawn. The pages in a real browser: tests/browser."""

from __future__ import annotations

import time

from tests.api.conftest import job
from tests.support import poll_job

REFRESH = '<meta http-equiv="refresh" content="2">'


def _finished(client, **overrides) -> dict:
    r = client.post("/v1/jobs", json=job(**overrides))
    assert r.status_code == 202, r.text
    return poll_job(client, r.headers["location"])


def test_a_running_job_page_reloads_itself_and_its_plots_are_409(client):
    r = client.post("/v1/jobs", json=job(t_final=5e6, samples=11))
    location = r.headers["location"]
    deadline = time.monotonic() + 10
    while client.get(location).json()["status"] == "queued" and time.monotonic() < deadline:
        time.sleep(0.01)
    page = client.get(f"{location}/page")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    assert REFRESH in page.text and "<progress" in page.text
    plot = client.get(f"{location}/plots/trajectory.png")
    assert plot.status_code == 409 and plot.headers["content-type"] == "application/problem+json"
    assert "running" in plot.json()["detail"] or "queued" in plot.json()["detail"]
    assert client.delete(location).status_code == 202
    cancelled = poll_job(client, location)
    assert cancelled["status"] == "cancelled"
    page = client.get(f"{location}/page").text
    assert REFRESH not in page and "cancelled" in page


def test_a_finished_job_page_has_its_tables_plots_and_exports(client):
    view = _finished(client, checks=["integrals", "measure"])
    page = client.get(f"/v1/jobs/{view['id']}/page").text
    assert REFRESH not in page
    for integral in view["result"]["integrals"]:
        assert f"<code>{integral['formula'].replace('>', '&gt;')}</code>" in page
    assert page.count('class="v passed"') == len(view["result"]["integrals"]) + len(view["result"]["checks"])
    # the plots the result can draw, and no others (no poincare or lyapunov block was asked for)
    assert (f"/v1/jobs/{view['id']}/plots/trajectory.png" in page
            and f"/v1/jobs/{view['id']}/plots/integrals.png" in page)
    assert "plots/poincare" not in page and "plots/lyapunov" not in page
    assert f"/v1/jobs/{view['id']}/trajectory?format=csv" in page
    assert "heyoka" in page and "sympy" in page  # the versions that computed it


def test_plots_answer_their_media_type_and_problems_name_the_reason(client):
    view = _finished(client)
    base = f"/v1/jobs/{view['id']}/plots"
    png = client.get(f"{base}/trajectory.png")
    assert png.status_code == 200 and png.headers["content-type"] == "image/png"
    assert png.content.startswith(b"\x89PNG\r\n\x1a\n")
    svg = client.get(f"{base}/integrals.svg")
    assert svg.status_code == 200 and svg.headers["content-type"].startswith("image/svg+xml")
    assert b"<svg" in svg.content[:500]
    missing = client.get(f"{base}/poincare.png")
    assert missing.status_code == 409 and "poincare" in missing.json()["detail"]
    unknown = client.get(f"{base}/phase_portrait.png")
    assert unknown.status_code == 422 and unknown.headers["content-type"] == "application/problem+json"
    assert client.get(f"{base}/trajectory.gif").status_code == 422
    assert client.get("/v1/jobs/nope/page").status_code == 404
    assert client.get("/v1/jobs/nope/plots/trajectory.png").status_code == 404


def test_the_trajectory_plots_window_is_chosen_on_the_page_and_refused_when_it_is_not_a_window(client):
    """Issue 35, item 6: the page's form asks for the page again with t_from and t_to; the plot draws that window
    (its SVG title says so); a window outside the run, backwards or on another plot is a 422 naming the field."""
    view = _finished(client, t_final=60.0)
    page = client.get(f"/v1/jobs/{view['id']}/page", params={"t_from": "20", "t_to": "35.5"})
    assert page.status_code == 200, page.text
    src = f"/v1/jobs/{view['id']}/plots/trajectory.png?t_from=20.0&t_to=35.5"
    assert src.replace("&", "&amp;") in page.text and 'name="t_from"' in page.text and 'value="20.0"' in page.text
    svg = client.get(f"/v1/jobs/{view['id']}/plots/trajectory.svg", params={"t_from": 20, "t_to": 35.5})
    assert svg.status_code == 200 and b"window t in [20, 35.5] of [0, 60] s" in svg.content
    whole = client.get(f"/v1/jobs/{view['id']}/plots/trajectory.svg", params={"t_from": 0, "t_to": 60})
    assert b"t in [0, 60] s" in whole.content and b"window t in" not in whole.content
    empty = client.get(f"/v1/jobs/{view['id']}/page", params={"t_from": "", "t_to": ""})  # the form, left empty
    assert empty.status_code == 200 and "plots/trajectory.png?" not in empty.text
    for params, field in (({"t_from": 70}, "t_from"), ({"t_from": 30, "t_to": 20}, "t_to"),
                          ({"t_to": 61}, "t_to"), ({"t_from": -1}, "t_from"), ({"t_from": "inf"}, "t_from")):
        r = client.get(f"/v1/jobs/{view['id']}/plots/trajectory.png", params=params)
        assert r.status_code == 422 and r.json()["errors"][0]["field"] == field, (params, r.text)
    r = client.get(f"/v1/jobs/{view['id']}/plots/integrals.png", params={"t_from": 1})
    assert r.status_code == 422 and "only the trajectory plot" in r.json()["detail"]
    r = client.get(f"/v1/jobs/{view['id']}/page", params={"t_from": "soon"})
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "t_from"


def test_an_ensemble_page_and_its_plots(client):
    body = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
            "members": {"sweep": {"parameter": "D", "values": [0.3, 0.5, 0.7],
                                  "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}}},
            "t_final": 100.0, "lyapunov": {"count": 1}}
    r = client.post("/v1/ensembles", json=body)
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"])
    assert view["status"] == "succeeded"
    page = client.get(f"{r.headers['location']}/page").text
    assert REFRESH not in page and page.count('<tr id="member-') == 3
    assert "D = 0.3" in page and "D = 0.7" in page  # the members' labels
    assert "plots/exponents.png" in page and "plots/poincare" not in page
    plot = client.get(f"{r.headers['location']}/plots/exponents.svg")
    assert plot.status_code == 200 and b"<svg" in plot.content[:500]
    none = client.get(f"{r.headers['location']}/plots/poincare.png")
    assert none.status_code == 409
    assert client.get("/v1/ensembles/nope/page").status_code == 404


def test_the_result_names_the_service_and_the_libraries_that_computed_it(client):
    import subprocess
    from importlib import metadata

    from tests.support import ROOT

    integration = _finished(client)["result"]["integration"]
    assert set(integration["versions"]) == {"heyoka", "sympy", "numpy", "scipy"}
    assert integration["versions"]["sympy"] == metadata.version("sympy")
    project = integration["project"]
    assert project["name"] == "nonholonomic" and project["version"] == metadata.version("nonholonomic")
    if (ROOT / ".git").exists():
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
        assert project["commit"].split("+")[0] == head
