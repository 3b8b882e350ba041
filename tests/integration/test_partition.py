"""A worker host cut off mid-ensemble (unreachable, not dead): the fault multi-machine deployments meet first.

One worker runs in a network namespace of the test's own (:mod:`tests.partition`), reaching Redis and
PostgreSQL through a veth pair; the API and a second worker run here. The namespace's link is cut while
its worker runs a chunk: its heartbeat expires, a live worker's sweep sends the chunk again
(:mod:`workers.redelivery`), the ensemble completes with every member once. When the link returns, the
cut-off worker finishes its chunk late: its results change nothing (:meth:`store.ensembles.EnsembleStore.store_chunk`),
and the worker serves the queue again.

Needs root and ``ip netns`` (skipped otherwise, with the reason), Redis and PostgreSQL as the other
integration tests; a database of its own.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import tempfile
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit, urlunsplit

import httpx
import pytest
import redis
from sqlalchemy.engine import make_url

from store.ensembles import EnsembleStore
from store.jobs import JobStore
from tests.partition import TestHost, unavailable
from tests.support import (
    BIN,
    ROOT,
    TEST_REDIS_URL,
    drop_database,
    free_port,
    fresh_database_url,
    poll_job,
    redis_available,
    start_api,
    stop,
    wait_healthy,
    wait_until,
)
from workers.redelivery import (
    inflight_key,
    record_ended,
    record_received,
    release_owned,
    sweep,
)

pytestmark = pytest.mark.integration

BALL = {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7}
LIMITS = {"NONHOLONOMIC_MAX_T_FINAL": "1e9"}
#: Four chunks of two members, each a few seconds of work on one core: the cut falls inside one.
BODY = {"system": BALL, "t_final": 5000.0, "chunk_size": 2, "samples": 2,
        "members": {"sample": {"count": 8, "seed": 19, "level": {"energy": 1.0}}}, "lyapunov": {"count": 6}}
HEARTBEAT = "nonholonomic:heartbeat:"
#: Hang guards (wide: a loaded 2-core machine), never the result.
WARM_S, STEP_S, ENSEMBLE_S = 300.0, 180.0, 600.0


# -- the store alone (no namespace needed) ---------------------------------------------------------


def test_a_late_write_of_a_finished_chunk_changes_nothing():
    """The first run of a chunk to finish is kept; a second (a worker that was cut off) is ignored."""
    url = fresh_database_url()
    jobs = JobStore(url, ttl_s=3600)
    try:
        jobs.migrate()
        store = EnsembleStore(jobs.engine, ttl_s=3600)
        store.create("e", {"t_final": 1.0}, [(0, 2), (2, 3)])
        first = [{"index": 0, "status": "succeeded", "x": 0.5}, {"index": 1, "status": "succeeded", "x": 1.5}]
        assert store.store_chunk("e", 0, first, [{"d": 1}] * 2, "healthy")
        late = [{"index": 0, "status": "failed", "error": "cut off"},
                {"index": 1, "status": "failed", "error": "cut off"}]
        assert not store.store_chunk("e", 0, late, late, "cut-off")
        record = store.record("e")
        assert (record["done"] == {0} and record["workers"] == {0: "healthy"}
                and record["digests"] == {0: [{"d": 1}] * 2})
        assert store.chunk_members("e", 0) == first
    finally:
        jobs.close()
        drop_database(url)


def test_a_late_end_leaves_the_task_to_the_worker_that_holds_it_now():
    """The lease of a task sent again belongs to its new holder: the cut-off worker's late end keeps it."""
    if not redis_available():
        pytest.fail(f"no Redis at {TEST_REDIS_URL}: run the README's test command, which starts one")
    client = redis.Redis.from_url(TEST_REDIS_URL)
    task_id, cut_off, healthy = (f"partition-{uuid.uuid4().hex}", f"{HEARTBEAT}worker:gone:1",
                                 f"{HEARTBEAT}worker:here:2")
    try:
        record_received(client, cut_off, task_id, "nonholonomic.ensemble_chunk", ["e", 0], {}, "q", 60)
        assert sweep(client, lambda *task: None) == [task_id]  # its heartbeat is gone: claimed, sent again
        record_received(client, healthy, task_id, "nonholonomic.ensemble_chunk", ["e", 0], {}, "q", 60)
        assert not record_ended(client, task_id, cut_off) and client.exists(inflight_key(task_id))
        release_owned(client, cut_off)
        assert client.exists(inflight_key(task_id))
        assert record_ended(client, task_id, healthy) and not client.exists(inflight_key(task_id))
    finally:
        client.delete(inflight_key(task_id))


# -- the drill ----------------------------------------------------------------------------------------


