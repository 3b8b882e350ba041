"""An Idempotency-Key makes one job, whatever process dies when (issue 34, item 1).

Real API processes (uvicorn), PostgreSQL and Redis in queue mode, the SQLite file in embedded mode. The key
is bound to its job in the job's own transaction (store/idempotency.py):

- a keyed POST held inside that transaction (the test locks the jobs table, so its INSERT waits) makes
  a second API answer 409 for the key; its API SIGKILLed, the transaction dies with its connection and
  the retry is an ordinary 202: one job;
- the crash drill: client threads send hundreds of keyed POSTs, each retried until it is answered 202,
  while the API is SIGKILLed and started again over and over; then the database holds exactly one job
  per key, and it is the job every answer for that key named. In queue mode every job is also either in
  the broker or marked "not sent yet" for the workers' sweep: none is lost.
"""

from __future__ import annotations

import os
import signal
import threading
import time
import uuid
from collections import Counter
from pathlib import Path
from typing import Any

import httpx
import pytest
import redis
from sqlalchemy import create_engine, func, select, text

from store.jobs import JobStore
from store.models import JobRow
from tests.support import (
    TEST_REDIS_URL,
    drop_database,
    free_port,
    fresh_database_url,
    redis_available,
    start_api,
    stop,
    wait_until,
)
from workers.broker_messages import parse_task_message, queued_messages

pytestmark = pytest.mark.integration

#: Hang guard (seconds) of the waits: an API's start takes a few seconds on a quiet machine; never a result.
GUARD_S = 300.0
KEY = {"X-API-Key": "alpha-secret"}
API_KEYS = "alice:alpha-secret"
BODY = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
        "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 20.0, "samples": 11}
#: Keyed POSTs of the drill in each mode, the client threads sending them, and the API's SIGKILLs: one
#: each time another KILL_EVERY keys have been answered.
DRILL_KEYS = {"queue": 250, "embedded": 150}
CLIENTS = 8
KILLS = 4


def _answering(base: str) -> None:
    wait_until(lambda: httpx.get(f"{base}/health", timeout=5).status_code in (200, 503), GUARD_S,
               f"{base} (a hang guard)")


def _queue_env(queue: str, database: str) -> dict[str, str]:
    return {"REDIS_URL": TEST_REDIS_URL, "NONHOLONOMIC_QUEUE": queue, "NONHOLONOMIC_DATABASE_URL": database,
            "NONHOLONOMIC_WARM_UP": "false", "NONHOLONOMIC_API_KEYS": API_KEYS,
            "NONHOLONOMIC_MAX_ACTIVE_JOBS_PER_KEY": "100000", "NONHOLONOMIC_MAX_QUEUED_MESSAGES": "100000"}


def _print_logs(tmp_path: Path) -> None:
    for log in sorted(tmp_path.glob("*.log")):
        print(f"--- {log.name}\n{log.read_text()[-3000:]}")


def test_a_key_in_progress_is_a_409_and_free_again_once_its_api_died(tmp_path: Path):
    if not redis_available():
        pytest.fail(f"no Redis at {TEST_REDIS_URL}: run the README's test command, which starts one")
    queue, database = f"inflight-{uuid.uuid4().hex[:8]}", fresh_database_url()
    env = _queue_env(queue, database)
    ports = [free_port(), free_port()]
    bases = [f"http://127.0.0.1:{port}" for port in ports]
    procs = [start_api(port, tmp_path / f"api-{i}.log", env) for i, port in enumerate(ports)]
    locker = create_engine(database, isolation_level="AUTOCOMMIT")
    headers = {**KEY, "Idempotency-Key": f"inflight-{uuid.uuid4().hex}"}
    try:
        for base in bases:
            _answering(base)
        other = httpx.Client(base_url=bases[1], timeout=30)
        with locker.connect() as lock:
            lock.execute(text("BEGIN"))
            lock.execute(text("LOCK TABLE jobs IN EXCLUSIVE MODE"))  # the keyed POST's INSERT waits

            def doomed() -> None:
                try:
                    httpx.post(f"{bases[0]}/v1/jobs", json=BODY, headers=headers, timeout=120)
                except httpx.HTTPError:
                    pass  # its API is killed

            threading.Thread(target=doomed, daemon=True).start()
            wait_until(lambda: lock.execute(text(
                "SELECT count(*) FROM pg_locks l JOIN pg_class c ON c.oid = l.relation "
                "WHERE c.relname = 'jobs' AND NOT l.granted "
                "AND l.database = (SELECT oid FROM pg_database WHERE datname = current_database())")).scalar() >= 1,
                GUARD_S, "the POST to wait for the table (a hang guard)")
            busy = other.post("/v1/jobs", json=BODY, headers=headers)  # another API process: the same key
            assert busy.status_code == 409 and busy.headers["retry-after"] == "1", busy.text
            assert busy.json()["type"] == "/problems/conflict"
            os.kill(procs[0].pid, signal.SIGKILL)  # mid-transaction
            procs[0].wait(10)
            lock.execute(text("ROLLBACK"))
        answers: list[httpx.Response] = []

        def retried() -> bool:
            answers.append(other.post("/v1/jobs", json=BODY, headers=headers))
            return answers[-1].status_code != 409

        wait_until(retried, GUARD_S, "the key to be free again (a hang guard)", interval=0.1)
        first = answers[-1]
        assert first.status_code == 202 and "idempotent-replayed" not in first.headers, first.text  # a normal 202
        procs[0] = start_api(ports[0], tmp_path / "api-0-again.log", env)
        _answering(bases[0])
        replay = httpx.post(f"{bases[0]}/v1/jobs", json=BODY, headers=headers, timeout=30)
        assert replay.status_code == 202 and replay.headers["idempotent-replayed"] == "true"
        assert replay.json()["id"] == first.json()["id"]
        jobs = JobStore(database, 600)
        try:
            with jobs.session() as session:
                assert session.scalar(select(func.count()).select_from(JobRow)) == 1  # the killed POST left none
        finally:
            jobs.close()
        print(f"key free again after {len(answers) - 1} answers of 409 once its API was killed")
    except Exception:
        _print_logs(tmp_path)
        raise
    finally:
        for proc in procs:
            stop(proc)
        locker.dispose()
        redis.Redis.from_url(TEST_REDIS_URL).delete(queue)
        drop_database(database)


