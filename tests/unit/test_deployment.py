"""docker-compose.yml (no Docker engine runs here: its content is checked instead)."""

from __future__ import annotations

import re

import yaml

from schemas.settings import Settings
from tests.support import ROOT


def _compose() -> dict:
    return yaml.safe_load((ROOT / "docker-compose.yml").read_text())


def _seconds(duration: str) -> float:
    units = {"s": 1, "m": 60, "h": 3600}
    return sum(float(n) * units[u] for n, u in re.findall(r"(\d+(?:\.\d+)?)([smh])", duration))


def test_redis_has_a_password_and_an_append_only_file():
    redis = _compose()["services"]["redis"]
    command = redis["command"]
    assert command[command.index("--requirepass") + 1].startswith("${REDIS_PASSWORD:?")
    assert command[command.index("--appendonly") + 1] == "yes"
    assert any(v.endswith(":/data") for v in redis["volumes"])


def test_api_and_workers_share_settings_with_the_password_in_the_url():
    services = _compose()["services"]
    assert services["api"]["environment"] == services["worker"]["environment"]
    env = services["worker"]["environment"]
    assert env["REDIS_URL"].startswith("redis://:${REDIS_PASSWORD:?")
    settings = Settings(job_soft_time_limit_s=float(env["NONHOLONOMIC_JOB_SOFT_TIME_LIMIT_S"]),
                        job_time_limit_s=float(env["NONHOLONOMIC_JOB_TIME_LIMIT_S"]),
                        visibility_timeout_s=float(env["NONHOLONOMIC_VISIBILITY_TIMEOUT_S"]))
    assert settings.job_soft_time_limit_s < settings.job_time_limit_s < settings.visibility_timeout_s


def test_workers_get_a_stop_grace_period_above_the_hard_time_limit():
    services = _compose()["services"]
    worker = services["worker"]
    hard_limit = float(worker["environment"]["NONHOLONOMIC_JOB_TIME_LIMIT_S"])
    assert worker["stop_signal"] == "SIGTERM" and _seconds(worker["stop_grace_period"]) > hard_limit


def test_api_keys_and_a_rate_limit_are_on():
    env = _compose()["services"]["api"]["environment"]
    assert env["NONHOLONOMIC_API_KEYS"].startswith("${NONHOLONOMIC_API_KEYS:?")
    assert int(env["NONHOLONOMIC_RATE_LIMIT_PER_MINUTE"]) > 0


def test_postgresql_holds_the_jobs_and_both_processes_use_it():
    compose = _compose()
    postgres = compose["services"]["postgres"]
    assert postgres["image"].startswith("postgres:") and any(v.endswith("/var/lib/postgresql/data")
                                                             for v in postgres["volumes"])
    url = compose["services"]["worker"]["environment"]["DATABASE_URL"]
    assert url.startswith("postgresql+psycopg://nonholonomic:${POSTGRES_PASSWORD:?") and url.endswith("@postgres:5432/nonholonomic")
    for name in ("api", "worker"):
        assert compose["services"][name]["depends_on"]["postgres"]["condition"] == "service_healthy"
