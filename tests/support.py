"""Starting real processes for tests and benchmarks: a Celery worker, the API under uvicorn."""

from __future__ import annotations

import atexit
import contextlib
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator, Mapping
from pathlib import Path

import httpx
import redis
from prometheus_client.parser import text_string_to_metric_families

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
TEST_REDIS_URL = os.environ.get("NONHOLONOMIC_TEST_REDIS_URL", "redis://127.0.0.1:6379/15")
#: Queue mode's job store in the tests (created if missing; the README's test command starts PostgreSQL).
TEST_DATABASE_URL = os.environ.get("NONHOLONOMIC_TEST_DATABASE_URL",
                                   "postgresql+psycopg://postgres@127.0.0.1:5432/nonholonomic_test")


def fresh_database_url() -> str:
    """The URL of a PostgreSQL database of its own (created by the first JobStore.migrate): a test that
    lists every job sees only its own."""
    import uuid

    from sqlalchemy.engine import make_url

    url = make_url(TEST_DATABASE_URL)
    return url.set(database=f"{url.database}_{uuid.uuid4().hex[:10]}").render_as_string(hide_password=False)


#: Databases named by :func:`queue_database_url` in this process (dropped by :func:`drop_queue_databases`).
_QUEUE_DATABASES: set[str] = set()


def queue_database_url(queue: str) -> str:
    """The job store of the stack (API and workers) on ``queue``: a PostgreSQL database of its own, named
    after the queue, so that no other test's sweep, listing or cancellation reaches its jobs (an API with
    keys lists and may cancel every job without an owner in its store). Created by the first
    ``JobStore.migrate``; dropped when this process exits (:func:`drop_queue_databases`)."""
    from sqlalchemy.engine import make_url

    url = make_url(TEST_DATABASE_URL)
    name = "".join(c if c.isalnum() else "_" for c in queue.lower())
    rendered = url.set(database=f"{url.database}_q_{name}"[:63]).render_as_string(hide_password=False)
    _QUEUE_DATABASES.add(rendered)
    return rendered


def drop_queue_databases() -> None:
    """Drop the databases this process named with :func:`queue_database_url` (at its exit: its stacks
    are stopped, or their connections are ended)."""
    while _QUEUE_DATABASES:
        try:
            drop_database(_QUEUE_DATABASES.pop())
        except Exception:  # noqa: BLE001 - PostgreSQL away (a test stopped it): left for the next run
            pass


def drop_database(url: str) -> None:
    from sqlalchemy import create_engine, text
    from sqlalchemy.engine import make_url

    target = make_url(url)
    admin = create_engine(target.set(database="postgres"), isolation_level="AUTOCOMMIT")
    with admin.connect() as connection:
        connection.execute(text(f'DROP DATABASE IF EXISTS "{target.database}" WITH (FORCE)'))
    admin.dispose()


atexit.register(drop_queue_databases)


