"""docker-compose.yml (no Docker engine runs here: its content is checked instead)."""

from __future__ import annotations

import os
import re
import shutil
import socket
import subprocess
from pathlib import Path

import pytest
import yaml

from schemas.settings import Settings
from tests.support import ROOT, free_port, wait_until


def _compose() -> dict:
    return yaml.safe_load((ROOT / "docker-compose.yml").read_text())


def _seconds(duration: str) -> float:
    units = {"s": 1, "m": 60, "h": 3600}
    return sum(float(n) * units[u] for n, u in re.findall(r"(\d+(?:\.\d+)?)([smh])", duration))


def _redis_script() -> str:
    """The shell command the redis container runs, as its shell sees it (compose's ``$$`` is ``$``)."""
    command = _compose()["services"]["redis"]["command"]
    assert command[:2] == ["sh", "-c"] and len(command) == 3
    return command[2].replace("$$", "$")


def test_redis_has_a_password_off_its_command_line_and_an_append_only_file():
    redis = _compose()["services"]["redis"]
    script = _redis_script()
    # the password is configuration read from standard input, never an argument
    assert "--requirepass" not in script and "REDIS_PASSWORD" not in script.split("<<")[0]
    assert re.search(r'^requirepass "\$REDIS_PASSWORD"$', script, re.M)
    assert script.startswith("exec docker-entrypoint.sh redis-server - ")
    assert "--appendonly yes" in script
    assert redis["environment"]["REDIS_PASSWORD"].startswith("${REDIS_PASSWORD:?")
    assert any(v.endswith(":/data") for v in redis["volumes"])


@pytest.mark.skipif(shutil.which("redis-server") is None, reason="no redis-server here")
def test_the_redis_command_really_requires_the_password_and_hides_it(tmp_path):
    """The compose command, run with the local redis-server (the image's entrypoint only drops
    privileges): a client without the password is refused, and the password is in no argv."""
    port, password = free_port(), "h4-" + os.urandom(8).hex()
    script = _redis_script().replace("docker-entrypoint.sh ", "").replace(
        "redis-server - ", f"redis-server - --port {port} --bind 127.0.0.1 --dir {tmp_path} --save '' ")
    proc = subprocess.Popen(["sh", "-c", script], env={**os.environ, "REDIS_PASSWORD": password},
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_until(lambda: _redis_answer(port, None) != "", 30, "redis to start")
        assert _redis_answer(port, None).startswith("-NOAUTH")
        assert _redis_answer(port, password) == "+PONG"
        argv = Path(f"/proc/{proc.pid}/cmdline").read_bytes()  # exec: the shell became redis-server
        assert password.encode() not in argv and b"redis-server" in argv
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def _redis_answer(port: int, password: str | None) -> str:
    """The first line of Redis' answer to PING (after AUTH when a password is given); "" if closed."""
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
            if password is not None:
                s.sendall(f"AUTH {password}\r\n".encode())
                s.recv(100)
            s.sendall(b"PING\r\n")
            return s.recv(100).decode().split("\r\n")[0]
    except OSError:
        return ""


def test_the_api_is_published_on_loopback_only_through_the_proxy():
    services = _compose()["services"]
    assert "ports" not in services["api"] and services["api"]["expose"] == ["8000"]
    published = [p for service in services.values() for p in service.get("ports", [])]
    assert published == ["127.0.0.1:8000:8000"] and services["proxy"]["ports"] == published
    assert "./deploy/nginx.conf:/etc/nginx/nginx.conf:ro" in services["proxy"]["volumes"]
    # uvicorn trusts X-Forwarded-For only because nothing but the proxy reaches it
    assert "--proxy-headers" in services["api"]["command"]


def test_the_proxy_bounds_slow_clients():
    conf = (ROOT / "deploy" / "nginx.conf").read_text()
    settings = dict(re.findall(r"^\s*(client_header_timeout|client_body_timeout|keepalive_timeout|limit_conn)\s+"
                               r"([^;]+);", conf, re.M))
    assert _seconds(settings["client_header_timeout"]) <= 30 and _seconds(settings["client_body_timeout"]) <= 30
    assert _seconds(settings["keepalive_timeout"]) <= 5
    assert re.search(r"^\s*proxy_request_buffering on;", conf, re.M) and "server api:8000;" in conf
    # the proxy's body limit is the API's (its 413 is the API's problem+json, served by the proxy)
    body_limit = re.search(r"^\s*client_max_body_size (\d+)m;", conf, re.M)
    assert body_limit and int(body_limit[1]) << 20 == Settings().max_body_bytes
    assert "NONHOLONOMIC_MAX_BODY_BYTES" not in _compose()["services"]["api"]["environment"]
    assert re.search(r"error_page 413 @too_large;", conf) and "application/problem+json" in conf
    upstream_idle = re.search(r"upstream api \{[^}]*keepalive_timeout (\d+)s;", conf, re.S)
    api_idle = _compose()["services"]["api"]["command"]
    assert upstream_idle and int(upstream_idle[1]) < int(api_idle[api_idle.index("--timeout-keep-alive") + 1])


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
    assert (url.startswith("postgresql+psycopg://nonholonomic:${POSTGRES_PASSWORD:?")
            and url.endswith("@postgres:5432/nonholonomic"))
    for name in ("api", "worker"):
        assert compose["services"][name]["depends_on"]["postgres"]["condition"] == "service_healthy"


def test_workers_expose_their_metrics_port_and_log_json():
    worker = _compose()["services"]["worker"]
    env = worker["environment"]
    port = Settings(worker_metrics_port=int(env["NONHOLONOMIC_WORKER_METRICS_PORT"])).worker_metrics_port
    assert port > 0 and str(port) in worker["expose"] and env["NONHOLONOMIC_LOG_FORMAT"] == "json"
    assert "9191" not in str(worker.get("ports", []))  # not published on the host