def _worker_env(redis_url: str, database_url: str, queue: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items()
           if not k.startswith("NONHOLONOMIC_") and k not in ("REDIS_URL", "DATABASE_URL")}
    env.update({"REDIS_URL": redis_url, "NONHOLONOMIC_DATABASE_URL": database_url, "NONHOLONOMIC_QUEUE": queue,
                "NONHOLONOMIC_DATA_DIR": tempfile.mkdtemp(prefix="nonholonomic-store-"), **LIMITS})
    return env


def _worker_cmd(queue: str, name: str) -> list[str]:
    return [str(BIN / "celery"), "-A", "workers.celery_app:app", "worker", "-Q", queue, "--pool", "prefork",
            "--concurrency", "1", "--loglevel", "INFO", "--hostname", f"{name}@%h", "--without-gossip",
            "--without-mingle"]


def _via(url: str, host: str) -> str:
    """``url`` (redis://...) with its host replaced by ``host`` (same port)."""
    parts = urlsplit(url)
    auth = parts.netloc.rsplit("@", 1)[0] + "@" if "@" in parts.netloc else ""
    return urlunsplit(parts._replace(netloc=f"{auth}{host}:{parts.port or 6379}"))


class Drill:
    """The API and a healthy worker here, a worker in the test host; their logs and the job store."""

    def __init__(self, host: TestHost, logs: Path, database_url: str) -> None:
        self.host, self.logs, self.database_url = host, logs, database_url
        self.queue = f"partition-{uuid.uuid4().hex[:8]}"
        self.redis = redis.Redis.from_url(TEST_REDIS_URL, socket_timeout=5)
        self.processes: list[subprocess.Popen] = []
        self.jobs = JobStore(database_url, ttl_s=3600)
        self.jobs.migrate()
        self.store = EnsembleStore(self.jobs.engine, ttl_s=3600)
        self.client: httpx.Client | None = None
        self.base = ""

    def start(self) -> None:
        port = free_port()
        self.processes.append(start_api(port, self.logs / "api.log", {
            "REDIS_URL": TEST_REDIS_URL, "NONHOLONOMIC_QUEUE": self.queue,
            "NONHOLONOMIC_DATABASE_URL": self.database_url, **LIMITS}))
        self.base = f"http://127.0.0.1:{port}"
        self.client = httpx.Client(base_url=self.base, timeout=10)
        self.healthy = subprocess.Popen(
            _worker_cmd(self.queue, "healthy"), cwd=ROOT,
            env=_worker_env(TEST_REDIS_URL, self.database_url, self.queue),
            stdout=(self.logs / "healthy.log").open("w"), stderr=subprocess.STDOUT)
        self.processes.append(self.healthy)
        redis_target = urlsplit(TEST_REDIS_URL)
        db_target = make_url(self.database_url)
        self.host.forward([(redis_target.hostname, redis_target.port or 6379),
                           (db_target.host, db_target.port or 5432)],
                          self.logs / "forwarder.log")
        remote_db = db_target.set(host=self.host.gateway).render_as_string(hide_password=False)
        self.remote = self.host.popen(
            _worker_cmd(self.queue, "remote"), cwd=ROOT,
            env=_worker_env(_via(TEST_REDIS_URL, self.host.gateway), remote_db, self.queue),
            stdout=(self.logs / "remote.log").open("w"), stderr=subprocess.STDOUT)
        self.processes.append(self.remote)

    def owner(self, worker: subprocess.Popen) -> str:
        """The heartbeat key of a worker's main process (``ip netns exec`` execs: same pid)."""
        return f"{HEARTBEAT}worker:{socket.gethostname()}:{worker.pid}"

    def warm(self, worker: subprocess.Popen) -> bool:
        """The worker consumes the queue (its heartbeat) with a warm pool process."""
        return bool(self.redis.exists(self.owner(worker))) and any(
            self.redis.scan_iter(match=f"{HEARTBEAT}process:{socket.gethostname()}:{worker.pid}:*"))

    def held(self, ensemble_id: str) -> list[bytes]:
        return list(self.redis.scan_iter(match=f"nonholonomic:inflight:{ensemble_id}.*"))

    def held_by(self, worker: subprocess.Popen, ensemble_id: str) -> list[str]:
        """Task ids of ``ensemble_id``'s chunks that ``worker`` holds (workers.redelivery)."""
        held = []
        for key in self.redis.scan_iter(match=f"nonholonomic:inflight:{ensemble_id}.*"):
            value = self.redis.get(key)
            if value is not None and json.loads(value)["owner"] == self.owner(worker):
                held.append(key.decode().removeprefix("nonholonomic:inflight:"))
        return held

    def log(self, name: str) -> str:
        return (self.logs / f"{name}.log").read_text()

    def logs_text(self) -> str:
        return "\n".join(f"--- {p.name}\n{p.read_text()[-4000:]}" for p in sorted(self.logs.glob("*.log")))

    def members(self, ensemble_id: str) -> list[dict[str, Any]]:
        assert self.client is not None
        return self.client.get(f"/v1/ensembles/{ensemble_id}/members", params={"limit": 1000}).json()["members"]

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
        for proc in reversed(self.processes):
            if proc is not self.remote:
                stop(proc)
        self.jobs.close()


