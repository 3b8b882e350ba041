"""Benchmark: the service under load, queue mode. API CPU per small job, jobs per second end to end
with 2 worker processes, submit latency, and nothing lost over many jobs.

Run from the repository root (needs Redis on 127.0.0.1:6379 and PostgreSQL on 127.0.0.1:5432)::

    .venv/bin/python bench/bench_load.py [--jobs 10000] [--rate 120] [--burst 2000] [--clients 8]

One API process (uvicorn, as the Dockerfile runs it) and one Celery worker with 2 pool processes,
on a queue and a PostgreSQL database of their own, on the same 2 cores as this client. After a
warm-up, two phases, each from ``--clients`` threads on one keep-alive connection each:

1. Saturation: ``--burst`` small jobs submitted as fast as the API answers: the most jobs per second
   end to end.
2. Paced: ``--jobs`` small jobs offered at ``--rate`` per second in all (open loop: each client keeps
   its own schedule); every submit is timed (p50, p99).

Meanwhile a process of its own polls ``GET /health`` 10 times a second (one keep-alive connection;
``--health-rate``); for each phase, its p50, p99 and max and the count of answers other than 200
(targets, issue 19: p99 ≤ 100 ms, no 503 while the broker, the store and a warm worker are there).
The issue's runs were ``--clients 16`` and ``--clients 32``.

For each, the API process's CPU time (``/proc/<pid>/stat``, every thread) over the submissions,
divided by the jobs, is its CPU per job (the worker's, its pool processes included, likewise), and
the end is read off the job store (not by polling the API): jobs per second end to end is
jobs / (last ``finished`` − first submission). Then nothing lost: every job is listed by the API
(``GET /v1/jobs`` pages) as ``succeeded``, and a sample of results is read back and compared bit for
bit with the same job run in this process (the API CPU of reading one result back is measured too).

The reference, measured in the same run: the same job run in this process through
:func:`workers.jobs.run_job` (what a worker process calls); ``2 / median`` is the rate two processes
could reach with no queue, no database and no HTTP, and ``end-to-end / that`` the fraction of it the
service delivers. Targets (issue 11): API CPU < 3 ms per job, ≥ 100 jobs/s, p99 submit < 50 ms,
(issue 19) /health p99 ≤ 100 ms and always 200, nothing lost (reported PASS or MISS; the exit status
is 1 only if a job was lost or failed).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import argparse  # noqa: E402
import copy  # noqa: E402
import http.client  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import random  # noqa: E402
import secrets  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from sqlalchemy import func, select  # noqa: E402

from tests.support import drop_database, free_port, fresh_database_url, start_api, start_worker, stop, wait_healthy  # noqa: E402

REDIS_URL = "redis://127.0.0.1:6379/13"
JOB: dict[str, Any] = {
    "system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
    "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]},
    "t_final": 20.0,
    "samples": 21,
}
WARMUP_JOBS = 100
SAMPLE_CHECKED = 100
TARGETS = {"api_cpu_ms": 3.0, "jobs_per_s": 100.0, "p99_submit_ms": 50.0, "p99_health_ms": 100.0}
#: Polls ``GET /health`` every ``1 / rate`` seconds on one keep-alive connection (in a process of its own:
#: the load's client threads do not delay it); prints ``wall-clock start, status, seconds`` per answer.
HEALTH_PROBE = """
import http.client, sys, time
port, period = int(sys.argv[1]), 1 / float(sys.argv[2])
connection = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
next_at = time.perf_counter()
while True:
    wall, start = time.time(), time.perf_counter()
    try:
        connection.request("GET", "/health")
        response = connection.getresponse()
        response.read()
        status = response.status
    except (OSError, http.client.HTTPException):
        connection.close()
        connection = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
        status = 0
    print(f"{wall:.6f} {status} {time.perf_counter() - start:.6f}", flush=True)
    next_at += period
    time.sleep(max(0.0, next_at - time.perf_counter()))
