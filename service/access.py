"""Access: optional API keys, each key's own jobs, per-key rate limits.

Off unless keys are configured (``NONHOLONOMIC_API_KEYS`` and/or ``NONHOLONOMIC_API_KEYS_FILE``,
entries ``name:key`` or ``key``). With keys, every ``/v1`` route needs one, sent as
``Authorization: Bearer <key>`` or ``X-API-Key: <key>`` (else 401); the key's *owner* (its name,
or ``key-`` and 12 hex digits of its SHA-256) is recorded with each job and ensemble it submits,
and another key gets a 404 for it, as for an id that does not exist. Jobs sent straight to the
broker (no owner) are visible to every key. ``/health``, ``/docs`` and ``/openapi.json`` need no key.

Guessing keys is rate limited: a client address that sent ``auth_failures_per_minute`` unknown keys
gets a 429 with ``Retry-After`` for every request with a key it has not used successfully from that
address in the last :data:`KNOWN_FOR_S`, right or wrong, until its bucket refills: a guess answers
nothing while it is limited. A key already at work from that address (a colleague behind the same NAT
as the guesser) is served as always (issue 34, item 5): guessing the keys already at work from an
address is the one answer a limited address still gets, and a key's length answers that (make keys
random, 32 bytes: ``openssl rand -hex 32``).
Behind a reverse proxy the address is the proxy's
unless uvicorn runs with ``--proxy-headers`` and the proxy is trusted (``--forwarded-allow-ips``).
An unknown job id and another key's answer the same 404 after the same lookups (:func:`job_of`). A job or an
ensemble is also found by the first 6 or more characters of its id when they are the caller's only one
that starts so (a 409 names the candidates otherwise).
"""

from __future__ import annotations

import hashlib
import hmac
import math
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fastapi import Request

from schemas.problems import CONFLICT, NOT_FOUND, RATE_LIMITED, UNAUTHORIZED
from schemas.settings import Settings
from service import metrics
from service.errors import ProblemError
from store.listing import is_prefix

if TYPE_CHECKING:
    from service.backends.base import JobBackend, JobRecord


def _owner_of(name: str | None, key: str) -> str:
    return name or "key-" + hashlib.sha256(key.encode()).hexdigest()[:12]


def load_keys(settings: Settings) -> dict[str, str]:
    """SHA-256 of each configured key → its owner. Raises ValueError for an empty or duplicated key."""
    entries = [e.strip() for e in (settings.api_keys or "").split(",") if e.strip()]
    if settings.api_keys_file:
        lines = Path(settings.api_keys_file).read_text().splitlines()
        entries += [line.strip() for line in lines if line.strip() and not line.lstrip().startswith("#")]
    keys: dict[str, str] = {}
    for entry in entries:
        name, _, key = entry.rpartition(":")
        if not key:
            raise ValueError("an API key entry has an empty key")
        digest = hashlib.sha256(key.encode()).hexdigest()
        if digest in keys:
            raise ValueError("an API key is listed twice")
        keys[digest] = _owner_of(name or None, key)
    return keys


@dataclass
class _Bucket:
    tokens: float
    updated: float


@dataclass
class RateLimiter:
    """A token bucket per owner: ``per_minute`` requests a minute, bursts up to ``per_minute``
    (per API process)."""

    per_minute: int
    _buckets: dict[str, _Bucket] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def wait_s(self, owner: str) -> float:
        """0 if ``owner`` may make a request now (one token taken), else seconds until it may."""
        rate = self.per_minute / 60.0
        now = time.monotonic()
        with self._lock:
            bucket = self._buckets.setdefault(owner, _Bucket(float(self.per_minute), now))
            bucket.tokens = min(float(self.per_minute), bucket.tokens + (now - bucket.updated) * rate)
            bucket.updated = now
            if bucket.tokens >= 1.0:
                bucket.tokens -= 1.0
                return 0.0
            return (1.0 - bucket.tokens) / rate


