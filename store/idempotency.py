"""Idempotency-Keys bound to the job or ensemble their first request created, in that record's transaction.

A creating POST with a key calls :func:`bind` inside the transaction that records its job or ensemble:

- on PostgreSQL it first takes the key's transaction-level advisory lock without waiting; another
  transaction holding it is a request with the same key still being served (:class:`KeyInProgress`).
  The lock ends with that transaction: its commit, its rollback, or its connection closing with a
  process that died;
- a row for the key is what an earlier request created (:class:`KeyBound`: the caller answers it again,
  or refuses another body);
- else the row is inserted, and commits or rolls back with the job's or ensemble's row.

So no moment exists in which a job is recorded without its key or a key without its job: a retry after
any crash finds either both or neither (issue 34, item 1). SQLite (one embedded API process) has no
advisory locks; the API's in-process guard (:mod:`service.idempotency`) keeps two requests with one
key apart there.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Any, cast

from sqlalchemy import Connection, Engine, Table, delete, insert, select, text
from sqlalchemy.exc import IntegrityError

from store.models import IdempotencyKeyRow

_KEYS = cast(Table, IdempotencyKeyRow.__table__)


@dataclass(frozen=True)
class KeyBinding:
    """What a keyed request binds: its ``slot`` (``owner:key``) to its ``fingerprint`` (path and body)."""

    slot: str
    fingerprint: str


class KeyInProgress(Exception):
    """Another transaction is binding this key now (its request is still being served)."""


class KeyBound(Exception):
    """The key is bound already: to ``resource``, by a request with ``fingerprint``."""

    def __init__(self, fingerprint: str, resource: str) -> None:
        super().__init__(f"bound to {resource}")
        self.fingerprint, self.resource = fingerprint, resource


def lock_id(slot: str) -> int:
    """The slot's advisory lock: a signed 64-bit key from its SHA-256 (one-key locks do not share the
    two-key space of the owners' admission locks, :func:`store.jobs.owner_lock_key`)."""
    return int.from_bytes(hashlib.sha256(slot.encode()).digest()[:8], "big", signed=True)


def bind(connection: Connection, binding: KeyBinding, resource: str, created: float) -> None:
    """Inside the caller's transaction on ``connection``: bind ``binding.slot`` to ``resource``, or raise
    :class:`KeyInProgress` or :class:`KeyBound` (the caller's transaction then rolls back)."""
    if connection.dialect.name == "postgresql":
        if not connection.scalar(text("SELECT pg_try_advisory_xact_lock(:id)"), {"id": lock_id(binding.slot)}):
            raise KeyInProgress(binding.slot)
    row = connection.execute(select(_KEYS.c.fingerprint, _KEYS.c.resource).where(_KEYS.c.slot == binding.slot)).first()
    if row is not None:
        raise KeyBound(row.fingerprint, row.resource)
    try:
        connection.execute(insert(_KEYS).values(slot=binding.slot, fingerprint=binding.fingerprint,
                                                resource=resource, created=created))
    except IntegrityError:  # bound meanwhile (SQLite from another process): the retry replays it
        raise KeyInProgress(binding.slot) from None


def unbind(connection: Connection, slot: str, resource: str) -> None:
    """Free ``slot`` if it is bound to ``resource`` (whose messages the broker refused: nothing was accepted)."""
    connection.execute(delete(_KEYS).where(_KEYS.c.slot == slot, _KEYS.c.resource == resource))


def delete_expired(connection: Connection, horizon: float) -> int:
    """Delete the keys bound before ``horizon`` (epoch seconds); returns how many."""
    return int(connection.execute(delete(_KEYS).where(_KEYS.c.created < horizon)).rowcount)


class IdempotencyKeys:
    """Reading the keys of the database of ``engine`` (the job store's)."""

    def __init__(self, engine: Engine) -> None:
        self.engine = engine

    def bound(self, slot: str) -> tuple[str, str] | None:
        """``(fingerprint, resource)`` of a bound key, None if it is free."""
        with self.engine.connect() as connection:
            row: Any = connection.execute(select(_KEYS.c.fingerprint, _KEYS.c.resource)
                                          .where(_KEYS.c.slot == slot)).first()
        return None if row is None else (row.fingerprint, row.resource)
