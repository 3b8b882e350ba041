"""The catalog, the health endpoint and the OpenAPI docs."""

from __future__ import annotations


def test_health_in_embedded_mode(client):
    r = client.get("/health")
    assert r.status_code == 200
    body = r.json()
    assert body["status"] == "ok" and body["mode"] == "embedded" and body["api"] == "ok"


def test_embedded_health_is_503_until_the_warm_up_ends(monkeypatch):
    """A job sent during the warm-up waits for it: /health says so (503, degraded, detail) and turns 200
    when it ends."""
    import threading

    from fastapi.testclient import TestClient

    import service.backends.embedded as embedded
    from schemas.settings import get_settings
    from service.main import create_app

    release = threading.Event()
    monkeypatch.setattr(embedded, "warm_up", lambda: release.wait(30))
    monkeypatch.delenv("REDIS_URL", raising=False)
    monkeypatch.setenv("NONHOLONOMIC_WARM_UP", "true")
    get_settings.cache_clear()
    try:
        with TestClient(create_app()) as client:
            r = client.get("/health")
            assert r.status_code == 503 and r.json()["status"] == "degraded"
            assert r.json()["workers"]["warm"] is False and "warm-up" in r.json()["detail"]
            release.set()
            for _ in range(100):
                if client.get("/health").status_code == 200:
                    break
                threading.Event().wait(0.02)
            r = client.get("/health")
            assert r.status_code == 200 and r.json()["workers"]["warm"] is True and "detail" not in r.json()
    finally:
        release.set()
        get_settings.cache_clear()


def test_catalog_describes_the_ball(client):
    systems = client.get("/v1/systems").json()["systems"]
    ball = next(s for s in systems if s["kind"] == "chaplygin_ball")
    assert ball == client.get("/v1/systems/chaplygin_ball").json()
    params = {p["name"]: p for p in ball["parameters"]}
    assert params["inertia"]["admissible"] == "> 0: 1e-12 .. 1e+12" and params["D"]["admissible"] == ">= 0, at most 1e+12"
    assert params["inertia"]["unit"] == "kg m^2"
    assert [s["name"] for s in ball["state"]] == ["M", "gamma"]
    assert {p["kind"] for p in ball["potentials"]} == {"zero", "linear", "brun"}
    integrals = {i["name"]: i for i in ball["integrals"]}
    assert integrals["F"]["claimed_for_potentials"] == ["zero"] and integrals["F"]["equation"] == "2604-4"
    assert set(integrals["energy"]["claimed_for_potentials"]) == {"zero", "linear", "brun", "expression"}
    assert ball["potential_expression"]["variables"] == ["gamma1", "gamma2", "gamma3"]
    assert {"D", "I1", "M1", "omega1", "inertia"} <= set(ball["potential_expression"]["reserved_names"])
    assert ball["measure"]["equation"] == "2604-3" and ball["reduced_time"]["equation"] == "2604-5"
    assert ball["checks"] == ["integrals", "measure", "bracket", "euler_angles", "isomorphisms"]
    assert ball["maps"] == {"zero": ["chaplygin_ball_to_clebsch"]}  # Theorem 3 holds for U = 0 only
    assert next(s for s in systems if s["kind"] == "neumann")["checks"] == ["integrals", "measure"]
    assert ball["alternative_inputs"][0]["name"] == "omega"


def test_unknown_kind_in_catalog_is_404(client):
    r = client.get("/v1/systems/suslov")
    assert r.status_code == 404 and r.headers["content-type"] == "application/problem+json"


def test_openapi_docs_are_served(client):
    assert client.get("/docs").status_code == 200
    spec = client.get("/openapi.json").json()
    assert {"/v1/jobs", "/v1/jobs/{job_id}", "/v1/systems", "/health", "/v1/maps/{name}", "/v1/paper/report",
            "/v1/paper/report/{job_id}"} <= set(spec["paths"])
