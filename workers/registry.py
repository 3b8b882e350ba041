"""The job registry in Redis: which job ids exist, their requests, and cancellation flags.

Celery's result backend answers PENDING for any id, so the API keeps its own record of every job
it accepted; workers read the cancellation flag to stop a running job cooperatively.

Keys (db of ``REDIS_URL``):

- ``nonholonomic:job:{id}``: hash ``request`` (JSON), ``created_at`` (ISO 8601, UTC), ``cancelled``
  (``0``/``1``) and, once the task finished, ``status`` (``succeeded``/``failed``, written by the
  worker after Celery stored the outcome, so a list need not read large results); expires
  ``job_ttl_s`` after creation.
- ``nonholonomic:jobs``: sorted set of job ids scored by creation time (epoch seconds), the index
  of ``GET /v1/jobs``. Ids whose hash expired are pruned when the index is written or read.

Jobs also arrive from job-queue clients that send ``nonholonomic.simulate`` straight to the Celery
queue (``send_task``): the task registers its job when it starts (:meth:`RedisJobRegistry.ensure`,
never overwriting a record, so a cancellation made while it was queued holds), and the API
registers a queued one it finds in the broker (:func:`parse_task_message`).
"""

from __future__ import annotations

import base64
import json
from datetime import datetime, timezone
from typing import Any

import redis

KEY_PREFIX = "nonholonomic:job:"
#: Sorted set of every job id, scored by creation time (epoch seconds).
INDEX_KEY = "nonholonomic:jobs"
#: Sorted sets of each key owner's jobs (``nonholonomic:active:{owner}``), pruned of finished ones when counted.
ACTIVE_PREFIX = "nonholonomic:active:"
#: The Celery task name of a simulation job (what job-queue clients ``send_task``).
SIMULATE_TASK = "nonholonomic.simulate"
#: Terminal statuses a worker writes into the record (``cancelled`` is the ``cancelled`` flag).
RECORDED_STATUSES = ("succeeded", "failed")

# Create the record unless it exists (the first writer wins: the API's, or the task's at its start).
_ENSURE = """
if redis.call('EXISTS', KEYS[1]) == 1 then return 0 end
redis.call('HSET', KEYS[1], 'request', ARGV[1], 'created_at', ARGV[2], 'cancelled', '0')
redis.call('EXPIRE', KEYS[1], ARGV[4])
redis.call('ZADD', KEYS[2], ARGV[3], ARGV[5])
return 1
"""
# Set one field of an existing record (never resurrect an expired one as a partial hash).
_SET_IF_EXISTS = """
if redis.call('EXISTS', KEYS[1]) == 0 then return 0 end
redis.call('HSET', KEYS[1], ARGV[1], ARGV[2])
return 1
"""


def _now() -> datetime:
    return datetime.now(timezone.utc)


