"""A worker's pool processes are replaced past a memory bound (issue 19, item 8): the compiled code of
many distinct user potentials is not all given back, so ``worker_max_memory_mib`` recycles a process
after the job that passed it. A real Celery worker (prefork), Redis, PostgreSQL and the API: the
replacement warms up again before its heartbeat says so, and the jobs after it succeed."""

from __future__ import annotations

import socket
import uuid
from pathlib import Path

import httpx
import pytest
import redis

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
from workers.heartbeat import PREFIX

pytestmark = pytest.mark.integration


def _job(k: int) -> dict:
    """A small job whose potential is the user's own (a new expression for each ``k``)."""
    return {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7,
                       "potential": {"kind": "expression", "U": f"q*gamma3**2 + {k}/1000*gamma1",
                                     "parameters": {"q": 0.3}}},
            "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 5.0, "samples": 11}


def _warm_processes(client: redis.Redis, worker_pid: int) -> set[int]:
    """The pids of the worker's pool processes whose heartbeat says warm."""
    pattern = f"{PREFIX}process:{socket.gethostname()}:{worker_pid}:*"
    return {int(key.decode().rsplit(":", 1)[1]) for key in client.scan_iter(match=pattern, count=1000)}


def test_a_pool_process_past_the_memory_bound_is_replaced_and_the_next_jobs_succeed(tmp_path: Path):
    if not redis_available():
        pytest.fail(f"no Redis at {TEST_REDIS_URL}")
    queue, database = f"test-recycle-{uuid.uuid4().hex[:8]}", fresh_database_url()
    # 1 MiB: every pool process is past it after its first job. No warm-up (minutes on a loaded machine, 4
    # times): a replacement says it is warm after _warm_up's last step all the same (workers/celery_app.py)
    env = {"NONHOLONOMIC_QUEUE": queue, "NONHOLONOMIC_DATABASE_URL": database,
           "NONHOLONOMIC_WORKER_MAX_MEMORY_MIB": "1", "NONHOLONOMIC_WARM_UP": "false"}
    worker = start_worker(TEST_REDIS_URL, queue, tmp_path / "worker.log", concurrency=1, extra_env=env)
    port = free_port()
    api = start_api(port, tmp_path / "api.log", {"REDIS_URL": TEST_REDIS_URL, **env})
    beats = redis.Redis.from_url(TEST_REDIS_URL)
    try:
        base = f"http://127.0.0.1:{port}"
        wait_healthy(base, timeout=300)
        seen = _warm_processes(beats, worker.pid)
        assert len(seen) == 1, seen  # concurrency 1
        with httpx.Client(base_url=base, timeout=30) as client:
            finals = []
            for k in range(3):
                view = poll_job(client, client.post("/v1/jobs", json=_job(k)).headers["location"], timeout=300)
                assert view["status"] == "succeeded", view["error"]
                finals.append(view["result"]["final_state"])
                # the process that ran it exits; its replacement is warm (after its warm-up) before it
                # says so, and /health is 200 again
                wait_until(lambda seen=seen: bool(_warm_processes(beats, worker.pid) - seen), 300,
                           "a new warm pool process")
                current = _warm_processes(beats, worker.pid)
                assert not current & seen, (current, seen)  # the old one said goodbye
                seen |= current
                wait_healthy(base, timeout=300)
        assert len(seen) == 4  # the first process and three replacements (on main: one process for all)
        assert all(len(f["M"]) == 3 and len(f["gamma"]) == 3 for f in finals)
    except Exception:
        print((tmp_path / "worker.log").read_text()[-4000:], (tmp_path / "api.log").read_text()[-3000:])
        raise
    finally:
        stop(api)
        stop(worker)
        beats.close()
        drop_database(database)
