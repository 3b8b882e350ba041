"""``Idempotency-Key`` on the POSTs that create work (IETF draft "The Idempotency-Key HTTP Header Field").

A client that sends ``Idempotency-Key: <key>`` with ``POST /v1/jobs``, ``/v1/ensembles`` or
``/v1/paper/report`` may retry the request safely: the same key with the same body (same path and
the same JSON, whatever the key order) answers the first request's response again (202, the same id
and ``Location``) without creating anything; the same key with another body is a 422 naming the
header; the same key while the first request is still being served is a 409. Keys are kept per API
key owner for the jobs' time to live; a request refused (4xx) frees its key. A key in progress is
claimed for a short lease (``idempotency_lease_s``) that the API serving it renews: if that API dies
mid-request, the key is free again within the lease (issue 19, item 4).
"""

from __future__ import annotations

import hashlib
import json
import threading
import time
import uuid
from collections.abc import Callable
from typing import Any, Protocol

import redis
from fastapi import Request
from fastapi.responses import JSONResponse

from schemas.problems import CONFLICT, FieldError
from service.backends.base import JobBackend
from service.errors import ProblemError, invalid_request

HEADER = "Idempotency-Key"
#: Descriptions of the problems of a creating POST (OpenAPI).
IDEMPOTENCY_IN_PROGRESS = "the first request with this Idempotency-Key is still being served"
IDEMPOTENCY_MISMATCH = "; or an Idempotency-Key used before with another body"
QUEUE_BOUNDS = ("the key has max_active_jobs_per_key queued or running jobs, or the queue would hold more than "
                "max_queued_messages (an ensemble counts each chunk); `Retry-After` says when to retry")
#: Longest accepted key.
MAX_KEY_LENGTH = 255
PREFIX = "nonholonomic:idempotency:"
#: Seconds between purges of expired keys in memory.
PURGE_INTERVAL_S = 60.0


class IdempotencyStore(Protocol):
    #: The keys this process is serving, renewed while it serves them.
    leases: Leases

    def claim(self, slot: str, fingerprint: str, token: str, lease_s: float) -> dict[str, Any] | None:
        """Claim ``slot`` for a request with ``fingerprint`` for ``lease_s`` (the claim is ``token``'s):
        None if claimed now, else what is stored (``{"fingerprint", "response"}``, ``response`` None
        while the first request is served)."""

    def renew(self, slot: str, token: str, lease_s: float) -> bool:
        """Extend ``token``'s claim of ``slot`` by ``lease_s``; False if it is no longer ``token``'s."""

    def complete(self, slot: str, fingerprint: str, response: dict[str, Any]) -> None: ...

    def release(self, slot: str, token: str) -> None:
        """Free ``slot`` if ``token`` still claims it."""


class Leases:
    """The claims this process is serving, renewed every third of their lease by one daemon thread, so
    that a request served longer than the lease keeps its key, and a key whose API died (nothing renews
    it) is free again within the lease."""

    def __init__(self, store: IdempotencyStore) -> None:
        self._store = store
        self._held: dict[str, tuple[str, float]] = {}  # token -> (slot, lease_s)
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._thread: threading.Thread | None = None

    def hold(self, slot: str, token: str, lease_s: float) -> None:
        with self._lock:
            self._held[token] = (slot, lease_s)
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, daemon=True, name="nonholonomic-idempotency-leases")
                self._thread.start()
        self._wake.set()

    def drop(self, token: str) -> None:
        with self._lock:
            self._held.pop(token, None)

    def _run(self) -> None:
        while True:
            with self._lock:
                held = dict(self._held)
            if not held:
                self._wake.wait()
                self._wake.clear()
                continue
            self._wake.clear()
            time.sleep(min(lease for _, lease in held.values()) / 3)
            for token, (slot, lease_s) in held.items():
                with self._lock:
                    if token not in self._held:
                        continue
                try:
                    self._store.renew(slot, token, lease_s)
                except (redis.RedisError, OSError):  # Redis away: retried at the next turn, within the lease
                    continue


class MemoryIdempotencyStore:
    """Embedded mode: a dictionary with expiry times."""

    def __init__(self, ttl_s: float) -> None:
        self.ttl_s = ttl_s
        self._slots: dict[str, tuple[float, dict[str, Any]]] = {}
        self._lock = threading.Lock()
        self._purged = time.monotonic()
        self.leases = Leases(self)

    def claim(self, slot: str, fingerprint: str, token: str, lease_s: float) -> dict[str, Any] | None:
        now = time.monotonic()
        with self._lock:
            if now - self._purged > PURGE_INTERVAL_S:
                for expired in [k for k, (t, _) in self._slots.items() if t < now]:
                    del self._slots[expired]
                self._purged = now
            held = self._slots.get(slot)
            if held is not None and held[0] >= now:
                return held[1]
            self._slots[slot] = (now + lease_s, {"fingerprint": fingerprint, "response": None, "token": token})
            return None

    def renew(self, slot: str, token: str, lease_s: float) -> bool:
        with self._lock:
            held = self._slots.get(slot)
            if held is None or held[1].get("token") != token:
                return False
            self._slots[slot] = (max(held[0], time.monotonic() + lease_s), held[1])
            return True

    def complete(self, slot: str, fingerprint: str, response: dict[str, Any]) -> None:
        with self._lock:
            self._slots[slot] = (time.monotonic() + self.ttl_s, {"fingerprint": fingerprint, "response": response})

    def release(self, slot: str, token: str) -> None:
        with self._lock:
            held = self._slots.get(slot)
            if held is not None and held[1].get("token") == token:
                del self._slots[slot]


