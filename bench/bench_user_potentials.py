"""Benchmark: potentials written by the user against the built-in ones (issue 12).

Run from the repository root::

    .venv/bin/python bench/bench_user_potentials.py [--potentials 200] [--runs 15]
    .venv/bin/python bench/bench_user_potentials.py --worker-jobs 500 [--max-memory-mib 0] [--only-worker]

1. Speed and agreement: Chaplygin's ball with the built-in linear potential (a, γ) against the same
   U written as ``a1*gamma1 + a2*gamma2 + a3*gamma3``: the same heyoka integration to t = 1000
   (machine-epsilon tolerance), median of ``--runs``; the ratio user / built-in (target ≤ 1.2) and the
   largest difference of the samples (target ≤ 1e-13). The reference is the built-in, in the same run.
2. The first job with a new expression: the seconds to build its definition (sympy), compile its
   integrator (heyoka) and its numpy kernels, against a job whose expression is cached.
3. Memory: the process's resident memory while ``--potentials`` distinct expressions are compiled
   one after the other (the caches keep the last 128 definitions, 64 kernel sets, 32 integrators).
4. With ``--worker-jobs N`` (issue 19): a real Celery worker (2 pool processes, Redis, PostgreSQL) runs N
   small jobs, each with a potential of its own, sent straight to its queue; every pool process's
   resident memory is sampled meanwhile and printed every 50 jobs, with the processes replaced so far.
   ``--max-memory-mib`` is the worker's ``worker_max_memory_mib`` (0: no replacement, to see the growth).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]

import argparse  # noqa: E402
import secrets  # noqa: E402
import signal  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
import uuid  # noqa: E402

import numpy as np  # noqa: E402

from nonholonomic.numerics.integration import MACHINE_EPSILON, heyoka_template, integrate  # noqa: E402
from nonholonomic.numerics.kernels import numeric, parameter_vector, state_vector  # noqa: E402
from nonholonomic.systems import get_system, user_potential  # noqa: E402

A = [0.3, -0.2, 0.5]
BASE = {"inertia": [2.0, 3.0, 4.5], "D": 0.7}
STATE = {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}
T_FINAL, SAMPLES = 1000.0, 1001


def rss_mib() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def timed_runs(system, values: dict, runs: int) -> tuple[float, np.ndarray]:
    p = parameter_vector(system, values)
    y0 = state_vector(system, STATE, p)
    integrate(system, p, y0, T_FINAL, SAMPLES)  # compile (or load) first
    times, states = [], None
    for _ in range(runs):
        start = time.perf_counter()
        states = integrate(system, p, y0, T_FINAL, SAMPLES).states
        times.append(time.perf_counter() - start)
    return statistics.median(times), states


def first_job_seconds(text: str) -> tuple[float, float, float]:
    """Seconds to define, compile the integrator, and compile the kernels of a new expression."""
    start = time.perf_counter()
    system = get_system("chaplygin_ball", user_potential("chaplygin_ball", text, ("q",)))
    defined = time.perf_counter()
    heyoka_template(system, MACHINE_EPSILON)
    compiled = time.perf_counter()
    numeric(system).compile_all()
    return defined - start, compiled - defined, time.perf_counter() - compiled


def pool_rss_mib(worker_pid: int) -> dict[int, float]:
    """Resident memory (MiB) of each pool process of the Celery worker ``worker_pid`` (its children)."""
    found: dict[int, float] = {}
    for task in Path(f"/proc/{worker_pid}/task").iterdir():
        for child in (task / "children").read_text().split():
            try:
                status = Path(f"/proc/{child}/status").read_text()
            except FileNotFoundError:  # replaced meanwhile
                continue
            kib = next((int(line.split()[1]) for line in status.splitlines() if line.startswith("VmRSS:")), 0)
            found[int(child)] = kib / 1024
    return found


def worker_memory(jobs: int, max_memory_mib: int) -> list[str]:
    """Run ``jobs`` jobs with distinct potentials on a real worker (2 processes); the report's lines."""
    from celery import Celery
    from sqlalchemy import func, select

    from store.jobs import JobStore
    from store.models import JobRow
    from tests.support import drop_database, fresh_database_url, start_worker, stop, wait_until

    redis_url, queue, database = "redis://127.0.0.1:6379/13", f"memory-{secrets.token_hex(4)}", fresh_database_url()
    logs = Path(tempfile.mkdtemp(prefix="bench-memory-"))
    worker = start_worker(redis_url, queue, logs / "worker.log", concurrency=2,
                          extra_env={"NONHOLONOMIC_DATABASE_URL": database,
                                     "NONHOLONOMIC_WORKER_MAX_MEMORY_MIB": str(max_memory_mib)}, warm_up=True)
    store = JobStore(database, 3600)
    sender = Celery(broker=redis_url, backend=redis_url)
    samples: list[tuple[int, dict[int, float]]] = []
    lines = [f"worker: 2 pool processes, worker_max_memory_mib = {max_memory_mib} (0: never replaced), "
             f"{jobs} jobs each with a potential of its own"]

    def ended() -> int:
        with store.session() as session:
            return session.scalar(select(func.count()).select_from(JobRow).where(
                JobRow.status.in_(("succeeded", "failed")))) or 0

    try:
        wait_until(lambda: "ready" in (logs / "worker.log").read_text(), 600, "the worker")
        wait_until(lambda: len(pool_rss_mib(worker.pid)) == 2, 600, "2 pool processes")
        time.sleep(5)  # the warm-up (compiling the built-in systems) ends before the first sample
        samples.append((0, pool_rss_mib(worker.pid)))
        for i in range(1, jobs + 1):
            request = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7,
                                  "potential": {"kind": "expression", "U": f"q*gamma3**2 + {i}/1000*gamma1*gamma2",
                                                "parameters": {"q": 0.3}}},
                       "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 5.0,
                       "samples": 11, "checks": ["integrals"]}  # not the measure's symbolic proof: ~10 s a job
            sender.send_task("nonholonomic.simulate", args=[request], task_id=str(uuid.uuid4()), queue=queue)
        stop_sampling = threading.Event()
        every: list[tuple[int, dict[int, float]]] = []

        def sample() -> None:
            while not stop_sampling.wait(1.0):
                every.append((ended(), pool_rss_mib(worker.pid)))

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        started, last = time.monotonic(), -1
        while (done := ended()) < jobs:
            if done // 50 != last // 50:
                print(f"  {done}/{jobs} jobs ended", flush=True)
            last = done
            if time.monotonic() - started > 60 + 20 * jobs:
                raise TimeoutError(f"only {done} of {jobs} jobs ended")
            time.sleep(1.0)
        stop_sampling.set()
        sampler.join(10)
        with store.session() as session:
            failed = session.scalar(select(func.count()).select_from(JobRow).where(JobRow.status == "failed")) or 0
        pids: set[int] = set(samples[0][1])
        peak = max(m for _, rss in every for m in rss.values()) if every else float("nan")
        for mark in sorted({*range(50, jobs + 1, 50), jobs}):
            near = [s for s in every if s[0] >= mark][:1] or every[-1:]
            if near:
                samples.append((mark, near[0][1]))
        for _, rss in every:
            pids |= set(rss)
        for done, rss in samples:
            lines.append(f"  after {done:4d} jobs: pool processes "
                         + ", ".join(f"{m:5.0f}" for m in sorted(rss.values())) + " MiB")
        lines.append(f"  largest resident memory of a pool process: {peak:.0f} MiB; pool processes seen: {len(pids)} "
                     f"({len(pids) - 2} replacements); jobs failed: {failed}")
        return lines
    except Exception:
        print((logs / "worker.log").read_text()[-3000:])
        raise
    finally:
        stop(worker)
        store.close()
        drop_database(database)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--potentials", type=int, default=200)
    parser.add_argument("--runs", type=int, default=15)
    parser.add_argument("--worker-jobs", type=int, default=0, help="jobs with distinct potentials on a real worker")
    parser.add_argument("--max-memory-mib", type=int, default=0, help="the worker's worker_max_memory_mib (0: never)")
    parser.add_argument("--only-worker", action="store_true", help="skip the in-process measurements")
    args = parser.parse_args()
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))  # the worker is stopped on the way out
    if args.only_worker:
        lines = worker_memory(args.worker_jobs, args.max_memory_mib)
        print("\n==================== SUMMARY bench_user_potentials (worker) ====================")
        print("\n".join(lines))
        return

    builtin = get_system("chaplygin_ball", "linear")
    mine = get_system("chaplygin_ball", user_potential("chaplygin_ball", "a1*gamma1 + a2*gamma2 + a3*gamma3",
                                                       ("a1", "a2", "a3")))
    t_builtin, s_builtin = timed_runs(builtin, {**BASE, "a": A}, args.runs)
    t_mine, s_mine = timed_runs(mine, {**BASE, "a1": A[0], "a2": A[1], "a3": A[2]}, args.runs)
    ratio, diff = t_mine / t_builtin, float(np.max(np.abs(s_mine - s_builtin)))

    first = first_job_seconds("q*gamma3**2 + gamma1*gamma2*gamma3")
    start = time.perf_counter()
    first_job_seconds("q*gamma3**2 + gamma1*gamma2*gamma3")  # cached now
    cached = time.perf_counter() - start

    memory = [(0, rss_mib())]
    compile_times = []
    for i in range(1, args.potentials + 1):
        start = time.perf_counter()
        first_job_seconds(f"q*gamma3**2 + {i}/1000*gamma1*gamma2")
        compile_times.append(time.perf_counter() - start)
        if i % 50 == 0 or i == args.potentials:
            memory.append((i, rss_mib()))
            print(f"  {i} distinct potentials compiled, RSS {memory[-1][1]:.0f} MiB", flush=True)

    print("\n==================== SUMMARY bench_user_potentials ====================")
    print(f"ball to t = {T_FINAL:g}, {SAMPLES} samples, machine epsilon, median of {args.runs}:")
    print(f"  built-in linear {t_builtin * 1e3:.2f} ms, the same U as an expression {t_mine * 1e3:.2f} ms: "
          f"ratio {ratio:.3f} (target <= 1.2: {'PASS' if ratio <= 1.2 else 'MISS'})")
    print(f"  largest difference of the samples {diff:.1e} (target <= 1e-13: {'PASS' if diff <= 1e-13 else 'MISS'})")
    print(f"first job with a new expression: define {first[0]:.2f} s, integrator {first[1]:.2f} s, kernels "
          f"{first[2]:.2f} s (total {sum(first):.2f} s); cached: {cached * 1e3:.2f} ms")
    print(f"{args.potentials} distinct expressions: compile median {statistics.median(compile_times):.2f} s, "
          f"max {max(compile_times):.2f} s; RSS " + ", ".join(f"{n}: {m:.0f} MiB" for n, m in memory))
    growth = memory[-1][1] - memory[len(memory) // 2][1]
    print(f"  RSS growth over the second half: {growth:.0f} MiB (bounded caches: it levels off)")
    if args.worker_jobs:
        print("\n".join(worker_memory(args.worker_jobs, args.max_memory_mib)))


if __name__ == "__main__":
    main()
