"""Durable jobs and ensembles. Embedded mode: the API killed (SIGKILL) or stopped (SIGTERM) and started
again on the same SQLite file loses no job, no ensemble and no result; the jobs and ensemble chunks it
had not finished run again. Queue mode: Redis
restarted empty, PostgreSQL stopped while a job runs, the API killed: no job and no result lost, work
sent during an outage answered 503 and accepted after it."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import tempfile
import time
import uuid
from pathlib import Path

import httpx
import pytest

from tests.support import (
    TEST_REDIS_URL,
    drop_database,
    free_port,
    fresh_database_url,
    poll_job,
    redis_available,
    start_api,
    start_worker,
    stop,
    wait_healthy,
    wait_until,
)

pytestmark = pytest.mark.integration

BODY = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
        "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 20.0, "samples": 11}
#: About 5 s on one core: running (and one more queued behind it) when the API is stopped.
LONG = {**BODY, "t_final": 2e6}
#: Four members in two chunks.
ENSEMBLE = {"system": BODY["system"], "t_final": 20.0, "chunk_size": 2,
            "members": {"sample": {"count": 4, "seed": 3, "level": {"energy": 1.0}}}}
#: Hang guard (seconds) of each wait: far above the seconds a quiet machine needs (an API's start, a job,
#: a first compile), never a result.
GUARD_S = 300.0


def _without_times(value):
    if isinstance(value, dict):
        return {k: _without_times(v) for k, v in value.items() if k != "wall_time_s"}
    return [_without_times(v) for v in value] if isinstance(value, list) else value


def _members(client: httpx.Client, location: str) -> list[dict]:
    """The members' results (without their wall times)."""
    return _without_times(client.get(f"{location}/members", params={"limit": 100}).json()["members"])


def _same_ensemble(client: httpx.Client, location: str, before: dict, members: list[dict]) -> None:
    """The ensemble as it was (its record, summary and members bit for bit)."""
    assert client.get(location).json() == before
    assert _members(client, location) == members


def _api(port: int, data_dir: Path, log: Path):
    return start_api(port, log, {"REDIS_URL": "", "NONHOLONOMIC_WARM_UP": "false", "NONHOLONOMIC_MAX_T_FINAL": "1e9",
                                 "NONHOLONOMIC_DATA_DIR": str(data_dir)})


@pytest.mark.parametrize("how", [signal.SIGKILL, signal.SIGTERM])
def test_an_api_restart_loses_no_job_and_no_result(tmp_path, how):
    port, data = free_port(), tmp_path / "data"
    base = f"http://127.0.0.1:{port}"
    api = _api(port, data, tmp_path / "api-1.log")
    try:
        wait_healthy(base, timeout=GUARD_S)
        with httpx.Client(base_url=base, timeout=10) as client:
            done = poll_job(client, client.post("/v1/jobs", json=BODY).headers["location"], timeout=GUARD_S)
            assert done["status"] == "succeeded"
            finished = client.post("/v1/ensembles", json=ENSEMBLE).headers["location"]
            finished_view = poll_job(client, finished, timeout=GUARD_S)
            assert finished_view["status"] == "succeeded"
            finished_members = _members(client, finished)
            running = client.post("/v1/jobs", json=LONG).headers["location"]
            queued = client.post("/v1/jobs", json=LONG).headers["location"]  # one thread: waits behind it
            cancelled = client.post("/v1/jobs", json=LONG).headers["location"]
            assert client.delete(cancelled).status_code == 202
            pending = client.post("/v1/ensembles", json=ENSEMBLE).headers["location"]  # waits too
            wait_until(lambda: client.get(running).json()["status"] == "running", GUARD_S,
                       "the long job to run (a hang guard)")
            assert client.get(queued).json()["status"] == "queued"
            assert client.get(pending).json()["status"] == "queued"
        api.send_signal(how)
        api.wait(GUARD_S)
    finally:
        stop(api)

    api = _api(port, data, tmp_path / "api-2.log")
    try:
        wait_healthy(base, timeout=GUARD_S)
        with httpx.Client(base_url=base, timeout=10) as client:
            again = client.get(f"/v1/jobs/{done['id']}").json()
            assert again == done  # the same record and result, bit for bit
            for location in (running, queued):  # run again after the restart
                view = poll_job(client, location, timeout=GUARD_S)
                assert view["status"] == "succeeded", view["error"]
            assert client.get(cancelled).json()["status"] == "cancelled"
            listed = {item["location"] for item in client.get("/v1/jobs").json()["items"]}
            assert {f"/v1/jobs/{done['id']}", running, queued, cancelled} <= listed
            _same_ensemble(client, finished, finished_view, finished_members)
            resumed = poll_job(client, pending, timeout=GUARD_S)  # its chunks run after the restart
            assert resumed["status"] == "succeeded" and resumed["members_done"] == 4
            assert _members(client, pending) == finished_members  # the same members, the same numbers
    except Exception:
        print((tmp_path / "api-1.log").read_text()[-3000:], (tmp_path / "api-2.log").read_text()[-3000:])
        raise
    finally:
        stop(api)


