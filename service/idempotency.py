"""``Idempotency-Key`` on the POSTs that create work (IETF draft "The Idempotency-Key HTTP Header Field").

A client that sends ``Idempotency-Key: <key>`` with ``POST /v1/jobs``, ``/v1/ensembles`` or
``/v1/paper/report`` may retry the request safely: the same key with the same body (same path and
the same JSON, whatever the key order) answers the first request's response again (202, the same id
and ``Location``) without creating anything; the same key with another body is a 422 naming the
header; the same key while the first request is still being served is a 409. Keys are kept per API
key owner for the jobs' time to live; a request refused (4xx, 503) binds nothing.

Exactly once across crashes (issue 34, item 1): the key is bound to its job or ensemble in the
database, in the transaction that records it (:mod:`store.idempotency`), in both modes. A request whose
API dies before that commit leaves neither, and its retry creates the job; one that dies after leaves
both, and its retry answers that job. "Still being served" is that transaction being open (PostgreSQL's
advisory lock, across API processes), or a request of this process holding the key (:data:`_serving`).
"""

from __future__ import annotations

import hashlib
import json
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from fastapi import Request
from fastapi.responses import JSONResponse

from schemas.problems import CONFLICT, FieldError
from service.backends.base import JobBackend
from service.errors import ProblemError, invalid_request
from store.idempotency import KeyBinding, KeyBound, KeyInProgress

HEADER = "Idempotency-Key"
#: Descriptions of the problems of a creating POST (OpenAPI).
IDEMPOTENCY_IN_PROGRESS = "the first request with this Idempotency-Key is still being served"
IDEMPOTENCY_MISMATCH = "; or an Idempotency-Key used before with another body"
QUEUE_BOUNDS = ("the key has max_active_jobs_per_key queued or running jobs, or the queue would hold more than "
                "max_queued_messages (an ensemble counts each chunk); `Retry-After` says when to retry")
#: Longest accepted key.
MAX_KEY_LENGTH = 255

#: The slots (``owner:key``) this process is serving now.
_serving: set[str] = set()
_serving_lock = threading.Lock()

#: A creating route's two halves: ``create(binding)`` records the work (binding the key, if any) and returns
#: its id; ``respond(id)`` is the 202's body and headers, the same for the first request and a replay.
Create = Callable[[KeyBinding | None], str]
Respond = Callable[[str], tuple[dict[str, Any], dict[str, str]]]


def _in_progress() -> ProblemError:
    return ProblemError(409, "Request in progress", f"the first request with this {HEADER} is still being served; "
                        "retry in a moment (if the service stopped while serving it, the key is free again as soon "
                        "as the database has rolled its transaction back)", CONFLICT, headers={"Retry-After": "1"})


@contextmanager
def _served(slot: str) -> Iterator[None]:
    """Hold ``slot`` in this process while the body serves it; a 409 if another request holds it."""
    with _serving_lock:
        if slot in _serving:
            raise _in_progress()
        _serving.add(slot)
    try:
        yield
    finally:
        with _serving_lock:
            _serving.discard(slot)


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


def idempotent(request: Request, owner: str | None, body: Any, create: Create, respond: Respond) -> JSONResponse:
    """Answer ``owner``'s creating POST (see :data:`Create` and :data:`Respond`). With an
    ``Idempotency-Key`` the key is bound to what ``create`` records, in its transaction, and a retry gets
    the same answer (see the module's docstring); keys are ``owner``'s own."""
    key = _key(request)
    if key is None:
        content, headers = respond(create(None))
        return JSONResponse(content, status_code=202, headers=headers)
    backend: JobBackend = request.app.state.backend
    slot = f"{owner or '-'}:{key}"
    mark = fingerprint(request.url.path, body)
    with _served(slot):
        stored = backend.keys.bound(slot)  # a retry of a request served: answered before any admission
        if stored is None:
            try:
                content, headers = respond(create(KeyBinding(slot, mark)))
                return JSONResponse(content, status_code=202, headers=headers)
            except KeyInProgress:
                raise _in_progress() from None
            except KeyBound as bound:  # bound by another API process since the lookup
                stored = (bound.fingerprint, bound.resource)
    fingerprint_then, resource = stored
    if fingerprint_then != mark:
        raise invalid_request([FieldError(field=HEADER, reason=(
            "this key was used with another request (path or body); send a new key for a new request"))])
    content, headers = respond(resource)
    return JSONResponse(content, status_code=202, headers={**headers, "Idempotent-Replayed": "true"})