@pytest.fixture()
def drill(tmp_path) -> Iterator[Drill]:
    reason = unavailable()
    if reason:
        pytest.skip(reason)
    if not redis_available():
        pytest.fail(f"no Redis at {TEST_REDIS_URL}: run the README's test command, which starts one")
    database_url = fresh_database_url()
    host = TestHost()
    d: Drill | None = None
    try:
        host.create()
        d = Drill(host, tmp_path, database_url)
        d.start()
        yield d
    except BaseException:
        if d is not None:
            print(d.logs_text())
        raise
    finally:
        host.destroy()  # the worker in the namespace (all its processes), the forwarder, the namespace, the veth
        if d is not None:
            d.close()
            for key in d.redis.scan_iter(match=f"{HEARTBEAT}*:{socket.gethostname()}:{d.remote.pid}*"):
                d.redis.delete(key)  # killed: its keys would expire anyway
        drop_database(database_url)


def _without_wall_time(value: Any) -> Any:
    """``value`` without its ``wall_time_s`` entries (the one field two runs of a member may differ in)."""
    if isinstance(value, dict):
        return {k: _without_wall_time(v) for k, v in value.items() if k != "wall_time_s"}
    if isinstance(value, list):
        return [_without_wall_time(v) for v in value]
    return value


def test_a_worker_cut_off_mid_ensemble_is_replaced_and_its_late_results_change_nothing(drill):
    client = drill.client
    assert client is not None
    wait_until(lambda: drill.warm(drill.healthy) and drill.warm(drill.remote), WARM_S, "both workers warm")
    wait_healthy(drill.base, WARM_S)

    r = client.post("/v1/ensembles", json=BODY)
    assert r.status_code == 202, r.text
    ensemble_id, location = r.json()["id"], r.headers["location"]
    assert r.json()["chunks"] == 4
    wait_until(lambda: drill.held_by(drill.remote, ensemble_id), STEP_S, "the worker in the namespace to take a chunk")
    task_id = drill.held_by(drill.remote, ensemble_id)[0]
    chunk = int(task_id.rsplit("-", 1)[1])
    wait_until(lambda: drill.store.record(ensemble_id)["starts"].get(chunk), STEP_S, f"chunk {chunk} to start")

    drill.host.cut()
    assert chunk not in drill.store.record(ensemble_id)["done"], "the chunk ended before the cut: make it longer"

    # Its heartbeat expires, a live worker's sweep sends the chunk again: the ensemble completes.
    view = poll_job(client, location, ENSEMBLE_S, interval=0.5)
    assert view["status"] == "succeeded", view
    # sent again (by a live worker's sweep: ours, or another on this Redis), run by the healthy worker
    assert drill.store.record(ensemble_id)["starts"] == {0: 1, 1: 1, 2: 1, 3: 1, chunk: 2}
    assert view["chunks"]["reruns"] == 1 and view["chunks"]["done"] == 4
    assert view["members_done"] == 8 and view["summary"]["members"] == 8
    assert view["chunks"]["workers"] == {f"healthy@{socket.gethostname()}": 4}
    members = drill.members(ensemble_id)
    assert [m["index"] for m in members] == list(range(8)) and all(m["status"] == "succeeded" for m in members)
    record = drill.store.record(ensemble_id)
    wait_until(lambda: not drill.held(ensemble_id), STEP_S, "every chunk's lease released")

    # The link returns: the cut-off worker finishes its chunk late, and that changes nothing.
    drill.host.restore()
    ended = re.compile(rf"\[{re.escape(task_id)}\] (succeeded|raised|retry)")
    wait_until(lambda: ended.search(drill.log("remote")), ENSEMBLE_S, "the cut-off worker to end its chunk",
               interval=0.5)
    assert client.get(location).json() == view
    assert drill.members(ensemble_id) == members
    assert drill.store.record(ensemble_id) == record
    assert not drill.held(ensemble_id)

    # It serves the queue again: alone (the healthy worker stopped), it runs the same ensemble, undisturbed,
    # to the same numbers.
    wait_until(lambda: drill.redis.exists(drill.owner(drill.remote)), STEP_S, "the cut-off worker's heartbeat")
    drill.healthy.send_signal(signal.SIGTERM)
    assert drill.healthy.wait(STEP_S) == 0
    again = client.post("/v1/ensembles", json=BODY)
    assert again.status_code == 202, again.text
    rerun = poll_job(client, again.headers["location"], ENSEMBLE_S, interval=0.5)
    assert rerun["status"] == "succeeded", rerun
    assert rerun["chunks"]["workers"] == {f"remote@{socket.gethostname()}": 4} and rerun["chunks"]["reruns"] == 0
    assert _without_wall_time(drill.members(rerun["id"])) == _without_wall_time(members)
    assert rerun["summary"] == view["summary"]