# --------------------------------------------------------------------------------------------------
# queue mode: Redis, PostgreSQL and the API restarted under a worker


def _redis_server(port: int, log: Path) -> subprocess.Popen:
    """A Redis of the test's own that keeps nothing on disk (a restart loses every message)."""
    binary = shutil.which("redis-server") or "/usr/bin/redis-server"
    return subprocess.Popen([binary, "--port", str(port), "--bind", "127.0.0.1", "--save", "", "--appendonly", "no"],
                            stdout=log.open("w"), stderr=subprocess.STDOUT)


def _postgres(data: Path, port: int, start: bool) -> None:
    """Start or stop (fast) a PostgreSQL cluster of the test's own in ``data`` (created on first start)."""
    bindir = sorted(Path("/usr/lib/postgresql").glob("*/bin/pg_ctl"))[-1].parent
    as_postgres = ["runuser", "-u", "postgres", "--"] if os.geteuid() == 0 else []
    if start and not (data / "PG_VERSION").exists():
        data.mkdir()
        if as_postgres:
            shutil.chown(data, "postgres", "postgres")
        subprocess.run([*as_postgres, str(bindir / "initdb"), "-D", str(data), "-A", "trust", "-U", "postgres"],
                       check=True, stdout=subprocess.DEVNULL)
    command = (["-l", str(data / "server.log"), "-w", "-o", f"-p {port} -k /tmp -c listen_addresses=127.0.0.1", "start"]
               if start else ["-w", "-m", "fast", "stop"])
    subprocess.run([*as_postgres, str(bindir / "pg_ctl"), "-D", str(data), *command], check=True,
                   stdout=subprocess.DEVNULL)


class QueueStack:
    """The API and a worker on a queue of their own, with the given Redis and database."""

    def __init__(self, tmp: Path, redis_url: str, database_url: str) -> None:
        self.tmp, self.queue = tmp, f"durable-{uuid.uuid4().hex[:8]}"
        self.env = {"REDIS_URL": redis_url, "NONHOLONOMIC_QUEUE": self.queue, "NONHOLONOMIC_DATABASE_URL": database_url,
                    "NONHOLONOMIC_MAX_T_FINAL": "1e9"}
        self.port = free_port()
        self.base = f"http://127.0.0.1:{self.port}"
        self.api: subprocess.Popen | None = None
        self.worker: subprocess.Popen | None = None
        self.client = httpx.Client(base_url=self.base, timeout=10)
        self._logs = 0

    def _log(self, name: str) -> Path:
        self._logs += 1
        return self.tmp / f"{self._logs:02d}-{name}.log"

    def start_api(self) -> None:
        self.api = start_api(self.port, self._log("api"), self.env)
        wait_until(lambda: self.client.get("/health").status_code in (200, 503), GUARD_S, "the API (a hang guard)")

    def start_worker(self) -> None:
        self.worker = start_worker(self.env["REDIS_URL"], self.queue, self._log("worker"),
                                   extra_env={k: v for k, v in self.env.items() if k != "REDIS_URL"})
        wait_healthy(self.base, timeout=GUARD_S)

    def stop(self) -> None:
        for proc in (self.api, self.worker):
            if proc is not None:
                stop(proc)
        self.client.close()

    def logs(self) -> str:
        return "\n".join(f"--- {p.name}\n{p.read_text()[-2500:]}" for p in sorted(self.tmp.glob("*.log")))

    def whole_logs(self) -> str:
        """Every log of the test whole (``logs`` keeps their ends only)."""
        return "\n".join(p.read_text() for p in sorted(self.tmp.glob("*.log")))

    def wait_logged(self, text: str) -> None:
        """Wait until a log holds ``text``: a process logs what it did a moment after doing it (a worker's
        sweep logs the jobs it sent again after sending them, which may run and end first)."""
        wait_until(lambda: text in self.whole_logs(), GUARD_S, f"{text!r} in the logs (a hang guard)")


