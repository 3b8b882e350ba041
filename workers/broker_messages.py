"""Task messages in the broker: the request a ``nonholonomic.simulate`` message carries, and the
messages waiting in a queue or reserved by a worker (to find jobs a job-queue client sent straight to
the queue, ``send_task``, before a worker records them in the job store)."""

from __future__ import annotations

import base64
import json
from typing import Any

import redis

#: The Celery task name of a simulation job (what job-queue clients ``send_task``).
SIMULATE_TASK = "nonholonomic.simulate"


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
