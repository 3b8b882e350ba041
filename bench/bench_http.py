"""Benchmark: end-to-end latency of a small simulation job over HTTP, with a warm real worker.

Run from the repository root (needs Redis on 127.0.0.1:6379)::

    .venv/bin/python bench/bench_http.py [--jobs 200] [--no-embedded]

Queue mode: the API under uvicorn plus one real Celery worker (prefork, concurrency 1) on a
dedicated Redis DB (13) and a random queue name, so nothing else is disturbed. After a warm-up,
``N`` jobs are run one after the other; each is timed from ``POST /v1/jobs`` to the first
``GET Location`` that reports ``succeeded`` (polling every ~1 ms on one keep-alive client).

The in-run reference is the same job run in this process through :func:`workers.jobs.run_job`
(the function the worker calls); ``e2e_p50 / in_process_median`` is the overhead factor of the
queue, the result backend and HTTP. Optionally the same measurement in embedded mode (no Redis:
the API runs jobs in its own thread pool). Target: queue-mode p50 <= 30 ms (reported, never an
exit status).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import argparse  # noqa: E402
import copy  # noqa: E402
import secrets  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from typing import Any  # noqa: E402

import httpx  # noqa: E402
import numpy as np  # noqa: E402
import redis  # noqa: E402

from tests.support import free_port, start_api, start_worker, stop, wait_healthy, wait_until  # noqa: E402

REDIS_URL = "redis://127.0.0.1:6379/13"
#: Job records and results expire after an hour in the bench DB (the service default is a week).
JOB_TTL_S = "3600"
JOB: dict[str, Any] = {
    "system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
    "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]},
    "t_final": 20.0,
    "samples": 201,
}
WARMUP_JOBS = 10
POLL_INTERVAL_S = 0.001
P50_TARGET_MS = 30.0
IN_PROCESS_REPS = 50


@dataclass
class Latencies:
    """Per-job timings of one mode, in seconds."""

    e2e: list[float]
    submit: list[float]
    polls: list[int]
    job_ids: list[str]
    #: submit -> succeeded of the first warm-up job (right after /health turned 200 / warm).
    first_s: float = float("nan")

    def pct_ms(self, q: float) -> float:
        return float(np.percentile(self.e2e, q)) * 1e3


def run_one(client: httpx.Client, posted: list[str], timeout: float = 60.0) -> tuple[float, float, int, str]:
    """Submit one job (its id is appended to ``posted``) and poll it to success.

    Returns
    -------
    (submit -> succeeded seconds, POST seconds, number of GETs, job id)

    Raises
    ------
    RuntimeError
        If the job ends in any state other than ``succeeded`` or takes longer than ``timeout``.
    """
    start = time.perf_counter()
    response = client.post("/v1/jobs", json=JOB)
    post_done = time.perf_counter()
    if response.status_code != 202:
        raise RuntimeError(f"POST /v1/jobs -> {response.status_code}: {response.text[:500]}")
    location = response.headers["Location"]
    posted.append(response.json()["id"])
    polls = 0
    while True:
        view = client.get(location).json()
        polls += 1
        if view["status"] == "succeeded":
            return time.perf_counter() - start, post_done - start, polls, view["id"]
        if view["status"] in ("failed", "cancelled"):
            raise RuntimeError(f"job {location} {view['status']}: {view.get('error')}")
        if time.perf_counter() - start > timeout:
            raise RuntimeError(f"job {location} still {view['status']} after {timeout:g} s")
        time.sleep(POLL_INTERVAL_S)


def measure(base: str, n: int, posted: list[str]) -> Latencies:
    """Warm up with :data:`WARMUP_JOBS` jobs, then time ``n`` sequential jobs (ids go to ``posted``)."""
    with httpx.Client(base_url=base, timeout=30.0) as client:
        warm = [run_one(client, posted, timeout=300.0)[0] for _ in range(WARMUP_JOBS)]  # the first may wait
        out = Latencies([], [], [], [], first_s=warm[0])
        for _ in range(n):
            e2e, submit, polls, job_id = run_one(client, posted)
            out.e2e.append(e2e)
            out.submit.append(submit)
            out.polls.append(polls)
            out.job_ids.append(job_id)
    return out


def in_process_median() -> float:
    """Median seconds of ``run_job(JOB)`` in this process, after a warm-up call."""
    from workers.jobs import run_job

    run_job(copy.deepcopy(JOB))  # compiles kernels and the integrator
    times = []
    for _ in range(IN_PROCESS_REPS):
        start = time.perf_counter()
        run_job(copy.deepcopy(JOB))
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def tail(path: Path, lines: int = 30) -> str:
    """The last ``lines`` lines of a log file (for failure reports)."""
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])
    except OSError:
        return "(no log)"


def cleanup_redis(queue: str, job_ids: list[str]) -> None:
    """Delete this run's job records, Celery results and queue binding from the bench DB (best effort)."""
    try:
        client = redis.Redis.from_url(REDIS_URL, socket_timeout=5)
        keys = [f"nonholonomic:job:{j}" for j in job_ids] + [f"celery-task-meta-{j}" for j in job_ids]
        keys += [queue, f"_kombu.binding.{queue}", f"_kombu.binding_permanent.{queue}"]
        for i in range(0, len(keys), 500):
            client.delete(*keys[i:i + 500])
    except redis.RedisError as exc:
        print(f"(redis cleanup skipped: {exc})")