class _Drill:
    """Client threads sending keyed POSTs (each key its own body: ``t_final`` = 1 + i/1000) and retrying
    each until a 202, while :meth:`run` SIGKILLs and restarts the API."""

    def __init__(self, base: str, keys: int) -> None:
        self.base, self.keys = base, keys
        self.answers: dict[int, list[str]] = {i: [] for i in range(keys)}
        self.replayed: Counter[str] = Counter()
        self.refused: Counter[str] = Counter()
        self._next = 0
        self._lock = threading.Lock()
        self.done = 0
        self.run_id = uuid.uuid4().hex[:8]

    @staticmethod
    def body(i: int) -> dict[str, Any]:
        return {**BODY, "t_final": 1.0 + i / 1000, "samples": 3}

    def _take(self) -> int | None:
        with self._lock:
            if self._next >= self.keys:
                return None
            self._next += 1
            return self._next - 1

    def client(self) -> None:
        with httpx.Client(base_url=self.base, timeout=60) as http:
            while (i := self._take()) is not None:
                headers = {**KEY, "Idempotency-Key": f"drill-{self.run_id}-{i}"}
                deadline = time.monotonic() + GUARD_S
                while True:
                    if time.monotonic() > deadline:
                        raise AssertionError(f"hang guard: key {i} not answered 202 in {GUARD_S:g} s")
                    try:
                        r = http.post("/v1/jobs", json=self.body(i), headers=headers)
                    except httpx.HTTPError as exc:  # the API was killed: retry
                        self.refused[type(exc).__name__] += 1
                        time.sleep(0.05)
                        continue
                    if r.status_code == 202:
                        self.answers[i].append(r.json()["id"])
                        if r.headers.get("idempotent-replayed") == "true":
                            self.replayed["replayed"] += 1
                        try:  # and once more, replayed: the same job
                            again = http.post("/v1/jobs", json=self.body(i), headers=headers)
                        except httpx.HTTPError:  # killed meanwhile
                            break
                        if again.status_code == 202:
                            self.answers[i].append(again.json()["id"])
                        break
                    assert r.status_code in (409, 503), r.text  # in progress, or the API starting
                    self.refused[str(r.status_code)] += 1
                    time.sleep(0.05)
                with self._lock:
                    self.done += 1

    def run(self, restart: Any) -> None:
        """Send every key while SIGKILLing the API (``restart()`` kills it and starts it again) each time
        another ``keys / (KILLS + 1)`` keys have been answered."""
        threads = [threading.Thread(target=self.client, daemon=True) for _ in range(CLIENTS)]
        for thread in threads:
            thread.start()
        every = self.keys // (KILLS + 1)
        for kill in range(1, KILLS + 1):
            wait_until(lambda k=kill: self.done >= k * every, GUARD_S, "the drill's clients (a hang guard)",
                       interval=0.02)
            restart()
        for thread in threads:
            thread.join(GUARD_S)
            assert not thread.is_alive(), "hang guard: a drill client did not finish"

    def check(self, jobs: list[tuple[str, float]]) -> dict[str, int]:
        """One job per key in the database (``jobs``: id and t_final of each), the one every answer named."""
        by_key: dict[int, list[str]] = {}
        for job_id, t_final in jobs:
            by_key.setdefault(round((t_final - 1.0) * 1000), []).append(job_id)
        twice = {i: ids for i, ids in by_key.items() if len(ids) != 1}
        assert not twice, f"keys with more than one job: {dict(list(twice.items())[:5])}"
        assert sorted(by_key) == list(range(self.keys)), "a key answered 202 without its job"
        for i, ids in self.answers.items():
            assert ids and set(ids) == set(by_key[i]), (i, ids, by_key[i])
        return {"keys": self.keys, "jobs": len(jobs), "replayed_after_a_kill": self.replayed["replayed"],
                **{f"retries_{k}": v for k, v in self.refused.items()}}


