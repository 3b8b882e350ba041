"""Benchmark: what admission and lookups cost the API in queue mode with a long queue (issue 19).

Run from the repository root (Redis on 127.0.0.1:6379, PostgreSQL on 127.0.0.1:5432)::

    .venv/bin/python bench/bench_admission.py [--messages 5000] [--repeat 20]

In this process, against a queue and a database of its own (removed at the end), with no worker:

- ``--messages`` jobs are submitted (recorded and sent, as ``POST /v1/jobs`` does), then the first page
  of ``GET /v1/jobs`` (``list_jobs``, 50 items) is timed, CPU seconds of this process per call (median of
  ``--repeat``): with the broker scan as main had it (every scanned message parsed and looked up one by
  one, :func:`scan_before`) and as it is now (messages looked at before are skipped);
- the same with the messages sent straight to the broker (``send_task``, unknown to the store): the first
  call records them, the later ones skip them;
- ``GET /v1/jobs/{id}`` with another key for an unknown id and for another key's job (``find``): the
  404s' median wall and CPU time, which should match;
- one ensemble of ``--chunks`` chunks: CPU seconds to admit and send it.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import argparse
import os
import statistics
import time
import uuid
from collections.abc import Callable

REDIS_URL = os.environ.get("NONHOLONOMIC_TEST_REDIS_URL", "redis://127.0.0.1:6379/13")
JOB = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
       "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 20.0, "samples": 11}


def scan_before(backend) -> None:
    """The first page's broker scan as main had it (for comparison)."""
    from service.backends.queue import BROKER_SCAN_LIMIT
    from workers.broker_messages import (
        parse_task_message,
        queued_messages,
        request_from_args,
    )

    epoch = backend._broker_epoch()
    for raw in queued_messages(backend.redis, backend.settings.queue, BROKER_SCAN_LIMIT):
        parsed = parse_task_message(raw)
        if parsed is not None:
            backend.store.ensure(parsed[0], request_from_args(parsed[1], parsed[2])[0], backend.settings.queue, epoch)


def _median(fn: Callable[[], object], repeat: int) -> tuple[float, float]:
    """Median (CPU seconds, wall seconds) of ``fn``."""
    cpu, wall = [], []
    for _ in range(repeat):
        c, w = time.process_time(), time.perf_counter()
        fn()
        cpu.append(time.process_time() - c)
        wall.append(time.perf_counter() - w)
    return statistics.median(cpu), statistics.median(wall)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--messages", type=int, default=5000)
    parser.add_argument("--repeat", type=int, default=20)
    parser.add_argument("--chunks", type=int, default=2000)
    args = parser.parse_args()

    queue = f"bench-admission-{uuid.uuid4().hex[:8]}"
    from tests.support import drop_database, fresh_database_url

    database = fresh_database_url()
    os.environ.update({"REDIS_URL": REDIS_URL, "NONHOLONOMIC_QUEUE": queue, "NONHOLONOMIC_DATABASE_URL": database,
                       "NONHOLONOMIC_WARM_UP": "false"})
    from celery import Celery

    from schemas.settings import get_settings
    from service.backends.queue import QueueBackend

    get_settings.cache_clear()
    backend = QueueBackend(get_settings())
    sender = Celery(broker=REDIS_URL)
    try:
        start = time.perf_counter()
        mine = [backend.submit(JOB, "alice").id for _ in range(args.messages)]
        print(f"{args.messages} jobs submitted in {time.perf_counter() - start:.1f} s; "
              f"queue length {backend.redis.llen(queue)}")

        def first_page():
            return backend.list_jobs(None, 50, None, "bob")

        backend._discover_all = lambda: scan_before(backend)  # type: ignore[method-assign]
        before = _median(first_page, args.repeat)
        del backend._discover_all
        after = _median(first_page, args.repeat)
        print(f"first page, posted jobs:  before {before[0] * 1000:7.1f} ms CPU ({before[1] * 1000:7.1f} ms wall)"
              f" | now {after[0] * 1000:7.1f} ms CPU ({after[1] * 1000:7.1f} ms wall)")

        backend.redis.delete(queue)
        for _ in range(args.messages):
            sender.send_task("nonholonomic.simulate", args=[JOB], queue=queue)
        c = time.process_time()
        backend.list_jobs(None, 50, None)
        once = time.process_time() - c
        backend._discover_all = lambda: scan_before(backend)  # type: ignore[method-assign]
        before = _median(first_page, args.repeat)
        del backend._discover_all
        after = _median(first_page, args.repeat)
        print(f"first page, sent jobs:    before {before[0] * 1000:7.1f} ms CPU ({before[1] * 1000:7.1f} ms wall)"
              f" | now {after[0] * 1000:7.1f} ms CPU ({after[1] * 1000:7.1f} ms wall); the first call, recording "
              f"them, {once * 1000:.0f} ms CPU")

        unknown = str(uuid.uuid4())
        backend.store.finish(mine[0], "succeeded", result={"samples": [[0.1 * i] * 10 for i in range(20_000)]})
        foreign = _median(lambda: backend.get(mine[0]), args.repeat)  # main's job_of: get, then compare owners
        missing = _median(lambda: backend.get(unknown), args.repeat)
        print(f"before: 404, another key's job (a 20,000-sample result): {foreign[0] * 1000:6.2f} ms CPU "
              f"{foreign[1] * 1000:6.2f} ms wall | unknown id: {missing[0] * 1000:6.2f} ms CPU "
              f"{missing[1] * 1000:6.2f} ms wall")
        foreign = _median(lambda: backend.find(mine[0], "bob"), args.repeat)
        missing = _median(lambda: backend.find(unknown, "bob"), args.repeat)
        assert backend.find(mine[0], "bob") is None and backend.find(unknown, "bob") is None
        print(f"now:    404, another key's job: {foreign[0] * 1000:6.2f} ms CPU {foreign[1] * 1000:6.2f} ms wall | "
              f"unknown id: {missing[0] * 1000:6.2f} ms CPU {missing[1] * 1000:6.2f} ms wall")

        backend.redis.delete(queue)
        from service.backends.base import QueueFull  # noqa: F401

        chunks = [(i, i + 1) for i in range(args.chunks)]
        spec = {"system": JOB["system"], "members": {"initial_states": [JOB["initial_state"]] * args.chunks},
                "t_final": 1.0, "samples": 2, "chunk_size": 1}
        c, w = time.process_time(), time.perf_counter()
        with backend.reserve_messages(len(chunks), 10 * args.chunks):
            backend.submit_ensemble(spec, chunks)
        print(f"an ensemble of {args.chunks} chunks admitted and sent: {time.process_time() - c:.2f} s CPU, "
              f"{time.perf_counter() - w:.2f} s wall ({(time.process_time() - c) / args.chunks * 1e3:.2f} ms CPU "
              "per chunk)")
    finally:
        backend.redis.delete(queue, f"nonholonomic:admission:{queue}")
        sender.close()
        backend.close()
        drop_database(database)


if __name__ == "__main__":
    main()
