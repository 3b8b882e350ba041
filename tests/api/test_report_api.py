"""POST /v1/paper/report (a job), its JSON through /v1/jobs/{id} and its HTML page."""

from __future__ import annotations

from tests.support import poll_job

CLAIMS = ["ball.theorem_3", "veselova.clebsch_hamiltonian", "jacobi.chaos"]


def test_report_job_json_and_html(client):
    r = client.post("/v1/paper/report", json={"claims": CLAIMS})
    assert r.status_code == 202, r.text
    assert r.headers["link"].startswith(f"</v1/paper/report/{r.json()['id']}>")
    view = poll_job(client, r.headers["location"], timeout=180)
    assert view["status"] == "succeeded", view["error"]
    report = view["result"]
    assert [row["id"] for row in report["rows"]] == sorted(
        CLAIMS, key=client.get("/v1/paper/claims").json()["claims"].index)
    verdicts = {row["id"]: row["verdict"] for row in report["rows"]}
    assert verdicts == {"ball.theorem_3": "holds after correction", "veselova.clebsch_hamiltonian":
                        "holds after correction", "jacobi.chaos": "holds"}
    page = client.get(f"/v1/paper/report/{view['id']}")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    for text in ("Paper report", "ball.theorem_3", "holds after correction", "ERRATA 8", "B^(1/2)"):
        assert text in page.text, text


def test_claims_are_listed_and_unknown_ones_refused(client):
    claims = client.get("/v1/paper/claims").json()["claims"]
    assert "veselova.multiplier" in claims and len(claims) == len(set(claims))
    r = client.post("/v1/paper/report", json={"claims": ["veselova.multiplier", "kovalevskaya"]})
    assert r.status_code == 422
    (error,) = r.json()["errors"]
    assert error["field"] == "claims[1]" and "'kovalevskaya'" in error["reason"]
    r = client.post("/v1/paper/report", json={"claims": [], "extra": 1})
    assert r.status_code == 422


def test_the_page_of_an_unknown_or_non_report_job_is_404(client):
    assert client.get("/v1/paper/report/nope").status_code == 404
    body = {"system": {"kind": "veselova", "inertia": [1.0, 2.0, 3.0]},
            "initial_state": {"omega": [0.5, -0.2, 0.15], "gamma": [0.0, 0.6, 0.8]}, "t_final": 1.0, "samples": 3}
    job = client.post("/v1/jobs", json=body).json()["id"]
    r = client.get(f"/v1/paper/report/{job}")
    assert r.status_code == 404 and r.headers["content-type"] == "application/problem+json"


def test_a_second_report_is_read_back_with_the_versions_it_was_computed_with(cached_client):
    claims = {"claims": ["veselova.multiplier", "ball.theorem_3"]}
    views = []
    for _ in range(2):
        r = cached_client.post("/v1/paper/report", json=claims)
        view = poll_job(cached_client, r.headers["location"], timeout=300)
        assert view["status"] == "succeeded", view["error"]
        views.append(view)
    first, second = (v["result"] for v in views)
    assert first["computed"]["cached"] is False and second["computed"]["cached"] is True
    assert second["rows"] == first["rows"] and second["summary"] == first["summary"]
    assert second["computed"]["at"] == first["computed"]["at"]  # when it was computed, not now
    versions = second["computed"]["versions"]
    assert {"nonholonomic", "code", "sympy", "heyoka", "numpy"} <= set(versions)
    page = cached_client.get(f"/v1/paper/report/{views[1]['id']}").text
    assert "Read back from the cache" in page and f"sympy {versions['sympy']}" in page