def test_a_redis_restart_loses_no_job_and_no_result(tmp_path):
    redis_port = free_port()
    server = _redis_server(redis_port, tmp_path / "00-redis.log")
    database = fresh_database_url()
    stack = QueueStack(tmp_path, f"redis://127.0.0.1:{redis_port}/0", database)
    try:
        wait_until(lambda: redis_available(stack.env["REDIS_URL"]), 30, "the test's Redis")
        stack.start_api()
        stack.start_worker()
        done = poll_job(stack.client, stack.client.post("/v1/jobs", json=BODY).headers["location"], timeout=GUARD_S)
        assert done["status"] == "succeeded"
        finished = stack.client.post("/v1/ensembles", json=ENSEMBLE).headers["location"]
        finished_view = poll_job(stack.client, finished, timeout=GUARD_S)
        assert finished_view["status"] == "succeeded"
        finished_members = _members(stack.client, finished)
        stop(stack.worker)  # no worker: the next job and ensemble wait in Redis
        waiting = stack.client.post("/v1/jobs", json=BODY).headers["location"]
        waiting_ensemble = stack.client.post("/v1/ensembles", json=ENSEMBLE).headers["location"]

        server.kill()  # Redis gone, with every message and every progress
        server.wait(10)
        refused = stack.client.post("/v1/jobs", json=BODY)
        assert refused.status_code == 503 and refused.json()["type"] == "/problems/unavailable"
        assert stack.client.get("/health").status_code == 503
        assert stack.client.get(f"/v1/jobs/{done['id']}").json() == done  # the result is in PostgreSQL
        assert stack.client.get(waiting).json()["status"] == "queued"
        _same_ensemble(stack.client, finished, finished_view, finished_members)  # and the ensemble's
        assert stack.client.post("/v1/ensembles", json=ENSEMBLE).status_code == 503

        server = _redis_server(redis_port, tmp_path / "00-redis-2.log")  # back, empty
        wait_until(lambda: redis_available(stack.env["REDIS_URL"]), 30, "the test's Redis again")
        accepted = stack.client.post("/v1/jobs", json=BODY)
        assert accepted.status_code == 202
        stack.start_worker()
        for location in (waiting, accepted.headers["location"]):  # the lost message is sent again
            view = poll_job(stack.client, location, timeout=GUARD_S)
            assert view["status"] == "succeeded", view["error"]
            assert view["result"]["final_state"] == done["result"]["final_state"]
        again = poll_job(stack.client, waiting_ensemble, timeout=GUARD_S)  # its lost chunks are sent again
        assert again["status"] == "succeeded" and _members(stack.client, waiting_ensemble) == finished_members
        stack.wait_logged("whose message or worker was lost")
        stack.wait_logged("pending chunks of 1 ensemble(s) whose messages were lost")
    except Exception:
        print(stack.logs())
        raise
    finally:
        stack.stop()
        server.kill()
        drop_database(database)