#: KEYS: the slot; ARGV: token, lease (ms). Extends the slot's claim if it is still the token's.
_RENEW = """
local v = redis.call('GET', KEYS[1])
if v and cjson.decode(v)['token'] == ARGV[1] then return redis.call('PEXPIRE', KEYS[1], ARGV[2]) end
return 0
"""
#: KEYS: the slot; ARGV: token. Deletes the slot if it is still the token's claim.
_RELEASE = """
local v = redis.call('GET', KEYS[1])
if v and cjson.decode(v)['token'] == ARGV[1] then return redis.call('DEL', KEYS[1]) end
return 0
"""


class RedisIdempotencyStore:
    """Queue mode: ``nonholonomic:idempotency:{owner}:{key}`` (SET NX), shared by every API process; a
    claim expires after its lease unless the API serving it renews it, a response after ``ttl_s``."""

    def __init__(self, client: redis.Redis, ttl_s: int) -> None:
        self.client, self.ttl_s = client, ttl_s
        self._renew = client.register_script(_RENEW)
        self._release = client.register_script(_RELEASE)
        self.leases = Leases(self)

    def claim(self, slot: str, fingerprint: str, token: str, lease_s: float) -> dict[str, Any] | None:
        pending = json.dumps({"fingerprint": fingerprint, "response": None, "token": token})
        for _ in range(3):  # a claim that expires between SET NX and GET: claim again
            if self.client.set(PREFIX + slot, pending, nx=True, px=max(1, int(lease_s * 1000))):
                return None
            stored = self.client.get(PREFIX + slot)
            if stored is not None:
                return json.loads(stored)
        raise redis.RedisError("an Idempotency-Key claim kept expiring")

    def renew(self, slot: str, token: str, lease_s: float) -> bool:
        return bool(self._renew(keys=[PREFIX + slot], args=[token, max(1, int(lease_s * 1000))]))

    def complete(self, slot: str, fingerprint: str, response: dict[str, Any]) -> None:
        self.client.set(PREFIX + slot, json.dumps({"fingerprint": fingerprint, "response": response}), ex=self.ttl_s)

    def release(self, slot: str, token: str) -> None:
        self._release(keys=[PREFIX + slot], args=[token])


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


def idempotent(request: Request, owner: str | None, body: Any,
               create: Callable[[], tuple[dict[str, Any], dict[str, str]]]) -> JSONResponse:
    """Answer ``owner``'s creating POST: ``create()`` returns the 202 body and headers. With an
    ``Idempotency-Key`` the first response is stored and a retry gets it again (see the module's docstring);
    keys are ``owner``'s own."""
    key = _key(request)
    if key is None:
        content, headers = create()
        return JSONResponse(content, status_code=202, headers=headers)
    store: IdempotencyStore = request.app.state.idempotency
    slot = f"{owner or '-'}:{key}"
    mark = fingerprint(request.url.path, body)
    lease_s = request.app.state.settings.idempotency_lease_s
    token = uuid.uuid4().hex
    stored = store.claim(slot, mark, token, lease_s)
    if stored is not None:
        if stored["fingerprint"] != mark:
            raise invalid_request([FieldError(field=HEADER, reason=(
                "this key was used with another request (path or body); send a new key for a new request"))])
        if stored["response"] is None:
            raise ProblemError(409, "Request in progress", f"the first request with this {HEADER} is still being "
                               f"served; retry in a moment (if the service stopped while serving it, the key is "
                               f"free again within {lease_s:g} s)", CONFLICT, headers={"Retry-After": "1"})
        response = stored["response"]
        return JSONResponse(response["content"], status_code=202,
                            headers={**response["headers"], "Idempotent-Replayed": "true"})
    store.leases.hold(slot, token, lease_s)
    try:
        try:
            content, headers = create()
        except BaseException:
            store.release(slot, token)
            raise
        store.complete(slot, mark, {"content": content, "headers": headers})
    finally:
        store.leases.drop(token)
    return JSONResponse(content, status_code=202, headers=headers)


def idempotency_store(backend: JobBackend, ttl_s: int) -> IdempotencyStore:
    """Redis's in queue mode (shared by every API process), else in memory."""
    client = backend.redis
    return RedisIdempotencyStore(client, ttl_s) if client is not None else MemoryIdempotencyStore(ttl_s)
