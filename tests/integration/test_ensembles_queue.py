"""Ensembles through the real queue: the API under uvicorn, a Celery worker with two processes,
Redis. Chunks fan out as one group, progress moves while they run, cancel stops them, and a worker
process SIGKILLed mid-chunk loses nothing: the chunk is redelivered and counted once."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time
import uuid
from collections.abc import Iterator

import httpx
import pytest
import redis

from tests.support import (
    TEST_REDIS_URL,
    free_port,
    poll_job,
    redis_available,
    start_api,
    start_worker,
    stop,
    wait_healthy,
    wait_until,
)

pytestmark = pytest.mark.integration

BALL = {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7}
LIMITS = {"NONHOLONOMIC_MAX_T_FINAL": "1e9"}
#: Hang guard (seconds) of each wait: far above what a quiet machine needs (seconds), never a result.
GUARD_S = 300.0


def _chunk_ends(log: str, ensemble_id: str) -> dict[int, str]:
    """How the worker logged the end of each chunk of ``ensemble_id``: what its task returned (``done``,
    ``cancelled`` ...), or ``discarded`` (revoked before it started)."""
    ends = {}
    task = rf"nonholonomic\.ensemble_chunk\[{re.escape(ensemble_id)}\.chunk-(\d+)\]"
    for line in log.splitlines():
        if found := re.search(rf"{task} succeeded in \S+: '([\w ]+)'", line):
            ends[int(found[1])] = found[2]
        elif found := re.search(rf"Discarding revoked task: {task}", line):
            ends[int(found[1])] = "discarded"
    return ends


@pytest.fixture(scope="module")
def stack(tmp_path_factory) -> Iterator[tuple[httpx.Client, redis.Redis, subprocess.Popen]]:
    if not redis_available():
        pytest.fail(f"no Redis at {TEST_REDIS_URL}: run the README's test command, which starts one")
    store = redis.Redis.from_url(TEST_REDIS_URL)
    logs = tmp_path_factory.mktemp("ensemble-logs")
    queue = f"test-ens-{uuid.uuid4().hex[:8]}"
    port = free_port()
    worker = start_worker(TEST_REDIS_URL, queue, logs / "worker.log", concurrency=2, extra_env=LIMITS)
    api = start_api(port, logs / "api.log", {"REDIS_URL": TEST_REDIS_URL, "NONHOLONOMIC_QUEUE": queue, **LIMITS})
    base = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(base, timeout=2 * GUARD_S)  # two processes warm up (~35 s each, cold)
        with httpx.Client(base_url=base, timeout=10) as client:
            client.worker_log = logs / "worker.log"  # type: ignore[attr-defined]
            yield client, store, worker
    except Exception:
        for p in sorted(logs.glob("*.log")):
            print(f"--- {p.name}\n{p.read_text()[-4000:]}")
        raise
    finally:
        stop(api)
        stop(worker)


def _all_members(client: httpx.Client, ensemble_id: str) -> list[dict]:
    return client.get(f"/v1/ensembles/{ensemble_id}/members", params={"limit": 1000}).json()["members"]


def _children(pid: int) -> list[int]:
    out = subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True).stdout
    return [int(x) for x in out.split()]


def test_chunks_fan_out_to_both_processes_and_progress_moves(stack):
    client, _, _ = stack
    body = {"system": BALL, "t_final": 400.0, "chunk_size": 8, "samples": 2,
            "members": {"sample": {"count": 48, "seed": 3, "level": {"energy": 1.0, "area": 0.1}}},
            "lyapunov": {"count": 6}}
    r = client.post("/v1/ensembles", json=body)
    assert r.status_code == 202, r.text
    assert r.json()["chunks"] == 6
    location = r.headers["location"]
    seen = []
    deadline = time.monotonic() + GUARD_S
    while (view := client.get(location).json())["status"] != "succeeded":
        seen.append(view["progress"])
        assert time.monotonic() < deadline, f"hang guard: not done after {GUARD_S:g} s: {view}"
        time.sleep(0.1)
    seen.append(view["progress"])
    assert any(0 < p < 1 for p in seen), "progress never moved between 0 and 1"
    assert seen == sorted(seen)
    assert view["chunks"]["done"] == 6 and sum(view["chunks"]["workers"].values()) == 6
    assert view["summary"]["succeeded"] == 48
    members = _all_members(client, view["id"])
    assert [m["index"] for m in members] == list(range(48))
    for m in members:  # the sum of the spectrum vanishes (invariant measure, eq. 2604-3)
        assert abs(m["lyapunov"]["sum"]) < 1e-2


def test_cancel_stops_every_chunk(stack):
    client, _, _ = stack
    body = {"system": BALL, "t_final": 20000.0, "chunk_size": 4,
            "members": {"sample": {"count": 40, "seed": 1, "level": {"energy": 1.0}}}, "lyapunov": {"count": 6}}
    r = client.post("/v1/ensembles", json=body)
    ensemble_id, location = r.json()["id"], r.headers["location"]
    wait_until(lambda: client.get(location).json()["members_done"] > 0
               or client.get(location).json()["status"] == "running", GUARD_S, "a running chunk (a hang guard)")
    cancelled = client.delete(location).json()
    assert cancelled["status"] == "cancelled"
    # Every chunk ends without running to its end: a running one at its next progress report (its task
    # returns 'cancelled'), a queued one before it starts ('cancelled', or discarded as revoked).
    wait_until(lambda: len(_chunk_ends(client.worker_log.read_text(), ensemble_id)) == 10, GUARD_S,
               "every chunk's task to end (a hang guard)")
    ends = _chunk_ends(client.worker_log.read_text(), ensemble_id)
    done = [chunk for chunk, end in ends.items() if end == "done"]  # finished before the cancellation
    assert set(ends.values()) <= {"cancelled", "discarded", "done"}, ends
    assert len(done) == cancelled["chunks"]["done"], ends
    stopped = client.get(location).json()  # no chunk of it runs any more: its record stays as it is
    assert stopped["status"] == "cancelled" and stopped["chunks"]["done"] == len(done)
    assert stopped["members_done"] < 40
    # both processes are free again: a small ensemble in two chunks runs, and the cancelled one has not moved
    small = {"system": BALL, "t_final": 10.0, "chunk_size": 4,
             "members": {"sample": {"count": 8, "level": {"energy": 1.0}}}}
    view = poll_job(client, client.post("/v1/ensembles", json=small).headers["location"], GUARD_S)
    assert view["status"] == "succeeded" and view["members_done"] == 8
    assert client.get(location).json() == stopped


def test_a_worker_process_killed_mid_chunk_loses_no_member_and_counts_none_twice(stack):
    client, _, worker = stack
    body = {"system": BALL, "t_final": 1500.0, "chunk_size": 4, "samples": 2,
            "members": {"sample": {"count": 16, "seed": 5, "level": {"energy": 1.0}}}, "lyapunov": {"count": 6}}
    r = client.post("/v1/ensembles", json=body)
    ensemble_id, location = r.json()["id"], r.headers["location"]
    wait_until(lambda: client.get(location).json()["status"] == "running", GUARD_S, "a chunk running (a hang guard)")
    children = _children(worker.pid)
    assert children, "the worker has no pool processes"
    for pid in children[:1]:
        os.kill(pid, signal.SIGKILL)
    view = poll_job(client, location, 400)
    assert view["status"] == "succeeded", view
    assert view["chunks"]["done"] == 4 and view["members_done"] == 16
    assert view["chunks"]["reruns"] >= 1  # the killed chunk ran again ...
    members = _all_members(client, ensemble_id)
    assert [m["index"] for m in members] == list(range(16))
    assert all(m["status"] == "succeeded" for m in members)
    assert view["summary"]["members"] == 16  # ... and was counted once


def test_a_chaos_map_fans_out_over_both_processes_with_the_numbers_of_the_core(stack):
    """The ball in a linear field, 16 x 12 cells in chunks of 24 over the worker's two processes: each cell's
    indicators equal the core's, computed here from the same request (lanes are independent)."""
    from nonholonomic.analysis.chaos_map import run_cells
    from schemas.ensembles import EnsembleRequest

    client, _, _ = stack
    body = {"system": {**BALL, "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}}, "t_final": 150.0,
            "chunk_size": 24, "indicators": ["fli", "megno"],
            "members": {"grid": {"surface": "gamma3", "coordinates": ["gamma1", "M3"],
                                 "level": {"energy": 2.0, "area": 0.0}, "shape": [16, 12]}}}
    r = client.post("/v1/ensembles", json=body)
    assert r.status_code == 202, r.text
    assert r.json()["chunks"] == 8
    view = poll_job(client, r.headers["location"], 300)
    assert view["status"] == "succeeded" and sum(view["chunks"]["workers"].values()) == 8
    summary = view["summary"]["map"]
    assert summary["status_by"] == "fli" and 0.1 < summary["chaotic_fraction"] < 0.9 and summary["failed"] == 0
    request = EnsembleRequest.model_validate(view["request"])  # with the ranges resolved at submission
    cells = {c.index: c for c in run_cells(request.definition(), request.members_list(0, 96), 150.0,
                                           request.map_options())}
    members = _all_members(client, view["id"])
    assert [m["index"] for m in members] == list(range(192))
    for m in members[:96]:
        c = cells[m["index"]]
        assert m["cell"]["status"] == c.status
        if c.values:
            assert m["cell"]["indicators"] == pytest.approx(dict(c.values), rel=1e-12)
