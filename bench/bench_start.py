"""Benchmark: how fast the service starts, and how fast it answers what it computed before.

Run from the repository root (queue mode needs Redis on 127.0.0.1:6379 and PostgreSQL on 127.0.0.1:5432)::

    .venv/bin/python bench/bench_start.py            # warm restarts (caches filled by a first start here)
    .venv/bin/python bench/bench_start.py --cold     # also a first start with empty caches (~1 min more)

Measured, each from a fresh process, on this machine (its load printed beside):

1. ``--cold`` only: a first start, with empty caches (a memo folder and a heyoka cache of its own):
   ``scripts/serve.py`` (embedded) until ``GET /health`` is 200, and the first Chaplygin-ball job
   (t = 100) after that. This start derives and compiles everything and fills the caches.
2. A restart with the caches filled: ``scripts/serve.py`` until ``/health`` 200 (target 10 s), then
   the first ball job (t = 100) from submission to ``succeeded`` (target 2 s).
3. The paper report twice: the first computed, the second read back (target 5 s), and the
   ``/v1/hamiltonize`` example twice (the second answered from the memo: ``Cache-Status: hit``).
4. Queue mode: a Celery worker (2 pool processes) and the API started together until ``/health`` is
   200 (a warm worker on the queue; target 10 s), then the first ball job.

The reference for 2 and 4 is 1, the same start with empty caches (``--cold``), measured in the same run.
A miss is reported, never turned into a non-zero exit status.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import argparse  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import secrets  # noqa: E402
import shutil  # noqa: E402
import signal  # noqa: E402
import socket  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections.abc import Mapping  # noqa: E402
from typing import Any  # noqa: E402

import httpx  # noqa: E402

BIN = ROOT / ".venv" / "bin"
BALL_JOB = {"system": {"kind": "chaplygin_ball", "inertia": [1.0, 1.5, 2.0], "D": 1.0},
            "initial_state": {"M": [0.5, 0.3, -0.2], "gamma": [0.0, 0.6, 0.8]}, "t_final": 100.0}
TARGET_HEALTH_S, TARGET_FIRST_JOB_S, TARGET_REPORT_S = 10.0, 2.0, 5.0


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def load() -> str:
    return "load " + " ".join(f"{x:.2f}" for x in os.getloadavg())


def verdict(value: float, target: float) -> str:
    return f"{value:6.2f} s  target <= {target:g} s: {'PASS' if value <= target else 'MISS'}"


class Service:
    """Processes started with one environment, stopped together (their process groups)."""

    def __init__(self, env: Mapping[str, str], log: Path) -> None:
        self.env = {**os.environ, **env}
        self.log = log
        self.procs: list[subprocess.Popen] = []

    def start(self, cmd: list[str]) -> None:
        self.procs.append(subprocess.Popen(cmd, cwd=ROOT, env=self.env, stdout=self.log.open("a"),
                                           stderr=subprocess.STDOUT, start_new_session=True))

    def stop(self) -> None:
        for p in self.procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in self.procs:
            try:
                p.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait(5)


def until_healthy(base: str, since: float, timeout: float = 600.0) -> float:
    while time.monotonic() - since < timeout:
        try:
            if httpx.get(f"{base}/health", timeout=5).status_code == 200:
                return time.monotonic() - since
        except httpx.HTTPError:
            pass
        time.sleep(0.05)
    raise TimeoutError(f"{base}/health not 200 within {timeout} s")


def run_job(client: httpx.Client, path: str, body: dict[str, Any] | None, timeout: float = 900.0) -> tuple[float, dict]:
    start = time.monotonic()
    r = client.post(path, json=body)
    r.raise_for_status()
    location = r.headers["location"]
    while time.monotonic() - start < timeout:
        view = client.get(location).json()
        if view["status"] in ("succeeded", "failed", "cancelled"):
            if view["status"] != "succeeded":
                raise RuntimeError(f"{path}: {view['status']}: {view.get('error')}")
            return time.monotonic() - start, view
        time.sleep(0.02)
    raise TimeoutError(location)


def embedded_start(env: dict[str, str], log: Path) -> tuple[Service, str, float, float]:
    """``scripts/serve.py`` (the README's command) until /health 200, then the first ball job."""
    port = free_port()
    service = Service({**env, "REDIS_URL": ""}, log)
    since = time.monotonic()
    service.start([sys.executable, "scripts/serve.py", "--port", str(port)])
    base = f"http://127.0.0.1:{port}"
    try:
        health = until_healthy(base, since)
        with httpx.Client(base_url=base, timeout=120) as client:
            first, _ = run_job(client, "/v1/jobs", BALL_JOB)
    except BaseException:  # a timeout or a failed job: no server left behind
        service.stop()
        raise
    return service, base, health, first


def report_twice(base: str) -> None:
    with httpx.Client(base_url=base, timeout=600) as client:
        for attempt in ("first", "second"):
            seconds, view = run_job(client, "/v1/paper/report", None)
            computed = view["result"]["computed"]
            line = (verdict(seconds, TARGET_REPORT_S) if attempt == "second" else f"{seconds:6.2f} s")
            print(f"  paper report, {attempt}: {line}  (cached: {computed['cached']}, computed in "
                  f"{computed['seconds']:.1f} s)")
        example = client.get("/v1/hamiltonize/examples").json()["examples"]["chaplygin_ball"]
        for attempt in ("first", "second"):
            start = time.monotonic()
            r = client.post("/v1/hamiltonize", json=example)
            seconds = time.monotonic() - start
            print(f"  /v1/hamiltonize example, {attempt}: {seconds:6.2f} s  (HTTP {r.status_code}, "
                  f"Cache-Status: {r.headers.get('cache-status')})")


def queue_start(env: dict[str, str], log: Path) -> tuple[float, float]:
    queue = f"bench-start-{secrets.token_hex(4)}"
    port = free_port()
    qenv = {**env, "REDIS_URL": "redis://127.0.0.1:6379/0", "NONHOLONOMIC_QUEUE": queue}
    service = Service(qenv, log)
    since = time.monotonic()
    service.start([str(BIN / "celery"), "-A", "workers.celery_app:app", "worker", "-Q", queue, "--pool", "prefork",
                   "--concurrency", "2", "--hostname", f"{queue}@%h", "--without-gossip", "--without-mingle"])
    service.start([str(BIN / "uvicorn"), "service.main:app", "--host", "127.0.0.1", "--port", str(port)])
    base = f"http://127.0.0.1:{port}"
    try:
        health = until_healthy(base, since)
        with httpx.Client(base_url=base, timeout=120) as client:
            first, _ = run_job(client, "/v1/jobs", BALL_JOB)
    finally:
        service.stop()
    return health, first


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cold", action="store_true", help="also measure a first start with empty caches")
    parser.add_argument("--no-queue", action="store_true", help="skip queue mode")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench-start-"))
    log = work / "service.log"
    env = {"NONHOLONOMIC_DATA_DIR": str(work / "data")}
    print(f"bench_start ({os.cpu_count()} cores, {load()}); logs in {log}")
    if args.cold:
        cold = {**env, "NONHOLONOMIC_CACHE_DIR": str(work / "memo"), "XDG_CACHE_HOME": str(work / "cache"),
                "HOME": str(work / "home")}
        service, _, health, first = embedded_start(cold, log)
        service.stop()
        print(f"first start, empty caches ({load()}): /health 200 after {health:6.2f} s; first ball job "
              f"{first:.2f} s")
    service, base, health, first = embedded_start(env, log)  # fills the default caches if they are empty
    service.stop()
    service, base, health, first = embedded_start(env, log)
    print(f"embedded restart, caches filled ({load()}):")
    print(f"  /health 200 after   {verdict(health, TARGET_HEALTH_S)}")
    print(f"  first ball job      {verdict(first, TARGET_FIRST_JOB_S)}")
    try:
        report_twice(base)
    finally:
        service.stop()
    if not args.no_queue:
        health, first = queue_start(env, log)
        print(f"queue mode, worker (2 processes) and API started, caches filled ({load()}):")
        print(f"  /health 200 after   {verdict(health, TARGET_HEALTH_S)}")
        print(f"  first ball job      {verdict(first, TARGET_FIRST_JOB_S)}")
    print(json.dumps({"load": os.getloadavg()}))
    for part in ("data", "memo", "cache", "home"):  # the log stays
        shutil.rmtree(work / part, ignore_errors=True)


if __name__ == "__main__":
    main()
