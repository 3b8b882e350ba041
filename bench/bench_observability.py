"""Benchmark: what the metrics and the logs cost. API CPU per small job, with and without them.

Run from the repository root (needs Redis on 127.0.0.1:6379 and PostgreSQL on 127.0.0.1:5432)::

    .venv/bin/python bench/bench_observability.py [--jobs 400] [--rounds 10] [--clients 4]

Two API processes in queue mode (uvicorn, as the Dockerfile runs it), each on its own queue and database,
each with a Celery worker of its own (one pool process):

* **with**: the defaults: ``/metrics`` and the request counts and durations
  (prometheus-fastapi-instrumentator), JSON log lines with the request and job ids, the
  ``X-Request-ID`` middleware; ``/metrics`` scraped every 50 jobs (a Prometheus scraping every 15 s at
  ~3 jobs/s: more often than a real one);
* **without**: ``NONHOLONOMIC_METRICS=false``, ``NONHOLONOMIC_LOG_FORMAT=text`` (the request id
  middleware stays: it is the answer's header).

Each job is submitted (``POST /v1/jobs``) and, once every job of the round has ended (read off the
database), read back once (``GET /v1/jobs/{id}``, its result inline): two requests per job, whatever the
worker's pace. The wait between the two phases is not counted (the API's background checks run by the clock,
not by the jobs). The API process's CPU time (``/proc/<pid>/stat``, every thread) over a round, divided by its
jobs, is its CPU per job. Rounds alternate the order (without-with, then with-without) so that a machine's
drift falls on both; each round's ratio is taken, and their median is the result (the machine is shared: a
configuration's own rounds vary by ±20 %, more than the effect). Target (issue 37): the ratio with/without ≤ 1.05.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import argparse  # noqa: E402
import os  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
import uuid  # noqa: E402
from typing import Any  # noqa: E402

import httpx  # noqa: E402

from store.jobs import JobStore  # noqa: E402
from tests.support import drop_database, free_port, fresh_database_url, start_api, start_worker, stop, wait_healthy  # noqa: E402

REDIS = "redis://127.0.0.1:6379/14"
JOB = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
       "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 5.0, "samples": 11}
WITHOUT = {"NONHOLONOMIC_METRICS": "false", "NONHOLONOMIC_LOG_FORMAT": "text"}
TICKS = os.sysconf("SC_CLK_TCK")
TARGET = 1.05


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


def run_round(base: str, pid: int, store: JobStore, jobs: int, clients: int, scrape: bool) -> float:
    """API CPU milliseconds per job over ``jobs`` jobs from ``clients`` threads: each job submitted, then
    (once the store says all have ended: read off the database, not through the API) read back once. Two
    requests per job, whatever the worker's pace (polling would add a number of requests that varies)."""
    ids: list[str] = []
    lock = threading.Lock()
    ended_before = sum(n for status, n in store.count_by_status().items() if status not in ("queued", "running"))

    def submit(count: int) -> None:
        with httpx.Client(base_url=base, timeout=30) as client:
            for _ in range(count):
                r = client.post("/v1/jobs", json=JOB)
                r.raise_for_status()
                with lock:
                    ids.append(r.json()["id"])
                    due = scrape and len(ids) % 50 == 0
                if due:
                    client.get("/metrics").raise_for_status()

    def read(chunk: list[str]) -> None:
        with httpx.Client(base_url=base, timeout=30) as client:
            for job_id in chunk:
                view = client.get(f"/v1/jobs/{job_id}").json()
                if view["status"] != "succeeded":
                    raise RuntimeError(f"job {job_id} ended {view['status']}")

    def in_threads(target: Any, parts: list[Any]) -> None:
        threads = [threading.Thread(target=target, args=(part,)) for part in parts]
        for t in threads:
            t.start()
        for t in threads:
            t.join()

    start = cpu_seconds(pid)
    in_threads(submit, [jobs // clients] * clients)
    spent = cpu_seconds(pid) - start
    deadline = time.monotonic() + 600  # a hang guard
    while sum(n for status, n in store.count_by_status().items()
              if status not in ("queued", "running")) < ended_before + len(ids):
        if time.monotonic() > deadline:
            raise RuntimeError("jobs did not end within 600 s")
        time.sleep(0.1)
    start = cpu_seconds(pid)  # the wait is not counted: the API's background checks run by the clock
    in_threads(read, [ids[i::clients] for i in range(clients)])
    spent += cpu_seconds(pid) - start
    return spent / len(ids) * 1e3


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--jobs", type=int, default=400, help="jobs per round")
    parser.add_argument("--rounds", type=int, default=10, help="rounds of each configuration")
    parser.add_argument("--clients", type=int, default=4)
    args = parser.parse_args()
    logs = Path(os.environ.get("TMPDIR", "/tmp")) / f"bench-observability-{uuid.uuid4().hex[:6]}"
    logs.mkdir(parents=True)
    queues = {name: f"bench-obs-{name}-{uuid.uuid4().hex[:6]}" for name in ("with", "without")}
    databases = {name: fresh_database_url() for name in queues}
    processes: list[subprocess.Popen] = []
    try:
        for name, queue in queues.items():  # a worker per API: each shares its API's database
            processes.append(start_worker(REDIS, queue, logs / f"worker-{name}.log",
                                          extra_env={"NONHOLONOMIC_DATABASE_URL": databases[name]}))
        apis: dict[str, tuple[str, int]] = {}
        for name, queue in queues.items():
            port = free_port()
            env = {"REDIS_URL": REDIS, "NONHOLONOMIC_QUEUE": queue, "NONHOLONOMIC_DATABASE_URL": databases[name],
                   **(WITHOUT if name == "without" else {})}
            api = start_api(port, logs / f"api-{name}.log", env)
            processes.append(api)
            apis[name] = (f"http://127.0.0.1:{port}", api.pid)
        for base, _ in apis.values():
            wait_healthy(base, 300)
        for name, (base, pid) in apis.items():  # warm: first requests import and compile what they need
            run_round(base, pid, JobStore(databases[name], 3600), 2 * args.clients, args.clients, scrape=False)
        stores = {name: JobStore(url, 3600) for name, url in databases.items()}
        per_job: dict[str, list[float]] = {"with": [], "without": []}
        for round_ in range(args.rounds):
            order = ("without", "with") if round_ % 2 == 0 else ("with", "without")  # ABBA: drift cancels
            for name in order:
                base, pid = apis[name]
                per_job[name].append(run_round(base, pid, stores[name], args.jobs, args.clients,
                                               scrape=name == "with"))
            pair = per_job["with"][-1] / per_job["without"][-1]
            print(f"  round {round_ + 1}: without {per_job['without'][-1]:5.2f} ms, with {per_job['with'][-1]:5.2f} ms "
                  f"API CPU per job (ratio {pair:.3f})", flush=True)
        with_ms, without_ms = statistics.median(per_job["with"]), statistics.median(per_job["without"])
        ratio = with_ms / without_ms
        paired = statistics.median(w / o for w, o in zip(per_job["with"], per_job["without"], strict=True))
        load = os.getloadavg()
        print(f"API CPU per small job (submit, read back), {args.jobs} jobs x {args.rounds} rounds, "
              f"{args.clients} clients; load {load[0]:.2f} {load[1]:.2f}")
        print(f"  without metrics and JSON logs: {without_ms:.2f} ms   with: {with_ms:.2f} ms   "
              f"ratio of the medians {ratio:.3f}, median of the rounds' ratios {paired:.3f} "
              f"({'PASS' if paired <= TARGET else 'MISS'}: target <= {TARGET})")
        return 0
    finally:
        for proc in reversed(processes):
            stop(proc)
        for url in databases.values():
            drop_database(url)


if __name__ == "__main__":
    sys.exit(main())
