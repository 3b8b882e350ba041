"""A deployment's worker hosts cut off (unreachable, not dead) and added: the faults multi-machine
deployments meet first, drilled on hosts of the test's own and watched through the service's metrics.

The hosts are Linux network namespaces (:mod:`tests.partition`), each with a machine name of its own:

- a store host running Redis (a ``redis-server`` of the drill's own: no other test's worker sweeps or
  counts in it). PostgreSQL is this machine's own (its root namespace, where it runs), in a database
  of the drill's own: the hosts reach it, like the store host's Redis, through the forwarder on their
  side of the link, so a cut host loses both;
- an API host (``uvicorn``; the test calls it at the host's address, and reads its ``GET /metrics``);
- worker hosts a, b (started together) and c (started mid-ensemble), each one Celery worker with one
  pool process, serving its metrics on its own address.

The hosts share this machine's file system, so its memo on disk (``~/.cache/nonholonomic``) too: the
warm-ups read back what an earlier run derived, where separate machines would each derive it once.

The drill, in one test (the warm-ups paid once):

1. Host b is cut off while it runs an ensemble chunk: its heartbeat expires, a live worker's sweep sends
   the chunk again (:mod:`workers.redelivery`), the ensemble completes with every member once. When the
   link returns, b ends its chunk late: its results change nothing
   (:meth:`store.ensembles.EnsembleStore.store_chunk`).
2. Host c, started while that ensemble runs, takes chunks.
3. Three plain jobs, one on each host (b serves the queue again); host a is cut off running its own: a
   live worker sends it again (:func:`workers.job_store.resend_lost`), it completes once with the same
   numbers as the others, and a's late end changes nothing.

The metrics show each event: ``nonholonomic_workers_alive`` drops by one as a cut host's heartbeat
expires and comes back when it returns; the sweep's resend is counted by the worker that made it
(``nonholonomic_task_redeliveries_total{source="sweeper"}``); the added worker's
``nonholonomic_tasks_total`` counts its chunks. The samples read at each event are printed (``-s``, or a
failure, shows them) and written as JSON to ``$NONHOLONOMIC_DRILL_REPORT`` if set.

Needs root and ``ip netns`` (skipped otherwise, with the reason) and ``redis-server``; PostgreSQL as the
other integration tests. The two tests before the drill need no namespace.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

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
    Samples,
    drop_database,
    free_port,
    fresh_database_url,
    metric_samples,
    metric_total,
    poll_job,
    redis_available,
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
#: Twelve chunks of two members, each a few seconds of work on one core: the cut falls inside one, and
#: chunks are left when the added host comes, ~20 s later.
CHUNKS = 12
ENSEMBLE = {"system": BALL, "t_final": 5000.0, "chunk_size": 2, "samples": 2,
            "members": {"sample": {"count": 2 * CHUNKS, "seed": 19, "level": {"energy": 1.0}}},
            "lyapunov": {"count": 6}}
#: A plain job of a few seconds on one core (its first run on a worker a few more: the three run at once).
JOB = {"system": BALL, "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 3e6,
       "samples": 11}
CHUNK_TASK, JOB_TASK = "nonholonomic.ensemble_chunk", "nonholonomic.simulate"
HEARTBEAT = "nonholonomic:heartbeat:"
WORKERS = ("a", "b", "c")
#: Ports inside the hosts' namespaces (each has its own): the API's, Redis', each worker's metrics'.
API_PORT, REDIS_PORT, METRICS_PORT = 8000, 6379, 9191
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

def _shown(samples: Samples) -> dict[str, float]:
    """The service's samples, as Prometheus writes them (no histogram buckets, no creation times)."""
    shown = {}
    for (name, labels), value in sorted(samples.items(), key=lambda item: (item[0][0], sorted(item[0][1]))):
        if name.startswith("nonholonomic_") and not name.endswith(("_bucket", "_created")):
            inside = ",".join(f'{k}="{v}"' for k, v in sorted(labels))
            shown[f"{name}{{{inside}}}" if inside else name] = value
    return shown


