"""Worker heartbeats in Redis: which workers consume which queues, and how many of their processes are warm.

``/health`` reads these keys (one SCAN, no broadcast to the workers) and says 200 only when a worker
consumes the API's queue with at least one process that has finished its warm-up, i.e. when a job
would start now rather than wait for a compilation.

- ``nonholonomic:heartbeat:worker:{machine}:{pid}``: JSON ``{"name", "queues"}`` of a worker's main process;
- ``nonholonomic:heartbeat:process:{machine}:{worker pid}:{pid}``: a pool process that is warm.

Each key is refreshed every :data:`INTERVAL_S` seconds and expires after :data:`TTL_S`: a process that
dies (even by SIGKILL) disappears from ``/health`` within that time.
"""

from __future__ import annotations

import json
import os
import socket
import threading
from collections.abc import Callable
from typing import Any

import redis

PREFIX = "nonholonomic:heartbeat:"
#: Seconds between refreshes.
INTERVAL_S = 3.0
#: Seconds a heartbeat outlives its last refresh.
TTL_S = 10


def worker_key(pid: int | None = None) -> str:
    return f"{PREFIX}worker:{socket.gethostname()}:{pid or os.getpid()}"


def process_key(worker_pid: int | None = None) -> str:
    """The key of this process, in the pool of the worker whose main process is ``worker_pid`` (default:
    the parent; the worker itself with a pool that runs jobs in the main process)."""
    return f"{PREFIX}process:{socket.gethostname()}:{worker_pid or os.getppid()}:{os.getpid()}"


class Heartbeat:
    """A daemon thread writing ``key`` (value from ``value()``) every :data:`INTERVAL_S` seconds."""

    def __init__(self, url: str, key: str, value: Callable[[], str]) -> None:
        self.key, self._value = key, value
        self._redis = redis.Redis.from_url(url, socket_timeout=2, socket_connect_timeout=2)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="nonholonomic-heartbeat")

    def start(self) -> Heartbeat:
        self._beat()
        self._thread.start()
        return self

    def _beat(self) -> None:
        try:
            self._redis.set(self.key, self._value(), ex=TTL_S)
        except redis.RedisError:
            pass  # the broker is away; the key expires and /health says so

    def _run(self) -> None:
        while not self._stop.wait(INTERVAL_S):
            self._beat()

    def stop(self) -> None:
        self._stop.set()
        try:
            self._redis.delete(self.key)
        except redis.RedisError:
            pass


def census(client: redis.Redis) -> dict[str, dict[str, Any]]:
    """Each live worker by name: its queues and its number of warm processes."""
    keys = list(client.scan_iter(match=PREFIX + "*", count=1000))
    values = client.mget(keys) if keys else []
    workers: dict[tuple[str, str], dict[str, Any]] = {}
    warm: dict[tuple[str, str], int] = {}
    for key, value in zip(keys, values):
        if value is None:
            continue
        parts = key.decode().removeprefix(PREFIX).split(":")
        if parts[0] == "worker" and len(parts) == 3:
            try:
                workers[(parts[1], parts[2])] = json.loads(value)
            except ValueError:
                continue
        elif parts[0] == "process" and len(parts) == 4:
            warm[(parts[1], parts[2])] = warm.get((parts[1], parts[2]), 0) + 1
    return {str(info.get("name")): {"queues": list(info.get("queues", [])), "warm_processes": warm.get(owner, 0)}
            for owner, info in workers.items()}
