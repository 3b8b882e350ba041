"""The catalog, the health endpoint and the OpenAPI docs."""

from __future__ import annotations

#: Hang guard (seconds) of each wait for /health to change: far above the fraction of a second the
#: monitor needs (a check every 0.25 s), never a result.
GUARD_S = 60.0


def _health_until(client, status: int):
    """GET /health until it answers ``status`` (returned); fail past the hang guard."""
    import threading
    import time

    deadline = time.monotonic() + GUARD_S
    while (r := client.get("/health")).status_code != status:
        assert time.monotonic() < deadline, f"hang guard: /health not {status} within {GUARD_S:g} s: {r.text}"
        threading.Event().wait(0.02)
    return r


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
    monkeypatch.setattr(embedded, "warm_up", lambda state=None: release.wait(GUARD_S))
    monkeypatch.delenv("REDIS_URL", raising=False)
    monkeypatch.setenv("NONHOLONOMIC_WARM_UP", "true")
    get_settings.cache_clear()
    try:
        with TestClient(create_app()) as client:
            r = client.get("/health")
            assert r.status_code == 503 and r.json()["status"] == "degraded"
            assert r.json()["workers"]["warm"] is False and "warm-up" in r.json()["detail"]
            release.set()
            r = _health_until(client, 200)
            assert r.json()["workers"]["warm"] is True and "detail" not in r.json()
    finally:
        release.set()
        get_settings.cache_clear()


def test_catalog_describes_the_ball(client):
    systems = client.get("/v1/systems").json()["systems"]
    ball = next(s for s in systems if s["kind"] == "chaplygin_ball")
    assert ball == client.get("/v1/systems/chaplygin_ball").json()
    params = {p["name"]: p for p in ball["parameters"]}
    assert (params["inertia"]["admissible"] == "> 0: 1e-12 .. 1e+12"
            and params["D"]["admissible"] == ">= 0, at most 1e+12")
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
    assert "did you mean" not in r.json()["detail"]  # nothing close to it
    r = client.get("/v1/systems/chaplygin_bal")
    assert r.status_code == 404 and "did you mean 'chaplygin_ball'?" in r.json()["detail"]


def test_the_generalized_chaplygin_entry_is_served_as_a_kind(client):
    """``GET /v1/systems/generalized_chaplygin``: the catalog's entry for a system of one's own (its own shape)."""
    r = client.get("/v1/systems/generalized_chaplygin")
    assert r.status_code == 200, r.text
    assert r.json() == client.get("/v1/systems").json()["generalized_chaplygin"]
    assert r.json()["example"]["system"]["kind"] == "generalized_chaplygin" and "L" in r.json()["fields"]
    r = client.get("/v1/systems/generalized_chaplygn")
    assert r.status_code == 404 and "did you mean 'generalized_chaplygin'?" in r.json()["detail"]


def test_a_misspelled_kind_gets_a_did_you_mean(client):
    r = client.post("/v1/jobs", json={"system": {"kind": "veselva"}, "t_final": 1.0})
    assert r.status_code == 422
    (kind,) = [e for e in r.json()["errors"] if e["field"] == "system.kind"]
    assert kind["reason"].endswith("did you mean 'veselova'?")
    r = client.post("/v1/jobs", json={"system": {"kind": "chaplygin_ball", "inertia": [2, 3, 4], "D": 0.5,
                                                 "potential": {"kind": "linaer"}}, "t_final": 1.0})
    (potential,) = [e for e in r.json()["errors"] if e["field"] == "system.potential.kind"]
    assert potential["reason"].endswith("did you mean 'linear'?")
    r = client.post("/v1/jobs", json={"system": {"kind": "pendulum"}, "t_final": 1.0})
    assert "did you mean" not in r.json()["errors"][0]["reason"]


def test_openapi_docs_are_served(client):
    assert client.get("/docs").status_code == 200
    spec = client.get("/openapi.json").json()
    assert {"/v1/jobs", "/v1/jobs/{job_id}", "/v1/systems", "/health", "/v1/maps/{name}", "/v1/paper/report",
            "/v1/paper/report/{job_id}"} <= set(spec["paths"])


def _slow(health, seconds: float, flip: dict | None = None):
    """A backend check that takes ``seconds`` (a loaded machine), answering ``flip`` once it is set."""
    import time

    def check() -> dict:
        time.sleep(seconds)
        return dict(flip["parts"]) if flip and "parts" in flip else health()

    return check


def test_health_answers_from_the_monitor_when_the_check_is_late(client):
    """Issue 19, item 7: under load the backend's check misses the route's deadline; /health answers at
    once with the monitor's latest check (refreshed in the background, its age in ``age_s``), not a
    503, and an outage still shows once a check reports it."""
    import threading

    backend = client.app.state.backend
    flip: dict = {}
    backend.health = _slow(backend.health, 0.2, flip)  # 8x the deadline: the route never waits for it
    ages = []
    for _ in range(10):
        r = client.get("/health")
        assert r.status_code == 200, r.text  # on main: 503 "no answer within 0.08 s" until a check ends
        ages.append(r.json()["age_s"])
        threading.Event().wait(0.1)
    assert max(ages) > 0  # answered from a check that began before the request
    flip["parts"] = {"ok": False, "mode": "embedded", "broker": "none (embedded)", "store": "unreachable",
                     "workers": {"threads": 1, "warm": True}, "detail": "the job store cannot be reached"}
    r = _health_until(client, 503)  # the monitor's next check reports it
    assert r.json()["store"] == "unreachable", r.text


def test_health_says_503_when_no_check_answers(client):
    """A backend whose check hangs (a store that does not answer): past STALE_S, 503 naming no host."""
    import threading

    from service.routes import health

    hang = threading.Event()
    backend = client.app.state.backend
    backend.health = lambda: hang.wait(2 * GUARD_S) and {}
    try:
        r = _health_until(client, 503)  # once the latest check is older than STALE_S
        assert r.json()["store"] == "unknown", r.text
        assert f"{health.STALE_S:g} s" in r.json()["detail"]
    finally:
        hang.set()


def test_the_event_loop_keeps_the_gil_under_load(client):
    """Issue 19, item 7: the threads of blocking request work are bounded (Starlette's default is 40,
    which starved the event loop) and start-up's objects are frozen out of full garbage collections."""
    import gc

    import anyio.to_thread

    settings = client.app.state.settings
    tokens = client.portal.call(lambda: anyio.to_thread.current_default_thread_limiter().total_tokens)
    assert tokens == settings.request_threads + settings.symbolic_workers < 40
    assert gc.get_freeze_count() > 0