#: Client addresses whose failure buckets are kept; beyond, the full (refilled) ones are dropped.
MAX_TRACKED_ADDRESSES = 10_000
#: Seconds a key used successfully from an address stays exempt from that address's failure limit.
KNOWN_FOR_S = 3600.0
#: (address, owner) pairs remembered as known; beyond, the oldest are forgotten.
MAX_KNOWN_PAIRS = 10_000


@dataclass
class KnownKeys:
    """The owners whose key was used successfully from each address, and when last (per API process)."""

    _seen: dict[tuple[str, str], float] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def saw(self, address: str, owner: str) -> None:
        now = time.monotonic()
        with self._lock:
            self._seen.pop((address, owner), None)  # re-inserted last: the dict is ordered by last use
            self._seen[(address, owner)] = now
            while len(self._seen) > MAX_KNOWN_PAIRS:
                del self._seen[next(iter(self._seen))]

    def known(self, address: str, owner: str | None) -> bool:
        if owner is None:
            return False
        with self._lock:
            when = self._seen.get((address, owner))
        return when is not None and time.monotonic() - when < KNOWN_FOR_S


@dataclass
class FailureLimiter:
    """A token bucket per client address, taken by each unknown key: ``per_minute`` failures a minute,
    bursts up to ``per_minute`` (per API process)."""

    per_minute: int
    _buckets: dict[str, _Bucket] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def _refilled(self, address: str, now: float) -> _Bucket:
        bucket = self._buckets.setdefault(address, _Bucket(float(self.per_minute), now))
        bucket.tokens = min(float(self.per_minute), bucket.tokens + (now - bucket.updated) * self.per_minute / 60.0)
        bucket.updated = now
        return bucket

    def wait_s(self, address: str) -> float:
        """0 if ``address`` may try a key now, else seconds until it may (a failure's token is back)."""
        now = time.monotonic()
        with self._lock:
            if address not in self._buckets:
                return 0.0
            bucket = self._refilled(address, now)
            return 0.0 if bucket.tokens >= 1.0 else (1.0 - bucket.tokens) * 60.0 / self.per_minute

    def failed(self, address: str) -> None:
        """Take one token from ``address``'s bucket."""
        now = time.monotonic()
        with self._lock:
            if len(self._buckets) >= MAX_TRACKED_ADDRESSES:
                for full in [a for a, b in self._buckets.items() if self._refilled(a, now).tokens >= self.per_minute]:
                    del self._buckets[full]
            bucket = self._refilled(address, now)
            bucket.tokens = max(0.0, bucket.tokens - 1.0)


class Access:
    """The API's keys and rate limiters (``app.state.access``)."""

    def __init__(self, settings: Settings) -> None:
        self.keys = load_keys(settings)
        self.limiter = RateLimiter(settings.rate_limit_per_minute) if settings.rate_limit_per_minute else None
        self.failures = FailureLimiter(settings.auth_failures_per_minute) if settings.auth_failures_per_minute else None
        self.known = KnownKeys()

    def owner(self, request: Request) -> str | None:
        """The caller's owner id (None when keys are off); 401 without a valid key, 429 past its rate."""
        if not self.keys:
            return None
        key = request.headers.get("x-api-key")
        authorization = request.headers.get("authorization", "")
        if key is None and authorization[:7].lower() == "bearer ":
            key = authorization[7:].strip()
        if not key:
            raise ProblemError(401, "API key required", "send your API key as 'Authorization: Bearer <key>' or "
                               "'X-API-Key: <key>'", UNAUTHORIZED, headers={"WWW-Authenticate": "Bearer"})
        address = request.client.host if request.client is not None else "-"
        digest = hashlib.sha256(key.encode()).hexdigest()
        owner = next((o for d, o in self.keys.items() if hmac.compare_digest(d, digest)), None)
        if self.failures is not None and not self.known.known(address, owner):
            wait = self.failures.wait_s(address)
            if wait > 0:  # a key new to this address, right or wrong, answers alike: a guess tells nothing
                retry = max(1, math.ceil(wait))
                metrics.refused("unknown_keys")
                raise ProblemError(429, "Too many unknown keys", f"this address sent more than "
                                   f"{self.failures.per_minute} unknown API keys in a minute; retry after {retry} s "
                                   "(keys already used from this address are served meanwhile)",
                                   RATE_LIMITED, headers={"Retry-After": str(retry)})
        if owner is None:
            if self.failures is not None:
                self.failures.failed(address)
            raise ProblemError(401, "Unknown API key", "the API key sent is not one of this service's",
                               UNAUTHORIZED, headers={"WWW-Authenticate": 'Bearer error="invalid_token"'})
        self.known.saw(address, owner)
        if self.limiter is not None:
            wait = self.limiter.wait_s(owner)
            if wait > 0:
                retry = max(1, math.ceil(wait))
                metrics.refused("rate_limited")
                raise ProblemError(429, "Rate limit", f"this key may make {self.limiter.per_minute} requests a "
                                   f"minute; retry after {retry} s", RATE_LIMITED, headers={"Retry-After": str(retry)})
        return owner