"""
TICKS = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` so far (all its threads)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


def tree_cpu_seconds(pid: int) -> float:
    """CPU seconds of ``pid`` and its children (a Celery worker and its pool processes)."""
    total = cpu_seconds(pid)
    for task in Path(f"/proc/{pid}/task").iterdir():
        for child in (task / "children").read_text().split():
            total += tree_cpu_seconds(int(child))
    return total


def submit_all(port: int, n: int, clients: int, rate: float | None = None) -> tuple[list[str], list[float], float]:
    """Submit ``n`` jobs from ``clients`` threads, at ``rate`` jobs per second in all (each client on its
    own schedule, open loop: a late answer does not delay the next submission's slot) or as fast as
    the API answers if None; returns the ids, each submit's seconds, the start time."""
    body = json.dumps(JOB).encode()
    headers = {"Content-Type": "application/json"}
    ids: list[str] = []
    latencies: list[float] = []
    lock = threading.Lock()
    counts = [n // clients + (1 if i < n % clients else 0) for i in range(clients)]
    errors: list[str] = []

    def one_client(count: int, offset: float) -> None:
        connection = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
        mine_ids, mine_lat = [], []
        t0 = time.perf_counter()
        for k in range(count):
            if rate is not None:  # slot k of this client: every clients / rate seconds
                delay = t0 + offset + k * clients / rate - time.perf_counter()
                if delay > 0:
                    time.sleep(delay)
            start = time.perf_counter()
            connection.request("POST", "/v1/jobs", body=body, headers=headers)
            response = connection.getresponse()
            payload = response.read()
            mine_lat.append(time.perf_counter() - start)
            if response.status != 202:
                errors.append(f"{response.status}: {payload[:300]!r}")
                continue
            mine_ids.append(json.loads(payload)["id"])
        connection.close()
        with lock:
            ids.extend(mine_ids)
            latencies.extend(mine_lat)

    threads = [threading.Thread(target=one_client, args=(c, i / rate if rate else 0.0)) for i, c in enumerate(counts)]
    started = time.time()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    if errors:
        raise RuntimeError(f"{len(errors)} submissions refused, e.g. {errors[0]}")
    return ids, latencies, started


def wait_ended(store: Any, n_before: int, n: int, timeout: float) -> None:
    """Wait until the store holds ``n_before + n`` ended jobs, printing progress."""
    from store.models import JobRow

    deadline = time.monotonic() + timeout
    last = -1
    while time.monotonic() < deadline:
        with store.session() as session:
            ended = session.scalar(select(func.count()).select_from(JobRow)
                                   .where(JobRow.status.in_(("succeeded", "failed", "cancelled")))) or 0
        if ended >= n_before + n:
            return
        if ended // 1000 != last // 1000:
            print(f"  {ended - n_before}/{n} ended", flush=True)
        last = ended
        time.sleep(0.5)
    raise TimeoutError(f"only {last - n_before} of {n} jobs ended after {timeout:g} s")


def listed_statuses(port: int) -> dict[str, str]:
    """Every job the API lists (all pages of ``GET /v1/jobs``), id → status."""
    connection = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
    found: dict[str, str] = {}
    cursor = None
    while True:
        path = "/v1/jobs?limit=500" + (f"&cursor={cursor}" if cursor else "")
        connection.request("GET", path)
        page = json.loads(connection.getresponse().read())
        for item in page["items"]:
            found[item["id"]] = item["status"]
        cursor = page.get("next_cursor")
        if not cursor:
            return found


def in_process_reference(reps: int = 200) -> tuple[float, dict[str, Any]]:
    """Median seconds of ``run_job(JOB)`` in this process (after a warm-up call), and its final state."""
    from workers.jobs import run_job

    final = run_job(copy.deepcopy(JOB))["final_state"]
    times = []
    for _ in range(reps):
        start = time.perf_counter()
        run_job(copy.deepcopy(JOB))
        times.append(time.perf_counter() - start)
    return statistics.median(times), final


@dataclass
class Phase:
    """One phase's numbers."""

    jobs: int
    ids: list[str]
    latencies_ms: np.ndarray
    offered_per_s: float
    end_to_end_per_s: float
    api_cpu_ms: float
    worker_cpu_ms: float
    started: float = 0.0
    ended: float = 0.0
    health: str = ""

    def line(self, name: str) -> str:
        p50, p99 = np.percentile(self.latencies_ms, [50, 99])
        return (f"  {name:<24s} offered {self.offered_per_s:5.0f}/s  end to end {self.end_to_end_per_s:5.1f} jobs/s  "
                f"submit p50 {p50:5.1f} ms p99 {p99:5.1f} ms  API CPU {self.api_cpu_ms:4.2f} ms/job  "
                f"worker CPU {self.worker_cpu_ms:4.2f} ms/job")


def run_phase(port: int, api_pid: int, worker_pid: int, store: Any, ended_before: int, jobs: int, clients: int,
              rate: float | None) -> Phase:
    """Submit ``jobs`` (paced at ``rate``, or as fast as answered) and wait until all ended."""
    from store.models import JobRow

    cpu0, worker_cpu0 = cpu_seconds(api_pid), tree_cpu_seconds(worker_pid)
    ids, latencies, started = submit_all(port, jobs, clients, rate)
    submit_wall = time.time() - started
    api_cpu_ms = (cpu_seconds(api_pid) - cpu0) / jobs * 1e3
    print(f"submitted {jobs} jobs in {submit_wall:.1f} s ({jobs / submit_wall:.0f}/s offered)", flush=True)
    wait_ended(store, ended_before, jobs, 60 + jobs / 20)
    worker_cpu_ms = (tree_cpu_seconds(worker_pid) - worker_cpu0) / jobs * 1e3
    with store.session() as session:
        last = session.scalar(select(func.max(JobRow.finished)))
    return Phase(jobs, ids, np.asarray(latencies) * 1e3, jobs / submit_wall, jobs / (last - started), api_cpu_ms,
                 worker_cpu_ms, started, time.time())


class HealthProbe:
    """``GET /health`` polled from a process of its own (:data:`HEALTH_PROBE`) for the whole run."""

    def __init__(self, port: int, rate: float) -> None:
        self.process = subprocess.Popen([sys.executable, "-c", HEALTH_PROBE, str(port), str(rate)],
                                        stdout=subprocess.PIPE, text=True)
        self.answers: list[tuple[float, int, float]] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            wall, status, seconds = line.split()
            self.answers.append((float(wall), int(status), float(seconds)))

    def stop(self) -> None:
        self.process.terminate()
        self.process.wait(10)
        self._reader.join(10)

    def summary(self, started: float, ended: float) -> tuple[str, float, int]:
        """One line on the answers between ``started`` and ``ended`` (wall clock), their p99 (ms) and the
        count of answers other than 200."""
        window = [(status, seconds) for wall, status, seconds in list(self.answers) if started <= wall <= ended]
        if not window:
            return "no /health answer in this phase", float("nan"), 0
        ms = np.asarray([seconds for _, seconds in window]) * 1e3
        p50, p99 = np.percentile(ms, [50, 99])
        bad = [status for status, _ in window if status != 200]
        return (f"/health ×{len(window)}: p50 {p50:5.1f} ms  p99 {p99:5.1f} ms  max {ms.max():5.1f} ms  "
                f"not 200: {len(bad)}" + (f" ({', '.join(map(str, sorted(set(bad))))})" if bad else ""),
                float(p99), len(bad))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--jobs", type=int, default=10000, help="jobs of the paced phase")
    parser.add_argument("--rate", type=float, default=120.0, help="jobs per second offered in the paced phase")
    parser.add_argument("--burst", type=int, default=2000, help="jobs of the saturation phase (as fast as answered)")
    parser.add_argument("--clients", type=int, default=8)
    parser.add_argument("--health-rate", type=float, default=10.0, help="GET /health per second during the phases")
    args = parser.parse_args()

    from store.jobs import JobStore

    reference_s, reference_final = in_process_reference()
    print(f"reference: run_job in this process {reference_s * 1e3:.2f} ms median "
          f"→ {2 / reference_s:.0f} jobs/s for 2 processes with no queue, database or HTTP")

    queue = f"load-{secrets.token_hex(4)}"
    database = fresh_database_url()
    env = {"REDIS_URL": REDIS_URL, "NONHOLONOMIC_QUEUE": queue, "NONHOLONOMIC_DATABASE_URL": database,
           "NONHOLONOMIC_MAX_QUEUED_MESSAGES": str(max(args.jobs, args.burst) + 1000)}
    logs = Path(tempfile.mkdtemp(prefix="bench-load-"))
    port = free_port()
    worker = start_worker(REDIS_URL, queue, logs / "worker.log", concurrency=2,
                          extra_env={k: v for k, v in env.items() if k != "REDIS_URL"}, warm_up=True)
    api = start_api(port, logs / "api.log", env)
    store = probe = None
    try:
        wait_healthy(f"http://127.0.0.1:{port}", timeout=300)
        store = JobStore(database, 3600)
        submit_all(port, WARMUP_JOBS, args.clients)
        wait_ended(store, 0, WARMUP_JOBS, 300)
        probe = HealthProbe(port, args.health_rate)
        ended = WARMUP_JOBS
        burst = run_phase(port, api.pid, worker.pid, store, ended, args.burst, args.clients, None)
        ended += args.burst
        paced = run_phase(port, api.pid, worker.pid, store, ended, args.jobs, args.clients, args.rate)
        ids = burst.ids + paced.ids
        probe.stop()

        statuses = listed_statuses(port)
        succeeded = sum(statuses.get(i) == "succeeded" for i in ids)
        connection = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
        sample = random.Random(1).sample(ids, min(SAMPLE_CHECKED, len(ids)))
        cpu0 = cpu_seconds(api.pid)
        same = 0
        for job_id in sample:
            connection.request("GET", f"/v1/jobs/{job_id}")
            view = json.loads(connection.getresponse().read())
            same += view["result"]["final_state"] == reference_final
        get_cpu_ms = (cpu_seconds(api.pid) - cpu0) / len(sample) * 1e3

        p99 = float(np.percentile(paced.latencies_ms, 99))
        bare = 2 / reference_s

        def verdict(ok: bool) -> str:
            return "PASS" if ok else "MISS"

        print("\n==================== SUMMARY bench_load ====================")
        print(f"small jobs ({reference_s * 1e3:.1f} ms of work each), {args.clients} clients, 1 API process, "
              f"1 worker × 2 processes, all on 2 cores")
        print(burst.line(f"saturation ({burst.jobs})"))
        print(paced.line(f"paced ({paced.jobs})"))
        print(f"  API CPU per result read {get_cpu_ms:.2f} ms")
        for name, phase in (("saturation", burst), ("paced", paced)):  # submissions until every job ended
            line, health_p99, not_ok = probe.summary(phase.started, phase.ended)
            print(f"  {name:<11s}{line}   target p99 ≤ {TARGETS['p99_health_ms']:g} ms, all 200   "
                  f"{verdict(health_p99 <= TARGETS['p99_health_ms'] and not_ok == 0)}")
        for name, phase in (("saturation", burst), ("paced", paced)):  # busy: warm caches; paced: each alone
            print(f"API CPU per job ({name + ')':<11s}{phase.api_cpu_ms:5.2f} ms   "
                  f"target < {TARGETS['api_cpu_ms']:g} ms   "
                  f"ratio {phase.api_cpu_ms / TARGETS['api_cpu_ms']:.2f}   "
                  f"{verdict(phase.api_cpu_ms < TARGETS['api_cpu_ms'])}")
        print(f"end to end (saturation)  {burst.end_to_end_per_s:6.1f} /s   target ≥ {TARGETS['jobs_per_s']:g}/s   "
              f"ratio {burst.end_to_end_per_s / TARGETS['jobs_per_s']:.2f}   "
              f"{verdict(burst.end_to_end_per_s >= TARGETS['jobs_per_s'])};  "
              f"{burst.end_to_end_per_s / bare:.3f} of the bare reference ({bare:.0f}/s: run_job back to back)")
        kept_up = paced.end_to_end_per_s >= 0.97 * paced.offered_per_s
        print(f"end to end (paced)       {paced.end_to_end_per_s:6.1f} /s   offered {paced.offered_per_s:.0f}/s: "
              f"{'kept up' if kept_up else 'fell behind'}   "
              f"{verdict(kept_up and paced.end_to_end_per_s >= TARGETS['jobs_per_s'])}")
        print(f"submit p99 (paced)       {p99:6.1f} ms   target < {TARGETS['p99_submit_ms']:g} ms   "
              f"ratio {p99 / TARGETS['p99_submit_ms']:.2f}   {verdict(p99 < TARGETS['p99_submit_ms'])}")
        print(f"nothing lost             {succeeded}/{len(ids)} listed succeeded, {same}/{len(sample)} sampled "
              f"results equal to the in-process run bit for bit   "
              f"{verdict(succeeded == len(ids) and same == len(sample))}")
        return 0 if succeeded == len(ids) and same == len(sample) else 1
    except Exception:
        print((logs / "worker.log").read_text()[-3000:], (logs / "api.log").read_text()[-3000:])
        raise
    finally:
        if probe is not None and probe.process.poll() is None:
            probe.stop()
        stop(api)
        stop(worker)
        if store is not None:
            store.close()
        drop_database(database)


if __name__ == "__main__":
    sys.exit(main())