def queue_mode(n: int, logs: Path) -> tuple[Latencies, str]:
    """Start a worker and the API on a fresh queue, measure, and always stop both."""
    queue = f"bench-{secrets.token_hex(6)}"
    env = {"REDIS_URL": REDIS_URL, "NONHOLONOMIC_QUEUE": queue, "NONHOLONOMIC_JOB_TTL_S": JOB_TTL_S}
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    worker: subprocess.Popen | None = None
    api: subprocess.Popen | None = None
    posted: list[str] = []
    try:
        worker = start_worker(REDIS_URL, queue, logs / "worker.log", concurrency=1,
                              extra_env={"NONHOLONOMIC_JOB_TTL_S": JOB_TTL_S}, warm_up=True)
        api = start_api(port, logs / "api-queue.log", env)
        start = time.perf_counter()
        wait_healthy(base, timeout=180.0)
        print(f"queue mode: API + worker healthy after {time.perf_counter() - start:.1f} s (queue {queue})")
        return measure(base, n, posted), queue
    except Exception:
        print("--- worker log ---\n" + tail(logs / "worker.log") + "\n--- api log ---\n" + tail(logs / "api-queue.log"))
        raise
    finally:
        for proc in (api, worker):
            if proc is not None:
                stop(proc)
        cleanup_redis(queue, posted)  # every job this run posted, warm-up included


def embedded_mode(n: int, logs: Path) -> Latencies:
    """The API alone (no REDIS_URL): jobs run in its thread pool. Waits for its background warm-up."""
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    api = start_api(port, logs / "api-embedded.log", {})
    try:
        start = time.perf_counter()
        wait_healthy(base, timeout=120.0)
        wait_until(lambda: httpx.get(f"{base}/health", timeout=5).json()["workers"]["warm"], 300.0,
                   "embedded warm-up", interval=0.2)
        print(f"embedded mode: API warm after {time.perf_counter() - start:.1f} s")
        return measure(base, n, [])
    except Exception:
        print("--- api log ---\n" + tail(logs / "api-embedded.log"))
        raise
    finally:
        stop(api)


def describe(name: str, lat: Latencies) -> None:
    """Percentiles of one mode."""
    print(f"{name}: n = {len(lat.e2e)}  p50 {lat.pct_ms(50):.2f} ms  p90 {lat.pct_ms(90):.2f} ms  "
          f"p99 {lat.pct_ms(99):.2f} ms  max {max(lat.e2e) * 1e3:.2f} ms  "
          f"(POST p50 {statistics.median(lat.submit) * 1e3:.2f} ms, GETs/job median {statistics.median(lat.polls):g}; "
          f"first warm-up job {lat.first_s * 1e3:.1f} ms)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=200, help="timed jobs per mode")
    parser.add_argument("--no-embedded", action="store_true", help="skip the embedded-mode variant")
    args = parser.parse_args()

    if not redis.Redis.from_url(REDIS_URL, socket_timeout=2).ping():
        raise SystemExit(f"Redis not reachable at {REDIS_URL}")

    with tempfile.TemporaryDirectory(prefix="nonholonomic-bench-") as tmp:
        logs = Path(tmp)
        in_proc = in_process_median()
        print(f"in-process run_job median: {in_proc * 1e3:.2f} ms over {IN_PROCESS_REPS} runs")
        queued, _ = queue_mode(args.jobs, logs)
        describe("queue mode", queued)
        embedded = None if args.no_embedded else embedded_mode(args.jobs, logs)
        if embedded is not None:
            describe("embedded mode", embedded)

    p50 = queued.pct_ms(50)
    print("\n==================== SUMMARY bench_http ====================")
    print(f"job: chaplygin_ball U = 0, t_final = {JOB['t_final']:g}, samples = {JOB['samples']}, "
          f"{args.jobs} sequential jobs after {WARMUP_JOBS} warm-up, poll {POLL_INTERVAL_S * 1e3:g} ms")
    print(f"queue mode (1 warm Celery worker, Redis) submit -> succeeded: p50 {p50:.2f} ms | "
          f"p90 {queued.pct_ms(90):.2f} ms | p99 {queued.pct_ms(99):.2f} ms | max {max(queued.e2e) * 1e3:.2f} ms")
    print(f"target p50 <= {P50_TARGET_MS:g} ms: {'PASS' if p50 <= P50_TARGET_MS else 'MISS'}")
    print(f"in-process run_job median {in_proc * 1e3:.2f} ms; overhead factor e2e_p50 / in_process = "
          f"{p50 / (in_proc * 1e3):.1f}x (queue + result backend + HTTP: {p50 - in_proc * 1e3:.2f} ms)")
    if embedded is not None:
        e50 = embedded.pct_ms(50)
        print(f"embedded mode p50 {e50:.2f} ms | p90 {embedded.pct_ms(90):.2f} ms | p99 {embedded.pct_ms(99):.2f} ms"
              f" | max {max(embedded.e2e) * 1e3:.2f} ms; e2e_p50 / in_process = {e50 / (in_proc * 1e3):.1f}x")
    print("=============================================================")


if __name__ == "__main__":
    main()
