"""Ensemble chunks: the function a worker (Celery task or embedded thread) runs for one chunk, and
the stores that keep an ensemble's parent record.

The parent record counts finished chunks as a *set* of chunk indices, and a chunk's members are
written with its index in one transaction, so a chunk that runs twice (redelivered after its worker
died) replaces its own results with the same numbers and is counted once. Progress is members done
per chunk, written while the chunk runs; cancellation is a flag every running chunk reads.
"""

from __future__ import annotations

import json
import threading
import time
from datetime import datetime, timezone
from typing import Any, Protocol

import redis

from nonholonomic.analysis.ensemble import digest, run_chunk
from nonholonomic.integration import IntegrationCancelled
from schemas.ensembles import EnsembleRequest
from schemas.results import member_to_json

KEY_PREFIX = "nonholonomic:ensemble:"
#: Seconds between progress writes (and cancellation checks) of a running chunk.
PROGRESS_INTERVAL_S = 0.2


class EnsembleStore(Protocol):
    """Where an ensemble's parent record, progress and member results live."""

    def create(self, ensemble_id: str, request: dict[str, Any], chunks: list[tuple[int, int]],
               owner: str | None = None) -> str: ...
    def record(self, ensemble_id: str) -> dict[str, Any] | None: ...
    def spec(self, ensemble_id: str) -> tuple[dict[str, Any], list[tuple[int, int]]] | None: ...
    def is_cancelled(self, ensemble_id: str) -> bool: ...
    def cancel(self, ensemble_id: str) -> None: ...
    def chunk_done(self, ensemble_id: str, chunk: int) -> bool: ...
    def set_progress(self, ensemble_id: str, chunk: int, members_done: int) -> None: ...
    def mark_started(self, ensemble_id: str, chunk: int) -> None: ...
    def store_chunk(self, ensemble_id: str, chunk: int, members: list[dict[str, Any]],
                    digests: list[dict[str, Any]], worker: str) -> None: ...
    def chunk_members(self, ensemble_id: str, chunk: int) -> list[dict[str, Any]] | None: ...


def _now() -> str:
    return datetime.now(timezone.utc).isoformat()