def redis_available(url: str = TEST_REDIS_URL) -> bool:
    try:
        return bool(redis.Redis.from_url(url, socket_timeout=1).ping())
    except redis.RedisError:
        return False


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _env(extra: Mapping[str, str]) -> dict[str, str]:
    """The environment of a started process: ours without the service's settings, then ``extra``; a job
    store of its own unless ``extra`` names one: a fresh folder (embedded), the queue's own database
    (queue mode, :func:`queue_database_url`)."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith("NONHOLONOMIC_") and k not in ("REDIS_URL", "DATABASE_URL")}
    env["NONHOLONOMIC_DATA_DIR"] = tempfile.mkdtemp(prefix="nonholonomic-store-")
    named = "DATABASE_URL" in extra or "NONHOLONOMIC_DATABASE_URL" in extra
    env["NONHOLONOMIC_DATABASE_URL"] = "" if named or not extra.get("REDIS_URL") else \
        queue_database_url(extra.get("NONHOLONOMIC_QUEUE", "nonholonomic"))
    # the suite starts ~60 APIs, most never asked a symbolic question: their fork servers start on demand
    env["NONHOLONOMIC_SYMBOLIC_PRESTART"] = "false"
    # a worker serves its metrics only where a test asks (many workers run at once: one port each)
    env["NONHOLONOMIC_WORKER_METRICS_PORT"] = "0"
    env.update(extra)
    return env


def start_worker(redis_url: str, queue: str, log: Path, concurrency: int = 1,
                 extra_env: Mapping[str, str] | None = None, warm_up: bool = False) -> subprocess.Popen:
    """A real Celery worker process (prefork pool) consuming ``queue``; its pool processes compile every
    system before their first job only with ``warm_up`` (~2 s of CPU each with warm caches: a test's
    jobs compile the one system they use)."""
    env = _env({"REDIS_URL": redis_url, "NONHOLONOMIC_QUEUE": queue, "NONHOLONOMIC_WARM_UP": str(warm_up).lower(),
                **(extra_env or {})})
    cmd = [str(BIN / "celery"), "-A", "workers.celery_app:app", "worker", "-Q", queue, "--pool", "prefork",
           "--concurrency", str(concurrency), "--loglevel", "INFO", "--hostname", f"{queue}@%h", "--without-gossip",
           "--without-mingle"]
    return subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=log.open("w"), stderr=subprocess.STDOUT)


def start_api(port: int, log: Path, env: Mapping[str, str]) -> subprocess.Popen:
    """The API under uvicorn on 127.0.0.1:``port``; ``env`` decides the mode (``REDIS_URL`` or not)."""
    cmd = [str(BIN / "uvicorn"), "service.main:app", "--host", "127.0.0.1", "--port", str(port)]
    return subprocess.Popen(cmd, cwd=ROOT, env=_env(env), stdout=log.open("w"), stderr=subprocess.STDOUT)


@contextlib.contextmanager
def embedded_api(logs: Path, env: Mapping[str, str] | None = None) -> Iterator[str]:
    """The API under uvicorn in embedded mode (no Redis, no warm-up) on a free port; yields its base URL,
    prints the end of its log if the block fails, stops it afterwards."""
    port = free_port()
    api = start_api(port, logs / "api.log", {"REDIS_URL": "", "NONHOLONOMIC_WARM_UP": "false", **(env or {})})
    url = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(url, timeout=120)
        yield url
    except Exception:
        print((logs / "api.log").read_text()[-4000:])
        raise
    finally:
        stop(api)


class HangGuard(AssertionError):
    """A test's work did not end within its hang guard (a failure of the test, never its result)."""


@contextlib.contextmanager
def hang_guard(seconds: float, what: str) -> Iterator[None]:
    """Interrupt the block if it runs past ``seconds`` (SIGALRM: a parse or loop that never ends fails
    with :class:`HangGuard` instead of holding the suite); nothing is measured or asserted when it ends
    in time. Outside the main thread (no signals there) the block runs unguarded."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum, frame):  # type: ignore[no-untyped-def]
        raise HangGuard(f"hang guard: {what} still running after {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, interrupt)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def wait_until(predicate, timeout: float, what: str, interval: float = 0.1) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if predicate():
                return
        except (httpx.HTTPError, redis.RedisError):
            pass
        time.sleep(interval)
    raise TimeoutError(f"timed out after {timeout:g} s waiting for {what}")


def wait_healthy(base: str, timeout: float = 120.0) -> None:
    """Wait until ``GET /health`` answers 200 (API up; in queue mode a worker serves the queue)."""
    wait_until(lambda: httpx.get(f"{base}/health", timeout=5).status_code == 200, timeout, f"{base}/health")


def stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)


def poll_job(client: httpx.Client, location: str, timeout: float = 60.0, interval: float = 0.002,
             max_interval: float = 0.1) -> dict:
    """Poll a job until it is terminal; returns its last view. The wait between polls starts at
    ``interval`` and doubles up to ``max_interval``: a quick job is seen at once, and a long one is not
    asked hundreds of times a second (each poll is CPU taken from the job, and in-process the GIL)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        view = client.get(location).json()
        if view["status"] in ("succeeded", "failed", "cancelled"):
            return view
        time.sleep(interval)
        interval = max(interval, min(2 * interval, max_interval))
    raise TimeoutError(f"job {location} not finished after {timeout:g} s")


#: Each metric sample as ``(name, labels)``: its value.
Samples = dict[tuple[str, frozenset[tuple[str, str]]], float]


def metric_samples(text: str) -> Samples:
    """The samples of a Prometheus text exposition (``/metrics``)."""
    return {(sample.name, frozenset(sample.labels.items())): sample.value
            for family in text_string_to_metric_families(text) for sample in family.samples}


def metric_total(samples: Samples | None, name: str, **labels: str) -> float:
    """The sum of the samples ``name`` whose labels include ``labels`` (others, such as ``pid``, summed over;
    0 when there are none)."""
    wanted = set(labels.items())
    return sum(value for (sample, have), value in (samples or {}).items() if sample == name and wanted <= have)