class Deployment:
    """A store host (Redis), an API host and worker hosts, each a namespace of its own; the job store is
    this machine's PostgreSQL, reached through each host's forwarder like the store host's Redis."""

    def __init__(self, logs: Path, database_url: str) -> None:
        self.logs, self.database_url = logs, database_url
        self.store_host, self.api_host = TestHost("store"), TestHost("api")
        self.worker_hosts = {name: TestHost(f"worker-{name}") for name in WORKERS}
        self.queue = f"drill-{uuid.uuid4().hex[:8]}"
        self.workers: dict[str, subprocess.Popen] = {}
        self.cut_off: set[str] = set()
        self.base = f"http://{self.api_host.address}:{API_PORT}"
        self.client = httpx.Client(base_url=self.base, timeout=10)
        self.redis = redis.Redis(host=self.store_host.address, port=REDIS_PORT, socket_timeout=5)
        self.redis_port, self.database_port = free_port(), free_port()  # each host's forwarder listens on these
        self.jobs = JobStore(database_url, ttl_s=3600)
        self.jobs.migrate()
        self.store = EnsembleStore(self.jobs.engine, ttl_s=3600)
        self.began = time.monotonic()
        self.events: list[dict[str, Any]] = []

    @property
    def hosts(self) -> list[TestHost]:
        return [self.store_host, self.api_host, *self.worker_hosts.values()]

    def start(self) -> None:
        """Every host's namespace, Redis on the store host, the forwarders, the API and workers a and b
        (started together: their warm-ups overlap)."""
        for host in self.hosts:
            host.create()
        self.store_host.popen([str(shutil.which("redis-server")), "--bind", self.store_host.address, "--port",
                               str(REDIS_PORT), "--save", "", "--appendonly", "no", "--protected-mode", "no"],
                              stdout=(self.logs / "redis.log").open("w"), stderr=subprocess.STDOUT)
        database = make_url(self.database_url)
        for host in self.hosts[1:]:
            host.forward([(self.store_host.address, REDIS_PORT, self.redis_port),
                          (str(database.host), database.port or 5432, self.database_port)],
                         self.logs / f"forwarder-{host.name}.log")
        wait_until(lambda: self.redis.ping(), STEP_S, "the store host's Redis")
        self.api_host.popen([str(BIN / "uvicorn"), "service.main:app", "--host", self.api_host.address, "--port",
                             str(API_PORT)], cwd=ROOT, env=self._env(self.api_host),
                            stdout=(self.logs / "api.log").open("w"), stderr=subprocess.STDOUT)
        for name in WORKERS[:2]:
            self.start_worker(name)

    def _env(self, host: TestHost, **extra: str) -> dict[str, str]:
        """A process's environment on ``host``: the store's Redis and database through its forwarder."""
        env = {k: v for k, v in os.environ.items() if not k.startswith("NONHOLONOMIC_")
               and k not in ("REDIS_URL", "DATABASE_URL", "PROMETHEUS_MULTIPROC_DIR")}
        database = make_url(self.database_url).set(host=host.gateway, port=self.database_port)
        data = self.logs / f"data-{host.name}"
        data.mkdir(exist_ok=True)
        env.update({"REDIS_URL": f"redis://{host.gateway}:{self.redis_port}/0", "NONHOLONOMIC_QUEUE": self.queue,
                    "NONHOLONOMIC_DATABASE_URL": database.render_as_string(hide_password=False),
                    "NONHOLONOMIC_DATA_DIR": str(data), "NONHOLONOMIC_SYMBOLIC_PRESTART": "false", **LIMITS, **extra})
        return env

    def start_worker(self, name: str) -> None:
        """One Celery worker (one pool process) on worker host ``name``, its metrics on its address."""
        host, counted = self.worker_hosts[name], self.logs / f"metrics-{name}"
        counted.mkdir()
        cmd = [str(BIN / "celery"), "-A", "workers.celery_app:app", "worker", "-Q", self.queue, "--pool", "prefork",
               "--concurrency", "1", "--loglevel", "INFO", "--hostname", "worker@%h", "--without-gossip",
               "--without-mingle"]
        self.workers[name] = self.worker_hosts[name].popen(
            # no warm-up: a job compiles the one system it uses (the drill's CPU, not its result)
            cmd, cwd=ROOT, env=self._env(host, NONHOLONOMIC_WORKER_METRICS_PORT=str(METRICS_PORT),
                                         NONHOLONOMIC_WARM_UP="false", PROMETHEUS_MULTIPROC_DIR=str(counted)),
            stdout=(self.logs / f"worker-{name}.log").open("w"), stderr=subprocess.STDOUT)

    def node(self, name: str) -> str:
        """Worker ``name``'s Celery node name (what an ensemble's ``chunks.workers`` lists)."""
        return f"worker@{self.worker_hosts[name].hostname}"

    def owner(self, name: str) -> str:
        """Worker ``name``'s heartbeat key (``ip netns exec`` execs: the pid is its main process's)."""
        return f"{HEARTBEAT}worker:{self.worker_hosts[name].hostname}:{self.workers[name].pid}"

    def warm(self, name: str) -> bool:
        """Worker ``name`` consumes the queue (its heartbeat) with a warm pool process."""
        return bool(self.redis.exists(self.owner(name))) and any(self.redis.scan_iter(
            match=f"{HEARTBEAT}process:{self.worker_hosts[name].hostname}:{self.workers[name].pid}:*"))

    def held(self, ensemble_id: str) -> list[bytes]:
        return list(self.redis.scan_iter(match=f"nonholonomic:inflight:{ensemble_id}.*"))

    def held_by(self, name: str, ensemble_id: str) -> list[str]:
        """Task ids of ``ensemble_id``'s chunks that worker ``name`` holds (workers.redelivery)."""
        held = []
        for key in self.held(ensemble_id):
            value = self.redis.get(key)
            if value is not None and json.loads(value)["owner"] == self.owner(name):
                held.append(key.decode().removeprefix("nonholonomic:inflight:"))
        return held

    def running(self) -> dict[str, str]:
        """The running jobs by the worker host running them (the job store's row names the worker)."""
        found = {}
        for key, ids in self.jobs.running_on().items():
            for name, host in self.worker_hosts.items():
                if f":{host.hostname}:" in key:
                    found.update(dict.fromkeys([name], *ids[:1]))
        return found

    def members(self, ensemble_id: str) -> list[dict[str, Any]]:
        return self.client.get(f"/v1/ensembles/{ensemble_id}/members", params={"limit": 1000}).json()["members"]

    # -- the network ----------------------------------------------------------------------------------

    def cut(self, name: str) -> None:
        self.worker_hosts[name].cut()
        self.cut_off.add(name)

    def restore(self, name: str) -> None:
        self.worker_hosts[name].restore()
        self.cut_off.discard(name)

    # -- the metrics ----------------------------------------------------------------------------------

    def api_metrics(self) -> Samples:
        """The API's ``GET /metrics`` (no API key in this deployment)."""
        r = self.client.get("/metrics")
        r.raise_for_status()
        return metric_samples(r.text)

    def worker_metrics(self, name: str) -> Samples | None:
        """Worker ``name``'s metrics (on its host's address); None while it cannot be reached."""
        try:
            r = httpx.get(f"http://{self.worker_hosts[name].address}:{METRICS_PORT}/metrics", timeout=3)
            r.raise_for_status()
        except httpx.HTTPError:
            return None
        return metric_samples(r.text)

    def alive(self) -> float:
        return metric_total(self.api_metrics(), "nonholonomic_workers_alive")

    def event(self, what: str) -> tuple[Samples, dict[str, Samples | None]]:
        """Read the API's and every worker's metrics (not a cut-off host's), print them and keep them for
        the report; returns them."""
        api = self.api_metrics()
        workers = {name: None if name in self.cut_off else self.worker_metrics(name) for name in self.workers}
        at, api_shown = round(time.monotonic() - self.began, 1), _shown(api)
        workers_shown: dict[str, dict[str, float] | str] = {
            f"worker-{name}": "cut off" if name in self.cut_off else "unreachable" if samples is None else
            _shown(samples) for name, samples in workers.items()}
        self.events.append({"t_s": at, "event": what, "api": api_shown, "workers": workers_shown})
        lines = [f"[drill {at:6.1f} s] {what}", f"  api: {_brief(api_shown)}"]
        lines += [f"  {name}: {_brief(shown)}" for name, shown in workers_shown.items()]
        print("\n".join(lines), flush=True)
        return api, workers

    def report(self, path: Path) -> None:
        """The hosts and the metrics read at each event, as JSON (``NONHOLONOMIC_DRILL_REPORT``)."""
        hosts = {host.name: {"address": host.address, "hostname": host.hostname} for host in self.hosts}
        path.write_text(json.dumps({"hosts": hosts, "queue": self.queue, "events": self.events,
                                    "wall_s": round(time.monotonic() - self.began, 1)}, indent=1))

    def logs_text(self) -> str:
        return "\n".join(f"--- {p.name}\n{p.read_text()[-4000:]}" for p in sorted(self.logs.glob("*.log")))

    def close(self) -> None:
        self.client.close()
        self.redis.close()
        self.jobs.close()


