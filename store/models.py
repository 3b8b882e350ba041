"""The tables (SQLAlchemy 2 declarative). Their history is in ``store/migrations/versions``."""

from __future__ import annotations

from typing import Any

from sqlalchemy import JSON, Boolean, Float, Index, Integer, String
from sqlalchemy.dialects.postgresql import JSONB
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

#: JSON documents: JSONB on PostgreSQL, JSON (text) elsewhere.
Document = JSON().with_variant(JSONB(), "postgresql")


class Base(DeclarativeBase):
    pass


class JobRow(Base):
    """A job: its request, its status, and once it ended its result or error.

    ``created`` (epoch seconds) orders the list (keyset pagination on ``(created, id)``);
    ``created_at`` is the same instant as the ISO 8601 string the API gave out at submission.
    """

    __tablename__ = "jobs"

    id: Mapped[str] = mapped_column(String(64), primary_key=True)
    owner: Mapped[str | None] = mapped_column(String(128), nullable=True)
    status: Mapped[str] = mapped_column(String(16))
    request: Mapped[dict[str, Any]] = mapped_column(Document)
    result: Mapped[dict[str, Any] | None] = mapped_column(Document, nullable=True)
    error: Mapped[dict[str, Any] | None] = mapped_column(Document, nullable=True)
    created: Mapped[float] = mapped_column(Float)
    created_at: Mapped[str] = mapped_column(String(40))
    finished: Mapped[float | None] = mapped_column(Float, nullable=True)
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    #: The heartbeat key of the worker running it (workers.heartbeat), while it runs.
    worker: Mapped[str | None] = mapped_column(String(200), nullable=True)
    #: The queue it was sent to, and the broker's epoch then (a new epoch: the broker lost its messages).
    queue: Mapped[str | None] = mapped_column(String(200), nullable=True)
    broker_epoch: Mapped[str | None] = mapped_column(String(64), nullable=True)

    __table_args__ = (
        Index("ix_jobs_created_id", "created", "id"),
        Index("ix_jobs_owner_status", "owner", "status"),
        Index("ix_jobs_status", "status"),
    )


class EnsembleRow(Base):
    """An ensemble: its request, its chunks' member ranges, whether it was cancelled, and how its chunks
    were sent (the queue and the broker's epoch, as for a job)."""

    __tablename__ = "ensembles"

    id: Mapped[str] = mapped_column(String(64), primary_key=True)
    owner: Mapped[str | None] = mapped_column(String(128), nullable=True)
    request: Mapped[dict[str, Any]] = mapped_column(Document)
    #: ``[[start, stop], ...]``: the members of each chunk.
    chunks: Mapped[list[list[int]]] = mapped_column(Document)
    created: Mapped[float] = mapped_column(Float)
    created_at: Mapped[str] = mapped_column(String(40))
    cancelled: Mapped[bool] = mapped_column(Boolean, default=False)
    queue: Mapped[str | None] = mapped_column(String(200), nullable=True)
    broker_epoch: Mapped[str | None] = mapped_column(String(64), nullable=True)

    __table_args__ = (Index("ix_ensembles_created", "created"),)


class EnsembleChunkRow(Base):
    """One chunk of an ensemble: its progress while it runs, then its members' results and digests,
    written in one statement with ``done`` (a chunk run twice is counted once)."""

    __tablename__ = "ensemble_chunks"

    ensemble_id: Mapped[str] = mapped_column(String(64), primary_key=True)
    chunk: Mapped[int] = mapped_column(Integer, primary_key=True)
    done: Mapped[bool] = mapped_column(Boolean, default=False)
    members_done: Mapped[int] = mapped_column(Integer, default=0)
    #: How many times a worker started it (more than once: redelivered).
    starts: Mapped[int] = mapped_column(Integer, default=0)
    #: The worker that finished it.
    worker: Mapped[str | None] = mapped_column(String(200), nullable=True)
    members: Mapped[list[dict[str, Any]] | None] = mapped_column(Document, nullable=True)
    digests: Mapped[list[dict[str, Any]] | None] = mapped_column(Document, nullable=True)

    __table_args__ = (Index("ix_ensemble_chunks_pending", "ensemble_id", "done"),)


class IdempotencyKeyRow(Base):
    """An ``Idempotency-Key`` bound to what its first request created: written in the same transaction as
    that job or ensemble (:mod:`store.idempotency`), so a key can never make two, whatever process dies when.

    ``slot`` is ``owner:key`` (``-:key`` when keys are off); ``fingerprint`` the SHA-256 of the request's
    path and canonical body; ``resource`` the job's or ensemble's id.
    """

    __tablename__ = "idempotency_keys"

    slot: Mapped[str] = mapped_column(String(400), primary_key=True)
    fingerprint: Mapped[str] = mapped_column(String(64))
    resource: Mapped[str] = mapped_column(String(64))
    created: Mapped[float] = mapped_column(Float)

    __table_args__ = (Index("ix_idempotency_keys_created", "created"),)
