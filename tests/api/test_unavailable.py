"""Queue mode with no reachable Redis: 503 problems, not 500s."""

from __future__ import annotations

from fastapi.testclient import TestClient

from schemas.settings import get_settings
from service.main import create_app
from tests.api.conftest import job
from tests.support import TEST_DATABASE_URL, free_port


def test_unreachable_broker_gives_503_problems(monkeypatch):
    monkeypatch.setenv("REDIS_URL", f"redis://127.0.0.1:{free_port()}/0")
    monkeypatch.setenv("NONHOLONOMIC_DATABASE_URL", TEST_DATABASE_URL)
    get_settings.cache_clear()
    try:
        with TestClient(create_app(), raise_server_exceptions=False) as client:
            health = client.get("/health")
            assert health.status_code == 503 and health.json()["status"] == "degraded"
            assert health.json()["broker"].startswith("unreachable")
            r = client.post("/v1/jobs", json=job())
            assert r.status_code == 503 and r.headers["content-type"] == "application/problem+json"
            assert r.json()["type"] == "/problems/unavailable"
            assert client.get("/v1/jobs/some-id").status_code == 503
    finally:
        get_settings.cache_clear()