def _brief(shown: dict[str, float] | str) -> str:
    """A worker's or the API's samples on one line, without the duration histograms' sums."""
    if isinstance(shown, str):
        return shown
    if not shown:
        return "(no samples yet: nothing counted)"
    return "; ".join(f"{name} {value:g}" for name, value in shown.items() if "_sum{" not in name)


@pytest.fixture()
def deployment(tmp_path) -> Iterator[Deployment]:
    reason = unavailable() or (None if shutil.which("redis-server") else "needs redis-server for the store host")
    if reason:
        pytest.skip(reason)
    database_url = fresh_database_url()
    d: Deployment | None = None
    try:
        d = Deployment(tmp_path, database_url)
        d.start()
        yield d
    except BaseException:
        if d is not None:
            print(d.logs_text())
        raise
    finally:
        if d is not None:
            for host in d.hosts:  # every process on it (Redis, the API, a worker's pool), its forwarder, the namespace
                host.destroy()
            d.close()  # the Redis was the store host's: nothing of the drill is left in another one
            if os.environ.get("NONHOLONOMIC_DRILL_REPORT"):
                d.report(Path(os.environ["NONHOLONOMIC_DRILL_REPORT"]))
        drop_database(database_url)


def _without_wall_time(value: Any) -> Any:
    """``value`` without its ``wall_time_s`` entries (the one field two runs of a member may differ in)."""
    if isinstance(value, dict):
        return {k: _without_wall_time(v) for k, v in value.items() if k != "wall_time_s"}
    if isinstance(value, list):
        return [_without_wall_time(v) for v in value]
    return value


