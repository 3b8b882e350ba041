"""Redelivery of the tasks of a worker that died whole, without waiting for the visibility timeout.

With ``acks_late`` a task is acknowledged when it ends, so a task whose pool process dies is
requeued at once by the worker's main process (``task_reject_on_worker_lost``). When the main
process dies too (SIGKILL of every process, a lost machine), Redis gives its unacknowledged
messages back only after the visibility timeout (an hour: it must exceed the longest job, or a
running job would be delivered twice). Lowering it would redeliver long jobs still running; so a
lease does it instead:

- when a worker receives a task it writes ``nonholonomic:inflight:{task id}``: the task's name,
  arguments and queue, and its owner, the worker's heartbeat key (:mod:`workers.heartbeat`, refreshed
  every 3 s, expiring after 10 s); the key is deleted when the task ends or is revoked. Jobs are not
  noted here: a job's row in the job store names its worker, and :func:`workers.job_store.resend_lost`
  sends them again; this is for ensemble chunks;
- every :data:`SWEEP_INTERVAL_S` each live worker sweeps these keys: a task whose owner's heartbeat
  has expired is claimed (the one sweep whose ``DEL`` removes the key) and sent again under the same
  id. A live worker so takes it within about 15 s of the owner's death.

The old message still comes back after the visibility timeout; by then the job is finished and the
task ends without running (a finished job's record says so, an ensemble chunk is marked done), so a
client never sees a job finish twice.

A worker that was only cut off (its host unreachable, not dead) may still end the task late, after a
live worker took it again: its late results change nothing (:meth:`store.ensembles.EnsembleStore.store_chunk`
keeps the first), and its end deletes the key only if it still names it as the owner, not the key of
the worker that holds the task now.
"""

from __future__ import annotations

import json
import logging
import threading
from typing import Any

import redis

log = logging.getLogger(__name__)

PREFIX = "nonholonomic:inflight:"
#: Seconds between sweeps of one worker.
SWEEP_INTERVAL_S = 5.0


def inflight_key(task_id: str) -> str:
    return PREFIX + task_id


def record_received(client: redis.Redis, owner: str, task_id: str, name: str, args: Any, kwargs: Any,
                    queue: str, ttl_s: int) -> None:
    """Note that the worker whose heartbeat key is ``owner`` holds ``task_id`` (until the visibility
    timeout ``ttl_s``, when the broker redelivers it anyway)."""
    value = json.dumps({"owner": owner, "name": name, "args": args, "kwargs": kwargs, "queue": queue})
    client.set(inflight_key(task_id), value, ex=ttl_s)


#: Delete KEYS[1] if it holds a task of the owner ARGV[1] (one atomic step in Redis).
_DELETE_IF_OWNER = """
local held = redis.call('GET', KEYS[1])
if held and cjson.decode(held)['owner'] == ARGV[1] then
  return redis.call('DEL', KEYS[1])
end
return 0
"""


def own_worker_key() -> str:
    """The heartbeat key of the worker this process serves: its own in the worker's main process (or a
    thread of it), its parent's in a pool process."""
    import os

    from billiard.process import current_process

    from workers.heartbeat import worker_key

    return worker_key(os.getpid() if current_process().name == "MainProcess" else os.getppid())


def record_ended(client: redis.Redis, task_id: str, owner: str | None = None) -> bool:
    """Forget that the worker ``owner`` (default: this process's, :func:`own_worker_key`) holds
    ``task_id``: not if another worker holds it now (it was sent again while this one was cut off).
    True if the key was deleted."""
    return bool(client.eval(_DELETE_IF_OWNER, 1, inflight_key(task_id), owner or own_worker_key()))


def release_owned(client: redis.Redis, owner: str) -> None:
    """Forget every task ``owner`` holds (a worker stopping cleanly: the broker restores them)."""
    for key in list(client.scan_iter(match=PREFIX + "*", count=1000)):
        client.eval(_DELETE_IF_OWNER, 1, key, owner)


def sweep(client: redis.Redis, send: Any) -> list[str]:
    """Send again every task whose owner is dead; returns their ids. ``send(name, args, kwargs, task_id,
    queue)`` publishes a task."""
    keys = list(client.scan_iter(match=PREFIX + "*", count=1000))
    if not keys:
        return []
    values = client.mget(keys)
    held = {}
    for key, value in zip(keys, values):
        if value is None:
            continue
        try:
            held[key.decode().removeprefix(PREFIX)] = json.loads(value)
        except ValueError:
            continue
    owners = sorted({entry["owner"] for entry in held.values()})
    alive = dict(zip(owners, (bool(n) for n in _exists_each(client, owners))))
    resent = []
    for task_id, entry in held.items():
        if alive.get(entry["owner"], True) or not client.delete(inflight_key(task_id)):
            continue  # the owner lives, or another sweep claimed it
        send(entry["name"], entry["args"], entry["kwargs"], task_id, entry["queue"])
        log.warning("redelivered %s %s: its worker (%s) stopped sending heartbeats", entry["name"], task_id,
                    entry["owner"])
        resent.append(task_id)
    return resent


def _exists_each(client: redis.Redis, keys: list[str]) -> list[int]:
    pipe = client.pipeline(transaction=False)
    for key in keys:
        pipe.exists(key)
    return pipe.execute()


class Sweeper:
    """A daemon thread calling ``sweeps`` (each a function of no argument) every
    :data:`SWEEP_INTERVAL_S` seconds."""

    def __init__(self, sweeps: list[Any]) -> None:
        self._sweeps = sweeps
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="nonholonomic-redelivery")

    def start(self) -> Sweeper:
        self._thread.start()
        return self

    def _run(self) -> None:
        while True:
            for one in self._sweeps:
                try:
                    one()
                except Exception as exc:  # the broker or the database is away: next time
                    log.warning("redelivery sweep skipped: %s: %s", type(exc).__name__, exc)
            if self._stop.wait(SWEEP_INTERVAL_S):
                return

    def stop(self) -> None:
        self._stop.set()
