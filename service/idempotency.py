"""``Idempotency-Key`` on the POSTs that create work (IETF draft "The Idempotency-Key HTTP Header Field").

A client that sends ``Idempotency-Key: <key>`` with ``POST /v1/jobs``, ``/v1/ensembles`` or
``/v1/paper/report`` may retry the request safely: the same key with the same body (same path and
the same JSON, whatever the key order) answers the first request's response again (202, the same id
and ``Location``) without creating anything; the same key with another body is a 422 naming the
header; the same key while the first request is still being served is a 409. Keys are kept per API
key owner for the jobs' time to live; a request refused (4xx) frees its key.
"""

from __future__ import annotations

import hashlib
import json
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol

import redis
from fastapi import Request
from fastapi.responses import JSONResponse

from schemas.problems import CONFLICT, FieldError
from service.errors import ProblemError, invalid_request

HEADER = "Idempotency-Key"
#: Descriptions of the problems of a creating POST (OpenAPI).
IDEMPOTENCY_IN_PROGRESS = "the first request with this Idempotency-Key is still being served"
IDEMPOTENCY_MISMATCH = "; or an Idempotency-Key used before with another body"
QUEUE_BOUNDS = ("the key has max_active_jobs_per_key queued or running jobs, or the queue holds "
                "max_queued_messages; `Retry-After` says when to retry")
#: Longest accepted key.
MAX_KEY_LENGTH = 255
PREFIX = "nonholonomic:idempotency:"


class IdempotencyStore(Protocol):
    def claim(self, slot: str, fingerprint: str) -> dict[str, Any] | None:
        """Claim ``slot`` for a request with ``fingerprint``: None if claimed now, else what is stored
        (``{"fingerprint", "response"}``, ``response`` None while the first request is served)."""

    def complete(self, slot: str, fingerprint: str, response: dict[str, Any]) -> None: ...

    def release(self, slot: str) -> None: ...


class MemoryIdempotencyStore:
    """Embedded mode: a dictionary with expiry times."""

    def __init__(self, ttl_s: float) -> None:
        self.ttl_s = ttl_s
        self._slots: dict[str, tuple[float, dict[str, Any]]] = {}
        self._lock = threading.Lock()

    def claim(self, slot: str, fingerprint: str) -> dict[str, Any] | None:
        now = time.monotonic()
        with self._lock:
            for expired in [k for k, (t, _) in self._slots.items() if t < now]:
                del self._slots[expired]
            if slot in self._slots:
                return self._slots[slot][1]
            self._slots[slot] = (now + self.ttl_s, {"fingerprint": fingerprint, "response": None})
            return None

    def complete(self, slot: str, fingerprint: str, response: dict[str, Any]) -> None:
        with self._lock:
            self._slots[slot] = (time.monotonic() + self.ttl_s, {"fingerprint": fingerprint, "response": response})

    def release(self, slot: str) -> None:
        with self._lock:
            self._slots.pop(slot, None)


class RedisIdempotencyStore:
    """Queue mode: ``nonholonomic:idempotency:{owner}:{key}`` (SET NX), shared by every API process."""

    def __init__(self, client: redis.Redis, ttl_s: int) -> None:
        self.client, self.ttl_s = client, ttl_s

    def claim(self, slot: str, fingerprint: str) -> dict[str, Any] | None:
        pending = json.dumps({"fingerprint": fingerprint, "response": None})
        if self.client.set(PREFIX + slot, pending, nx=True, ex=self.ttl_s):
            return None
        stored = self.client.get(PREFIX + slot)
        return json.loads(stored) if stored is not None else self.claim(slot, fingerprint)

    def complete(self, slot: str, fingerprint: str, response: dict[str, Any]) -> None:
        self.client.set(PREFIX + slot, json.dumps({"fingerprint": fingerprint, "response": response}), ex=self.ttl_s)

    def release(self, slot: str) -> None:
        self.client.delete(PREFIX + slot)


def fingerprint(path: str, body: Any) -> str:
    """SHA-256 of the path and the body's canonical JSON (sorted keys)."""
    canonical = json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hashlib.sha256(f"{path}\n{canonical}".encode()).hexdigest()


def _key(request: Request) -> str | None:
    key = request.headers.get(HEADER)
    if key is None:
        return None
    if not 1 <= len(key) <= MAX_KEY_LENGTH or not key.isprintable() or not key.isascii():
        raise invalid_request([FieldError(field=HEADER, reason=f"must be 1 to {MAX_KEY_LENGTH} printable ASCII "
                                                               "characters")])
    return key


def idempotent(request: Request, body: Any, create: Callable[[], tuple[dict[str, Any], dict[str, str]]]) -> JSONResponse:
    """Answer a creating POST: ``create()`` returns the 202 body and headers. With an ``Idempotency-Key``
    the first response is stored and a retry gets it again (see the module's docstring)."""
    key = _key(request)
    if key is None:
        content, headers = create()
        return JSONResponse(content, status_code=202, headers=headers)
    store: IdempotencyStore = request.app.state.idempotency
    slot = f"{getattr(request.state, 'owner', None) or '-'}:{key}"
    mark = fingerprint(request.url.path, body)
    stored = store.claim(slot, mark)
    if stored is not None:
        if stored["fingerprint"] != mark:
            raise invalid_request([FieldError(field=HEADER, reason=(
                "this key was used with another request (path or body); send a new key for a new request"))])
        if stored["response"] is None:
            raise ProblemError(409, "Request in progress", f"the first request with this {HEADER} is still being "
                               "served; retry in a moment", CONFLICT, headers={"Retry-After": "1"})
        response = stored["response"]
        return JSONResponse(response["content"], status_code=202,
                            headers={**response["headers"], "Idempotent-Replayed": "true"})
    try:
        content, headers = create()
    except BaseException:
        store.release(slot)
        raise
    store.complete(slot, mark, {"content": content, "headers": headers})
    return JSONResponse(content, status_code=202, headers=headers)


def idempotency_store(backend: Any, ttl_s: int) -> IdempotencyStore:
    """Redis's in queue mode (shared by every API process), else in memory."""
    client = getattr(backend, "redis", None)
    return RedisIdempotencyStore(client, ttl_s) if client is not None else MemoryIdempotencyStore(ttl_s)