class MemoryEnsembleStore:
    """The store of embedded mode: dictionaries under a lock."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._records: dict[str, dict[str, Any]] = {}

    def create(self, ensemble_id: str, request: dict[str, Any], chunks: list[tuple[int, int]],
               owner: str | None = None) -> str:
        created_at = _now()
        with self._lock:
            self._records[ensemble_id] = {"request": request, "created_at": created_at, "chunks": chunks,
                                          "owner": owner,
                                          "cancelled": False, "done": set(), "progress": {}, "digests": {},
                                          "workers": {}, "members": {}, "starts": {}}
        return created_at

    def record(self, ensemble_id: str) -> dict[str, Any] | None:
        with self._lock:
            r = self._records.get(ensemble_id)
            if r is None:
                return None
            return {"request": r["request"], "created_at": r["created_at"], "chunks": r["chunks"],
                    "owner": r["owner"], "cancelled": r["cancelled"], "done": set(r["done"]), "progress": dict(r["progress"]),
                    "digests": dict(r["digests"]), "workers": dict(r["workers"]), "starts": dict(r["starts"])}

    def spec(self, ensemble_id: str) -> tuple[dict[str, Any], list[tuple[int, int]]] | None:
        r = self._records.get(ensemble_id)
        return None if r is None else (r["request"], r["chunks"])

    def is_cancelled(self, ensemble_id: str) -> bool:
        return bool(self._records.get(ensemble_id, {}).get("cancelled"))

    def cancel(self, ensemble_id: str) -> None:
        with self._lock:
            self._records[ensemble_id]["cancelled"] = True

    def chunk_done(self, ensemble_id: str, chunk: int) -> bool:
        return chunk in self._records[ensemble_id]["done"]

    def set_progress(self, ensemble_id: str, chunk: int, members_done: int) -> None:
        with self._lock:
            self._records[ensemble_id]["progress"][chunk] = members_done

    def mark_started(self, ensemble_id: str, chunk: int) -> None:
        with self._lock:
            starts = self._records[ensemble_id]["starts"]
            starts[chunk] = starts.get(chunk, 0) + 1

    def store_chunk(self, ensemble_id: str, chunk: int, members: list[dict[str, Any]],
                    digests: list[dict[str, Any]], worker: str) -> None:
        with self._lock:
            r = self._records[ensemble_id]
            r["members"][chunk], r["digests"][chunk], r["workers"][chunk] = members, digests, worker
            r["done"].add(chunk)

    def chunk_members(self, ensemble_id: str, chunk: int) -> list[dict[str, Any]] | None:
        return self._records[ensemble_id]["members"].get(chunk)


class RedisEnsembleStore:
    """The store of queue mode: ``nonholonomic:ensemble:{id}`` (hash: request, created_at, chunks,
    cancelled) and beside it ``:done`` (set of finished chunks), ``:progress``, ``:digests``,
    ``:workers``, ``:starts`` (hashes by chunk) and ``:chunk:{i}`` (the members' results), all with the job TTL."""

    def __init__(self, client: redis.Redis, ttl_s: int) -> None:
        self.client, self.ttl_s = client, ttl_s

    @staticmethod
    def key(ensemble_id: str, part: str = "") -> str:
        return KEY_PREFIX + ensemble_id + (f":{part}" if part else "")

    def create(self, ensemble_id: str, request: dict[str, Any], chunks: list[tuple[int, int]],
               owner: str | None = None) -> str:
        created_at = _now()
        pipe = self.client.pipeline()
        pipe.hset(self.key(ensemble_id), mapping={"request": json.dumps(request), "created_at": created_at,
                                                  "chunks": json.dumps(chunks), "cancelled": "0",
                                                  **({"owner": owner} if owner else {})})
        pipe.expire(self.key(ensemble_id), self.ttl_s)
        pipe.execute()
        return created_at

    def record(self, ensemble_id: str) -> dict[str, Any] | None:
        pipe = self.client.pipeline()
        pipe.hgetall(self.key(ensemble_id))
        pipe.smembers(self.key(ensemble_id, "done"))
        pipe.hgetall(self.key(ensemble_id, "progress"))
        pipe.hgetall(self.key(ensemble_id, "digests"))
        pipe.hgetall(self.key(ensemble_id, "workers"))
        pipe.hgetall(self.key(ensemble_id, "starts"))
        raw, done, progress, digests, workers, starts = pipe.execute()
        if not raw:
            return None
        fields = {k.decode(): v.decode() for k, v in raw.items()}
        return {"request": json.loads(fields["request"]), "created_at": fields["created_at"],
                "chunks": [tuple(c) for c in json.loads(fields["chunks"])],
                "owner": fields.get("owner"), "cancelled": fields.get("cancelled") == "1",
                "done": {int(c) for c in done},
                "progress": {int(k): int(v) for k, v in progress.items()},
                "digests": {int(k): json.loads(v) for k, v in digests.items()},
                "workers": {int(k): v.decode() for k, v in workers.items()},
                "starts": {int(k): int(v) for k, v in starts.items()}}

    def spec(self, ensemble_id: str) -> tuple[dict[str, Any], list[tuple[int, int]]] | None:
        request, chunks = self.client.hmget(self.key(ensemble_id), "request", "chunks")
        if request is None or chunks is None:
            return None
        return json.loads(request), [tuple(c) for c in json.loads(chunks)]

    def is_cancelled(self, ensemble_id: str) -> bool:
        return self.client.hget(self.key(ensemble_id), "cancelled") == b"1"

    def cancel(self, ensemble_id: str) -> None:
        self.client.hset(self.key(ensemble_id), "cancelled", "1")

    def chunk_done(self, ensemble_id: str, chunk: int) -> bool:
        return bool(self.client.sismember(self.key(ensemble_id, "done"), chunk))

    def set_progress(self, ensemble_id: str, chunk: int, members_done: int) -> None:
        pipe = self.client.pipeline()
        pipe.hset(self.key(ensemble_id, "progress"), chunk, members_done)
        pipe.expire(self.key(ensemble_id, "progress"), self.ttl_s)
        pipe.execute()

    def mark_started(self, ensemble_id: str, chunk: int) -> None:
        pipe = self.client.pipeline()
        pipe.hincrby(self.key(ensemble_id, "starts"), chunk, 1)
        pipe.expire(self.key(ensemble_id, "starts"), self.ttl_s)
        pipe.execute()

    def store_chunk(self, ensemble_id: str, chunk: int, members: list[dict[str, Any]],
                    digests: list[dict[str, Any]], worker: str) -> None:
        pipe = self.client.pipeline(transaction=True)  # all or nothing: counted once with its results
        pipe.set(self.key(ensemble_id, f"chunk:{chunk}"), json.dumps(members), ex=self.ttl_s)
        for part, value in (("digests", json.dumps(digests)), ("workers", worker)):
            pipe.hset(self.key(ensemble_id, part), chunk, value)
            pipe.expire(self.key(ensemble_id, part), self.ttl_s)
        pipe.sadd(self.key(ensemble_id, "done"), chunk)
        pipe.expire(self.key(ensemble_id, "done"), self.ttl_s)
        pipe.execute()

    def chunk_members(self, ensemble_id: str, chunk: int) -> list[dict[str, Any]] | None:
        raw = self.client.get(self.key(ensemble_id, f"chunk:{chunk}"))
        return None if raw is None else json.loads(raw)


def run_ensemble_chunk(store: EnsembleStore, ensemble_id: str, chunk: int, worker: str) -> str:
    """Run chunk ``chunk`` of an ensemble and store its members' results.

    Returns what happened: ``"done"``, ``"already done"`` (a redelivered chunk whose results are
    stored), ``"cancelled"``. A chunk that fails as a whole (a bug, a time limit) stores every one
    of its members as failed with the reason, so the ensemble still completes.
    """
    if store.is_cancelled(ensemble_id):
        return "cancelled"
    if store.chunk_done(ensemble_id, chunk):
        return "already done"
    spec = store.spec(ensemble_id)
    if spec is None:
        return "cancelled"  # expired or never created
    start, stop = spec[1][chunk]
    store.mark_started(ensemble_id, chunk)
    request = EnsembleRequest.model_validate(spec[0])
    last = [time.monotonic()]

    def progress(fraction: float) -> bool:
        now = time.monotonic()
        if now - last[0] < PROGRESS_INTERVAL_S:
            return True
        last[0] = now
        if store.is_cancelled(ensemble_id):
            return False
        store.set_progress(ensemble_id, chunk, int(fraction * (stop - start)))
        return True

    try:
        members = request.members_list(start, stop)
        results = run_chunk(
            request.definition(), members, request.t_final, request.samples, checks=request.checks,
            poincare=request.poincare.options() if request.poincare else None,
            lyapunov=request.lyapunov.options() if request.lyapunov else None,
            tolerance=request.integrator.tolerance,
            parameter_groups=request.system.parameter_values(),  # type: ignore[attr-defined]
            progress=progress)
    except IntegrationCancelled:
        return "cancelled"
    except Exception as exc:  # noqa: BLE001 - the chunk's members fail with the reason, the ensemble goes on
        reason = f"the chunk failed: {type(exc).__name__}: {exc}"
        failed = [{"index": i, "status": "failed", "error": reason} for i in range(start, stop)]
        store.store_chunk(ensemble_id, chunk, failed, failed, worker)
        return "failed"
    store.store_chunk(ensemble_id, chunk, [member_to_json(m) for m in results], [digest(m) for m in results],
                      worker)
    return "done"