def test_a_deployment_replaces_a_cut_off_worker_host_takes_an_added_one_and_its_metrics_show_it(deployment):
    d, client = deployment, deployment.client
    wait_until(lambda: d.warm("a") and d.warm("b"), WARM_S, "workers a and b warm", interval=0.25)
    wait_healthy(d.base, WARM_S)
    ready, _ = d.event("ready: the API, workers a and b")
    assert metric_total(ready, "nonholonomic_workers_alive") == 2

    # 1. An ensemble; worker host b is cut off while it runs a chunk.
    r = client.post("/v1/ensembles", json=ENSEMBLE)
    assert r.status_code == 202, r.text
    ensemble_id, location = r.json()["id"], r.headers["location"]
    assert r.json()["chunks"] == CHUNKS
    wait_until(lambda: d.held_by("b", ensemble_id), STEP_S, "worker b to take a chunk", interval=0.05)
    task_id = d.held_by("b", ensemble_id)[0]
    chunk = int(task_id.rsplit("-", 1)[1])
    wait_until(lambda: d.store.record(ensemble_id)["starts"].get(chunk), STEP_S, f"chunk {chunk} to start",
               interval=0.05)
    b_before = d.worker_metrics("b")
    d.cut("b")
    assert chunk not in d.store.record(ensemble_id)["done"], "the chunk ended before the cut: make it longer"
    api, _ = d.event(f"ensemble submitted, worker b cut off running chunk {chunk}")
    assert metric_total(api, "nonholonomic_ensembles_submitted_total", kind="chaplygin_ball") == 1
    assert metric_total(api, "nonholonomic_queue_depth", queue=d.queue) > 0  # chunks wait for a worker
    wait_until(lambda: d.alive() == 1, STEP_S, "worker b's heartbeat to expire", interval=0.25)
    d.event("worker b's heartbeat expired")

    # 2. A worker host added while the ensemble runs takes chunks.
    d.start_worker("c")
    wait_until(lambda: d.alive() == 2, WARM_S, "worker c's heartbeat", interval=0.25)
    assert client.get(location).json()["status"] in ("queued", "running"), "the ensemble ended before c came"
    d.event("worker c added")

    view = poll_job(client, location, ENSEMBLE_S, interval=0.5)
    assert view["status"] == "succeeded", view
    # b's chunk sent again by a live worker's sweep (a's or c's: this Redis is the drill's own), run once more
    assert d.store.record(ensemble_id)["starts"] == {**dict.fromkeys(range(CHUNKS), 1), chunk: 2}
    assert view["chunks"]["reruns"] == 1 and view["chunks"]["done"] == CHUNKS
    assert view["members_done"] == 2 * CHUNKS and view["summary"]["members"] == 2 * CHUNKS
    workers = view["chunks"]["workers"]
    assert set(workers) == {d.node("a"), d.node("c")} and sum(workers.values()) == CHUNKS, workers
    members = d.members(ensemble_id)
    assert [m["index"] for m in members] == list(range(2 * CHUNKS))
    assert all(m["status"] == "succeeded" for m in members)
    record = d.store.record(ensemble_id)
    wait_until(lambda: not d.held(ensemble_id), STEP_S, "every chunk's lease released")
    api, live = d.event("ensemble done on a and c")
    assert metric_total(api, "nonholonomic_queue_depth", queue=d.queue) == 0
    assert sum(metric_total(live[name], "nonholonomic_task_redeliveries_total", task=CHUNK_TASK, source="sweeper")
               for name in ("a", "c")) == 1
    assert (metric_total(live["c"], "nonholonomic_tasks_total", task=CHUNK_TASK, status="succeeded")
            == workers[d.node("c")])
    assert (metric_total(live["a"], "nonholonomic_tasks_total", task=CHUNK_TASK, status="succeeded")
            == workers[d.node("a")])

    # The link returns: b ends its chunk late, and that changes nothing.
    d.restore("b")
    ended = metric_total(b_before, "nonholonomic_tasks_total", task=CHUNK_TASK) + 1
    wait_until(lambda: metric_total(d.worker_metrics("b"), "nonholonomic_tasks_total", task=CHUNK_TASK) >= ended,
               ENSEMBLE_S, "worker b to end its chunk late", interval=0.25)
    assert client.get(location).json() == view
    assert d.members(ensemble_id) == members
    assert d.store.record(ensemble_id) == record
    assert not d.held(ensemble_id)
    wait_until(lambda: d.alive() == 3, STEP_S, "worker b's heartbeat again", interval=0.25)
    api, live = d.event("worker b restored: its late chunk ended")
    assert metric_total(live["b"], "nonholonomic_members_finished_total") == 0  # its results were not kept

    # 3. Three plain jobs, one on each host (b serves the queue again); host a is cut off running its own.
    locations = []
    for _ in WORKERS:
        r = client.post("/v1/jobs", json=JOB)
        assert r.status_code == 202, r.text
        locations.append(r.headers["location"])
    wait_until(lambda: len(d.running()) == 3, STEP_S, "each worker host to run one of the jobs", interval=0.05)
    job_id = d.running()["a"]
    a_before = d.worker_metrics("a")
    d.cut("a")
    assert d.jobs.status(job_id) == "running", "the job ended before the cut: make it longer"
    api, _ = d.event("three jobs running, worker a cut off running one")
    assert metric_total(api, "nonholonomic_jobs", status="running") == 3
    wait_until(lambda: d.alive() == 2, STEP_S, "worker a's heartbeat to expire", interval=0.25)
    d.event("worker a's heartbeat expired")
    views = [poll_job(client, loc, ENSEMBLE_S, interval=0.5) for loc in locations]
    assert all(v["status"] == "succeeded" for v in views), views
    assert len({json.dumps(_without_wall_time(v["result"]), sort_keys=True) for v in views}) == 1
    stored = d.jobs.get(job_id)
    assert stored is not None and stored.attempts == 2  # started on a, then once more on b or c
    api, live = d.event("the three jobs done on b and c")
    assert metric_total(api, "nonholonomic_jobs", status="succeeded") == 3
    assert sum(metric_total(live[name], "nonholonomic_task_redeliveries_total", task=JOB_TASK, source="sweeper")
               for name in ("b", "c")) == 1

    d.restore("a")
    ended = metric_total(a_before, "nonholonomic_tasks_total", task=JOB_TASK) + 1
    wait_until(lambda: metric_total(d.worker_metrics("a"), "nonholonomic_tasks_total", task=JOB_TASK) >= ended,
               ENSEMBLE_S, "worker a to end its job late", interval=0.25)
    assert [client.get(loc).json() for loc in locations] == views
    wait_until(lambda: d.alive() == 3, STEP_S, "worker a's heartbeat again", interval=0.25)
    api, live = d.event("worker a restored: its late job ended")
    # each job and each member counted once, by the run whose end the store kept: not by the late ones
    assert sum(metric_total(live[name], "nonholonomic_jobs_finished_total", status="succeeded")
               for name in WORKERS) == 3
    assert metric_total(live["a"], "nonholonomic_jobs_finished_total") == 0
    assert sum(metric_total(live[name], "nonholonomic_members_finished_total", status="succeeded")
               for name in WORKERS) == 2 * CHUNKS