class RedisJobRegistry:
    """Job records as Redis hashes ``nonholonomic:job:{id}`` with a time to live, and their index."""

    def __init__(self, client: redis.Redis, ttl_s: int) -> None:
        self.client = client
        self.ttl_s = ttl_s
        self._ensure = client.register_script(_ENSURE)
        self._set_if_exists = client.register_script(_SET_IF_EXISTS)

    @staticmethod
    def key(job_id: str) -> str:
        return KEY_PREFIX + job_id

    def create(self, job_id: str, request: dict[str, Any], owner: str | None = None) -> str:
        """Record a job (overwriting any record of that id) of ``owner``'s key; returns its ``created_at``."""
        now = _now()
        pipe = self.client.pipeline()
        pipe.hset(self.key(job_id), mapping={"request": json.dumps(request), "created_at": now.isoformat(),
                                             "cancelled": "0", **({"owner": owner} if owner else {})})
        pipe.expire(self.key(job_id), self.ttl_s)
        pipe.zadd(INDEX_KEY, {job_id: now.timestamp()})
        if owner:
            pipe.zadd(ACTIVE_PREFIX + owner, {job_id: now.timestamp()})
            pipe.expire(ACTIVE_PREFIX + owner, self.ttl_s)
        pipe.zremrangebyscore(INDEX_KEY, "-inf", f"({now.timestamp() - self.ttl_s!r}")  # their hashes expired
        pipe.execute()
        return now.isoformat()

    def ensure(self, job_id: str, request: dict[str, Any]) -> bool:
        """Record a job unless a record of that id exists (atomically); True if this call created it."""
        now = _now()
        return bool(self._ensure(keys=[self.key(job_id), INDEX_KEY],
                                 args=[json.dumps(request), now.isoformat(), repr(now.timestamp()), self.ttl_s,
                                       job_id]))

    @staticmethod
    def _entry(request: bytes | None, created_at: bytes | None, cancelled: bytes | None,
               status: bytes | None, owner: bytes | None) -> dict[str, Any] | None:
        if request is None or created_at is None:
            return None
        recorded = status.decode() if status is not None else None
        return {"request": json.loads(request), "created_at": created_at.decode(), "cancelled": cancelled == b"1",
                "status": recorded if recorded in RECORDED_STATUSES else None,
                "owner": owner.decode() if owner is not None else None}

    _FIELDS = ("request", "created_at", "cancelled", "status", "owner")

    def get(self, job_id: str) -> dict[str, Any] | None:
        """``{request, created_at, cancelled, status}`` (status: what the worker recorded, or None)."""
        return self._entry(*self.client.hmget(self.key(job_id), *self._FIELDS))

    def get_many(self, job_ids: list[str]) -> list[dict[str, Any] | None]:
        """:meth:`get` for several ids in one round trip."""
        pipe = self.client.pipeline(transaction=False)
        for job_id in job_ids:
            pipe.hmget(self.key(job_id), *self._FIELDS)
        return [self._entry(*fields) for fields in pipe.execute()]

    def exists_many(self, job_ids: list[str]) -> list[bool]:
        pipe = self.client.pipeline(transaction=False)
        for job_id in job_ids:
            pipe.exists(self.key(job_id))
        return [bool(n) for n in pipe.execute()]

    def active_count(self, owner: str, enough: int) -> int:
        """Queued and running jobs of ``owner``: the size of its set of jobs, pruned of finished ones when
        it holds ``enough`` (so exact from there, an overestimate below)."""
        key = ACTIVE_PREFIX + owner
        self.client.zremrangebyscore(key, "-inf", f"({_now().timestamp() - self.ttl_s!r}")
        count = int(self.client.zcard(key))
        if count < enough:
            return count
        ids = [m.decode() for m in self.client.zrange(key, 0, -1)]
        pipe = self.client.pipeline(transaction=False)
        for job_id in ids:
            pipe.hmget(self.key(job_id), "status", "cancelled")
        ended = [job_id for job_id, (status, cancelled) in zip(ids, pipe.execute())
                 if status is not None or cancelled == b"1"]  # a status is recorded at the end only
        if ended:
            self.client.zrem(key, *ended)
        return count - len(ended)

    def finished(self, job_id: str) -> bool:
        """Whether a worker recorded the job's end (succeeded or failed)."""
        status = self.client.hget(self.key(job_id), "status")
        return status is not None and status.decode() in RECORDED_STATUSES

    def cancel(self, job_id: str) -> None:
        self._set_if_exists(keys=[self.key(job_id)], args=["cancelled", "1"])

    def is_cancelled(self, job_id: str) -> bool:
        return self.client.hget(self.key(job_id), "cancelled") == b"1"

    def set_status(self, job_id: str, status: str) -> None:
        """Record a terminal status (``succeeded``/``failed``) once Celery stored the outcome."""
        if status not in RECORDED_STATUSES:
            raise ValueError(f"not a recorded status: {status!r}")
        self._set_if_exists(keys=[self.key(job_id)], args=["status", status])

    def newest(self, max_score: float | None, count: int) -> list[tuple[str, float]]:
        """Up to ``count`` ``(id, score)`` of the index, newest first, from ``max_score`` (inclusive) down;
        equal scores come in reverse order of id."""
        top = "+inf" if max_score is None else repr(max_score)
        return [(m.decode(), s) for m, s in self.client.zrevrangebyscore(INDEX_KEY, top, "-inf", start=0, num=count,
                                                                          withscores=True)]

    def prune(self, job_ids: list[str]) -> None:
        """Drop ids from the index (their records expired)."""
        if job_ids:
            self.client.zrem(INDEX_KEY, *job_ids)


# --- requests as job-queue clients send them -------------------------------------------------------


def request_from_args(args: Any, kwargs: Any) -> tuple[dict[str, Any], str | None]:
    """The job request in a ``nonholonomic.simulate`` task's arguments, and why it is refused (or None).

    The task takes one argument, the request: a ``JobRequest`` (or ``PaperReportRequest``) as a JSON
    object, or as a string holding that JSON. A valid request comes back normalized (defaults filled,
    as ``POST /v1/jobs`` records it); an invalid one comes back as sent, for the record, with the
    reason (``field: reason; ...`` for a JSON object that fails the schema). Anything that is not a
    JSON object is recorded as ``{"raw": <what was sent>}``. The physics checks (|γ| = 1, state
    names ...) are :func:`workers.jobs.run_job`'s.
    """
    args = list(args) if isinstance(args, (list, tuple)) else [args]
    kwargs = kwargs if isinstance(kwargs, dict) else {}
    if len(args) == 1 and not kwargs:
        value = args[0]
    elif not args and set(kwargs) == {"request"}:
        value = kwargs["request"]
    else:
        reason = (f"the task takes one argument, the job request (a JSON object); got {len(args)} positional "
                  f"and {len(kwargs)} keyword argument(s)")
        return {"raw": {"args": args, "kwargs": kwargs}}, reason
    if isinstance(value, (str, bytes)):
        try:
            value = json.loads(value)
        except ValueError as exc:
            text = value.decode(errors="replace") if isinstance(value, bytes) else value
            return {"raw": text}, f"the request is not valid JSON: {exc}"
    if not isinstance(value, dict):
        return {"raw": value}, f"the request must be a JSON object (a JobRequest), not {type(value).__name__}"
    return _normalized(value)