def test_a_postgresql_restart_loses_no_job_and_no_result(tmp_path):
    pg_port = free_port()
    home = Path(tempfile.mkdtemp(prefix="nonholonomic-pg-", dir="/var/tmp"))  # the postgres user reaches it
    home.chmod(0o755)
    data = home / "data"
    _postgres(data, pg_port, start=True)
    database = f"postgresql+psycopg://postgres@127.0.0.1:{pg_port}/nonholonomic"
    stack = QueueStack(tmp_path, TEST_REDIS_URL, database)
    try:
        stack.start_api()
        stack.start_worker()
        done = poll_job(stack.client, stack.client.post("/v1/jobs", json=BODY).headers["location"], timeout=GUARD_S)
        assert done["status"] == "succeeded"
        running = stack.client.post("/v1/jobs", json=LONG).headers["location"]
        wait_until(lambda: stack.client.get(running).json()["status"] == "running", GUARD_S,
                   "the long job to run (a hang guard)")
        behind = stack.client.post("/v1/jobs", json=BODY).headers["location"]  # one process: it waits
        ensemble = stack.client.post("/v1/ensembles", json=ENSEMBLE).headers["location"]  # and its chunks

        _postgres(data, pg_port, start=False)  # while the job runs; the next one starts during the outage
        refused = stack.client.post("/v1/jobs", json=BODY)
        assert refused.status_code == 503 and refused.json()["type"] == "/problems/unavailable", refused.text
        assert stack.client.get(running).status_code == 503
        health = stack.client.get("/health")
        assert health.status_code == 503 and health.json()["store"] == "unreachable", health.text
        assert "127.0.0.1" not in health.text and str(pg_port) not in health.text  # no host, no port
        time.sleep(8)  # the long job ends meanwhile: its worker keeps its result and retries the write

        _postgres(data, pg_port, start=True)
        for location in (running, behind):  # the result kept and written; the start retried
            view = poll_job(stack.client, location, timeout=GUARD_S)
            assert view["status"] == "succeeded", view["error"]
        assert stack.client.get(f"/v1/jobs/{done['id']}").json() == done
        view = poll_job(stack.client, ensemble, timeout=GUARD_S)  # chunks that met the outage tried again
        assert view["status"] == "succeeded" and view["members_done"] == 4
        assert all(m["status"] == "succeeded" for m in _members(stack.client, ensemble))
        after = stack.client.post("/v1/jobs", json=BODY)
        assert after.status_code == 202
        assert poll_job(stack.client, after.headers["location"], timeout=GUARD_S)["status"] == "succeeded"
    except Exception:
        print(stack.logs())
        raise
    finally:
        stack.stop()
        try:
            _postgres(data, pg_port, start=False)
        except subprocess.CalledProcessError:
            pass
        shutil.rmtree(home, ignore_errors=True)


def test_an_api_restart_in_queue_mode_loses_nothing(tmp_path):
    database = fresh_database_url()
    stack = QueueStack(tmp_path, TEST_REDIS_URL, database)
    try:
        stack.start_api()
        stack.start_worker()
        done = poll_job(stack.client, stack.client.post("/v1/jobs", json=BODY).headers["location"], timeout=GUARD_S)
        running = stack.client.post("/v1/jobs", json=LONG).headers["location"]
        ensemble = stack.client.post("/v1/ensembles", json=ENSEMBLE).headers["location"]
        wait_until(lambda: stack.client.get(running).json()["status"] == "running", GUARD_S,
                   "the long job to run (a hang guard)")
        stack.api.send_signal(signal.SIGKILL)
        stack.api.wait(10)
        stack.start_api()
        assert stack.client.get(f"/v1/jobs/{done['id']}").json() == done
        assert poll_job(stack.client, running, timeout=GUARD_S)["status"] == "succeeded"  # the worker went on
        assert poll_job(stack.client, ensemble, timeout=GUARD_S)["status"] == "succeeded"
        listed = {i["location"] for i in stack.client.get("/v1/jobs").json()["items"]}
        assert {f"/v1/jobs/{done['id']}", running} <= listed
    except Exception:
        print(stack.logs())
        raise
    finally:
        stack.stop()
        drop_database(database)