class _KilledApi:
    """An API process on one port that :meth:`restart` SIGKILLs and starts again."""

    def __init__(self, tmp_path: Path, env: dict[str, str]) -> None:
        self.tmp_path, self.env, self.port = tmp_path, env, free_port()
        self.base = f"http://127.0.0.1:{self.port}"
        self.procs = [start_api(self.port, tmp_path / "api-0.log", env)]
        try:
            _answering(self.base)
        except BaseException:
            self.stop()
            raise

    def restart(self) -> None:
        os.kill(self.procs[-1].pid, signal.SIGKILL)
        self.procs[-1].wait(10)
        self.procs.append(start_api(self.port, self.tmp_path / f"api-{len(self.procs)}.log", self.env))

    def stop(self) -> None:
        for proc in self.procs:
            stop(proc)


def _jobs_of(url: str) -> list[tuple[str, float]]:
    engine = create_engine(url)
    try:
        with engine.connect() as connection:
            return [(job_id, float(request["t_final"]))
                    for job_id, request in connection.execute(select(JobRow.id, JobRow.request))]
    finally:
        engine.dispose()


def test_crash_drill_queue_mode_one_job_per_key_and_none_lost(tmp_path: Path):
    if not redis_available():
        pytest.fail(f"no Redis at {TEST_REDIS_URL}: run the README's test command, which starts one")
    queue, database = f"drill-{uuid.uuid4().hex[:8]}", fresh_database_url()
    api = _KilledApi(tmp_path, _queue_env(queue, database))
    try:
        drill = _Drill(api.base, DRILL_KEYS["queue"])
        drill.run(api.restart)
        jobs = _jobs_of(database)
        figures = drill.check(jobs)
        # none lost: each job's message is in the broker, or it is "not sent yet" for the workers' sweep
        client = redis.Redis.from_url(TEST_REDIS_URL)
        sent = {p[0] for raw in queued_messages(client, queue, 10 * len(jobs))
                if (p := parse_task_message(raw)) is not None}
        store = JobStore(database, 600)
        try:
            unsent = {row[0] for row in store.sent_before("no-such-epoch", grace_s=0.0)}
            with store.session() as session:
                marked_unsent = set(session.scalars(select(JobRow.id).where(JobRow.broker_epoch.is_(None))))
        finally:
            store.close()
        lost = {job_id for job_id, _ in jobs} - sent - marked_unsent
        assert not lost, f"{len(lost)} jobs neither in the broker nor marked not sent: {sorted(lost)[:5]}"
        assert marked_unsent <= unsent  # the sweep's query finds those (past its grace)
        figures["not_sent_when_killed"] = len(marked_unsent - sent)
        print(f"queue-mode crash drill, {KILLS} SIGKILLs: {figures}")
    except Exception:
        _print_logs(tmp_path)
        raise
    finally:
        api.stop()
        redis.Redis.from_url(TEST_REDIS_URL).delete(queue)
        drop_database(database)


def test_crash_drill_embedded_mode_keys_outlive_a_restart(tmp_path: Path):
    store_path = tmp_path / "store" / "jobs.db"
    env = {"NONHOLONOMIC_DATABASE_URL": f"sqlite:///{store_path}", "NONHOLONOMIC_WARM_UP": "false",
           "NONHOLONOMIC_API_KEYS": API_KEYS, "NONHOLONOMIC_MAX_ACTIVE_JOBS_PER_KEY": "100000",
           "NONHOLONOMIC_MAX_QUEUED_MESSAGES": "100000"}
    api = _KilledApi(tmp_path, env)
    try:
        drill = _Drill(api.base, DRILL_KEYS["embedded"])
        drill.run(api.restart)
        api.restart()  # keys persist in the store: after one more restart every key still answers its job
        _answering(api.base)
        with httpx.Client(base_url=api.base, timeout=60) as http:
            for i in range(0, drill.keys, 7):
                r = http.post("/v1/jobs", json=drill.body(i),
                              headers={**KEY, "Idempotency-Key": f"drill-{drill.run_id}-{i}"})
                assert r.status_code == 202 and r.headers["idempotent-replayed"] == "true", r.text
                drill.answers[i].append(r.json()["id"])
        figures = drill.check(_jobs_of(f"sqlite:///{store_path}"))
        print(f"embedded-mode crash drill, {KILLS + 1} SIGKILLs: {figures}")
    except Exception:
        _print_logs(tmp_path)
        raise
    finally:
        api.stop()