async def caller(request: Request) -> str | None:
    """FastAPI dependency: the caller's owner id (see :meth:`Access.owner`); routes take it as
    :data:`service.deps.Owner` (resolved once per request). Async, because it does not block: a sync
    dependency would cost every request a trip through the thread pool."""
    owner: str | None = request.app.state.access.owner(request)
    return owner


def job_of(backend: JobBackend, owner: str | None, job_id: str) -> JobRecord:
    """The job ``job_id`` if ``owner`` may see it, else a 404 (the same as for an unknown id).

    With keys on, whether the caller may see the job is asked first, in one lookup that costs the same
    for an unknown id and another key's job (the record, its result included, is read only when the
    caller may see it: :meth:`JobBackend.find`): the 404s are alike in status, body and work, so their
    timing tells nothing.
    """
    record = backend.find(job_id, owner)
    if record is None and is_prefix(job_id):  # the first characters of an id (a progress bar shows 8)
        full = _unique(backend.job_ids_with_prefix(job_id, owner), job_id, "job")
        record = backend.find(full, owner) if full is not None else None
    if record is None or not visible(record.owner, owner):
        raise ProblemError(404, "Unknown job", f"no job with id {job_id!r}", NOT_FOUND)
    return record


def _unique(found: list[str], prefix: str, what: str) -> str | None:
    """The one id of ``found`` (those starting with ``prefix`` the caller may see), None if there is none;
    a 409 naming them if there are several."""
    if len(found) > 1:
        shown = ", ".join(found[:5]) + (" ..." if len(found) > 5 else "")
        raise ProblemError(409, "Ambiguous id prefix", f"{len(found)}{'+' if len(found) > 5 else ''} {what}s start "
                           f"with {prefix!r}: {shown}; send more of the id", CONFLICT)
    return found[0] if found else None


def ensemble_of(backend: JobBackend, owner: str | None, ensemble_id: str) -> dict[str, Any]:
    """The ensemble's record if ``owner`` may see it, else a 404 (the same as for an unknown id).

    As for a job (:func:`job_of`), with keys on the visibility is asked first in one lookup that costs
    the same for an unknown id and another key's ensemble; the record is read only when it is visible.
    """
    store = backend.ensembles
    record = None if owner is not None and not store.visible(ensemble_id, owner) else store.record(ensemble_id)
    if record is None and is_prefix(ensemble_id):  # the first characters of an id (a progress bar shows 8)
        full = _unique(store.with_prefix(ensemble_id, owner), ensemble_id, "ensemble")
        record = store.record(full) if full is not None else None
    if record is None or not visible(record.get("owner"), owner):
        raise ProblemError(404, "Unknown ensemble", f"no ensemble with id {ensemble_id!r}", NOT_FOUND)
    return record


def visible(owner_of_item: str | None, caller_owner: str | None) -> bool:
    """Whether a job or ensemble owned by ``owner_of_item`` is the caller's to see: keys off, no owner
    (sent straight to the broker), or the same owner."""
    return caller_owner is None or owner_of_item is None or owner_of_item == caller_owner