def _normalized(request: dict[str, Any]) -> tuple[dict[str, Any], str | None]:
    from pydantic import ValidationError

    from schemas.jobs import JobRequest
    from schemas.report import REPORT_JOB, PaperReportRequest

    model = PaperReportRequest if request.get("job") == REPORT_JOB else JobRequest
    try:
        return model.model_validate(request).model_dump(mode="json"), None
    except ValidationError as exc:  # does not survive Celery's result backend: say it in words
        return request, "; ".join(f"{_field(err['loc'], request)}: {err['msg']}" for err in exc.errors())


def _field(loc: tuple[Any, ...], body: Any) -> str:
    """Dotted path of a pydantic error location, without the tags of discriminated unions (as the
    API's 422 names fields: ``system.D``, not ``system.chaplygin_ball.D``)."""
    parts: list[str] = []
    node = body
    for item in loc:
        if isinstance(item, int):
            parts.append(f"[{item}]")
            node = node[item] if isinstance(node, list) and -len(node) <= item < len(node) else None
            continue
        if isinstance(node, dict) and item not in node and node.get("kind") == item:
            continue
        parts.append(f".{item}" if parts else str(item))
        node = node.get(item) if isinstance(node, dict) else None
    return "".join(parts) or "request"


def parse_task_message(raw: bytes) -> tuple[str, list[Any], dict[str, Any]] | None:
    """``(task id, args, kwargs)`` of a ``nonholonomic.simulate`` message as kombu's Redis transport
    keeps it in the queue's list, or None for anything else (another task, a body that is not JSON,
    which the workers refuse too).

    The list element is JSON ``{"body", "content-type", "headers", "properties"}``; Celery's message
    protocol 2 has the task name and id in ``headers`` and the body (base64 when
    ``properties.body_encoding`` says so) is JSON ``[args, kwargs, embed]``; protocol 1 has
    ``{"task", "id", "args", "kwargs"}`` in the body.
    """
    try:
        message = json.loads(raw)
        if message.get("content-type") != "application/json":
            return None
        headers = message.get("headers") or {}
        if "task" in headers and headers["task"] != SIMULATE_TASK:
            return None
        body = message["body"]
        if (message.get("properties") or {}).get("body_encoding") == "base64":
            body = base64.b64decode(body)
        body = json.loads(body)
        if "id" in headers and "task" in headers:
            args, kwargs = body[0], body[1]
            task_id = headers["id"]
        elif isinstance(body, dict) and body.get("task") == SIMULATE_TASK:
            args, kwargs, task_id = body.get("args", []), body.get("kwargs", {}), body["id"]
        else:
            return None
    except (ValueError, TypeError, KeyError, IndexError, AttributeError):
        return None
    if not isinstance(task_id, str):
        return None
    return task_id, args, kwargs


def broker_lists(queue: str) -> list[str]:
    """The Redis lists kombu keeps a queue's messages in: the queue's name, and one per priority step
    (``{queue}\\x06\\x16{3,6,9}``) for messages sent with a priority."""
    return [queue] + [f"{queue}\x06\x16{p}" for p in (3, 6, 9)]


def queued_messages(client: redis.Redis, queue: str, limit: int) -> list[bytes]:
    """At most ``limit`` raw messages waiting in ``queue``, each list oldest first (the order they were
    sent): all of a list that fits, else its oldest and newest halves (kombu pushes at the head and
    workers pop at the tail). Two round trips."""
    lists = broker_lists(queue)
    pipe = client.pipeline(transaction=False)
    for name in lists:
        pipe.llen(name)
    lengths = pipe.execute()
    left = limit
    pipe = client.pipeline(transaction=False)
    parts: list[int] = []  # LRANGE calls per list
    for name, length in zip(lists, lengths):
        take = min(length, left)
        if take <= 0:
            continue
        left -= take
        if take == length:
            pipe.lrange(name, 0, -1)
            parts.append(1)
        else:
            newest = take // 2
            if newest:
                pipe.lrange(name, 0, newest - 1)
            pipe.lrange(name, -(take - newest), -1)
            parts.append(2 if newest else 1)
    chunks = iter(pipe.execute())
    found: list[bytes] = []
    for n in parts:
        head_to_tail = [m for _ in range(n) for m in next(chunks)]
        found.extend(reversed(head_to_tail))
    return found


def reserved_messages(client: redis.Redis, queue: str, limit: int, unacked_key: str = "unacked") -> list[bytes]:
    """At most ``limit`` raw messages of ``queue`` that workers took but have not acknowledged (kombu's
    ``unacked`` hash: delivery tag → JSON ``[message, exchange, routing key]``): jobs reserved by a busy
    or warming-up worker, and (``acks_late``) running ones."""
    found: list[bytes] = []
    for count, (_, value) in enumerate(client.hscan_iter(unacked_key, count=min(limit, 1000))):
        if count >= limit:
            break
        try:
            message, _, routing_key = json.loads(value)
        except (ValueError, TypeError):
            continue
        if routing_key == queue and isinstance(message, dict):
            found.append(json.dumps(message).encode())
    return found
