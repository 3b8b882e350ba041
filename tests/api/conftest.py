"""The API in embedded mode through FastAPI's TestClient."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from schemas.settings import get_settings
from service.main import create_app

BALL = {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7}
STATE = {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}


def job(**overrides) -> dict:
    body = {"system": dict(BALL), "initial_state": dict(STATE), "t_final": 20.0, "samples": 51}
    body.update(overrides)
    return body


@pytest.fixture()
def client(monkeypatch) -> Iterator[TestClient]:
    monkeypatch.delenv("REDIS_URL", raising=False)
    monkeypatch.delenv("NONHOLONOMIC_REDIS_URL", raising=False)
    monkeypatch.setenv("NONHOLONOMIC_WARM_UP", "false")
    monkeypatch.setenv("NONHOLONOMIC_MAX_T_FINAL", "1e9")
    monkeypatch.setenv("NONHOLONOMIC_MAX_SAMPLES", "5001")
    get_settings.cache_clear()
    with TestClient(create_app()) as c:
        yield c
    get_settings.cache_clear()


@pytest.fixture()
def cached_client(monkeypatch, tmp_path):
    """The embedded API with a memo of its own (``tmp_path``): the first answer is computed, not read."""
    from nonholonomic import memo

    previous = memo.installed()
    monkeypatch.delenv("REDIS_URL", raising=False)
    monkeypatch.setenv("NONHOLONOMIC_WARM_UP", "false")
    monkeypatch.setenv("NONHOLONOMIC_CACHE_DIR", str(tmp_path))
    get_settings.cache_clear()
    try:
        with TestClient(create_app()) as c:
            yield c
    finally:
        get_settings.cache_clear()
        memo.install(previous)
