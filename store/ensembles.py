"""The ensemble store: ensembles' records, their chunks' progress and their members' results in the
job store's database (SQLAlchemy; the schema is migrated with the jobs', :meth:`store.jobs.JobStore.migrate`).

An ensemble counts its finished chunks by their ``done`` flag, and a chunk's members are written
with that flag in one statement, only while it is not set: a chunk that runs twice (redelivered after
its worker died or was cut off, or sent again after the broker lost its messages) keeps the results of
its first run to finish and is counted once. Ensembles are deleted ``ttl_s`` after their creation
once none of their chunks is pending (or they were cancelled).
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import Engine, and_, delete, exists, insert, or_, select, update
from sqlalchemy.orm import sessionmaker

from store.expiry import Expiry
from store.idempotency import KeyBinding, bind, unbind
from store.jobs import UNSENT_GRACE_S
from store.listing import ids_with_prefix, newest_first
from store.models import EnsembleChunkRow, EnsembleRow
from store.statements import autocommit, changed_one

_PENDING = exists().where(EnsembleChunkRow.ensemble_id == EnsembleRow.id, EnsembleChunkRow.done.is_(False))
#: The chunk columns an ensemble's status and progress are read from.
_CHUNK_STATE = (EnsembleChunkRow.chunk, EnsembleChunkRow.done, EnsembleChunkRow.members_done, EnsembleChunkRow.starts)


def _record(row: EnsembleRow, chunks: Sequence[Any], with_digests: bool) -> dict[str, Any]:
    """An ensemble's record (:meth:`EnsembleStore.record`) from its row and its chunks' rows; without digests the
    chunks' ``digests``, ``workers`` and ``starts`` are left empty (a list reads only status and progress)."""
    return {"id": row.id, "created": row.created, "request": row.request, "created_at": row.created_at,
            "chunks": [tuple(c) for c in row.chunks], "owner": row.owner, "cancelled": row.cancelled,
            "done": {c.chunk for c in chunks if c.done},
            "progress": {c.chunk: c.members_done for c in chunks if c.starts and not c.done},
            "digests": {c.chunk: c.digests for c in chunks if c.done} if with_digests else {},
            "workers": {c.chunk: c.worker for c in chunks if c.done} if with_digests else {},
            "starts": {c.chunk: c.starts for c in chunks if c.starts} if with_digests else {}}


class EnsembleStore:
    """Ensembles in the database of ``engine`` (shared with the :class:`store.jobs.JobStore`)."""

    def __init__(self, engine: Engine, ttl_s: int) -> None:
        self.engine, self.ttl_s = engine, ttl_s
        self._session = sessionmaker(engine, expire_on_commit=False)
        self._autocommit = autocommit(engine)
        self._expiry = Expiry(self.delete_expired)

    # -- writing ---------------------------------------------------------------------------------

    def create(self, ensemble_id: str, request: dict[str, Any], chunks: list[tuple[int, int]],
               owner: str | None = None, queue: str | None = None, broker_epoch: str | None = None,
               binding: KeyBinding | None = None) -> str:
        """Record an ensemble and its chunks, none started (``broker_epoch`` None: not sent yet, see
        :meth:`mark_sent`); returns its ``created_at`` (ISO 8601, UTC). With ``binding`` the
        Idempotency-Key is bound to it in the same transaction (:func:`store.idempotency.bind`, which
        raises, nothing recorded, if it cannot be)."""
        now = datetime.now(UTC)
        with self._session.begin() as session:
            if binding is not None:
                bind(session.connection(), binding, ensemble_id, now.timestamp())
            session.add(EnsembleRow(id=ensemble_id, owner=owner, request=request,
                                    chunks=[list(c) for c in chunks], created=now.timestamp(),
                                    created_at=now.isoformat(), cancelled=False, queue=queue,
                                    broker_epoch=broker_epoch))
            session.flush()
            session.execute(insert(EnsembleChunkRow), [
                {"ensemble_id": ensemble_id, "chunk": i, "done": False, "members_done": 0, "starts": 0}
                for i in range(len(chunks))])
        self._expiry.now_and_then(now.timestamp())
        return now.isoformat()

    def delete(self, ensemble_id: str, slot: str | None = None) -> None:
        """Forget an ensemble whose chunks could not be sent (the broker refused them), and free the
        Idempotency-Key ``slot`` bound to it, in one transaction."""
        with self._session.begin() as session:
            session.execute(delete(EnsembleChunkRow).where(EnsembleChunkRow.ensemble_id == ensemble_id))
            session.execute(delete(EnsembleRow).where(EnsembleRow.id == ensemble_id))
            if slot is not None:
                unbind(session.connection(), slot, ensemble_id)

    def mark_sent(self, ensemble_id: str, broker_epoch: str) -> None:
        """Its chunks' messages are in the broker (as :meth:`store.jobs.JobStore.mark_sent`)."""
        changed_one(self._autocommit, update(EnsembleRow).where(EnsembleRow.id == ensemble_id,
                                                                EnsembleRow.broker_epoch.is_(None))
                    .values(broker_epoch=broker_epoch))

    def cancel(self, ensemble_id: str) -> None:
        changed_one(self._autocommit, update(EnsembleRow).where(EnsembleRow.id == ensemble_id).values(cancelled=True))

    def mark_started(self, ensemble_id: str, chunk: int) -> None:
        self._update_chunk(ensemble_id, chunk, starts=EnsembleChunkRow.starts + 1)

    def set_progress(self, ensemble_id: str, chunk: int, members_done: int) -> None:
        """The members a running chunk has finished (not for a chunk already done)."""
        changed_one(self._autocommit, update(EnsembleChunkRow)
                    .where(EnsembleChunkRow.ensemble_id == ensemble_id, EnsembleChunkRow.chunk == chunk,
                           EnsembleChunkRow.done.is_(False))
                    .values(members_done=members_done))

    def store_chunk(self, ensemble_id: str, chunk: int, members: list[dict[str, Any]],
                    digests: list[dict[str, Any]], worker: str) -> bool:
        """A chunk's members' results and digests, and ``done``, in one statement, unless the chunk is
        done already: the first run to finish is the one kept, and a late run (its worker was cut off
        while another ran the chunk again) changes nothing. True if this call stored the chunk."""
        return changed_one(self._autocommit, update(EnsembleChunkRow)
                           .where(EnsembleChunkRow.ensemble_id == ensemble_id, EnsembleChunkRow.chunk == chunk,
                                  EnsembleChunkRow.done.is_(False))
                           .values(members=members, digests=digests, worker=worker, done=True,
                                   members_done=len(members)))

    def _update_chunk(self, ensemble_id: str, chunk: int, **values: Any) -> None:
        changed_one(self._autocommit, update(EnsembleChunkRow)
                    .where(EnsembleChunkRow.ensemble_id == ensemble_id, EnsembleChunkRow.chunk == chunk)
                    .values(**values))

    def resend_claim(self, ensemble_id: str, old_epoch: str | None, broker_epoch: str) -> bool:
        """Claim an ensemble sent in ``old_epoch`` for sending its pending chunks again in
        ``broker_epoch``; True for the one caller that claims it."""
        epoch = EnsembleRow.broker_epoch.is_(None) if old_epoch is None else EnsembleRow.broker_epoch == old_epoch
        return changed_one(self._autocommit, update(EnsembleRow).where(EnsembleRow.id == ensemble_id, epoch)
                           .values(broker_epoch=broker_epoch))

    def delete_expired(self) -> int:
        """Delete ensembles created more than ``ttl_s`` ago that ended (no chunk pending, or
        cancelled); returns how many."""
        horizon = datetime.now(UTC).timestamp() - self.ttl_s
        with self._session.begin() as session:
            ids = list(session.scalars(select(EnsembleRow.id).where(
                EnsembleRow.created < horizon, or_(EnsembleRow.cancelled.is_(True), ~_PENDING))))
            if ids:
                session.execute(delete(EnsembleChunkRow).where(EnsembleChunkRow.ensemble_id.in_(ids)))
                session.execute(delete(EnsembleRow).where(EnsembleRow.id.in_(ids)))
            return len(ids)

    # -- reading ---------------------------------------------------------------------------------

    def record(self, ensemble_id: str) -> dict[str, Any] | None:
        """The ensemble's request, chunks, owner, ``cancelled``, and by chunk: ``done`` (a set),
        ``progress`` (members done, of chunks started and not done), ``digests``, ``workers`` and ``starts``;
        None if unknown."""
        with self._session() as session:
            row = session.get(EnsembleRow, ensemble_id)
            if row is None:
                return None
            chunks = session.execute(select(*_CHUNK_STATE, EnsembleChunkRow.worker, EnsembleChunkRow.digests)
                                     .where(EnsembleChunkRow.ensemble_id == ensemble_id)).all()
        return _record(row, chunks, with_digests=True)

    def page(self, limit: int, after: tuple[float, str] | None,
             owner: str | None = None) -> tuple[list[dict[str, Any]], bool]:
        """Ensembles newest first by ``(created, id)``, strictly after ``after``, only those ``owner`` may see
        if given (its own and those without an owner): each as :meth:`record` gives it, without the chunks'
        digests and workers (two queries for the page). Returns the page and whether more follow."""
        with self._session() as session:
            rows = list(session.scalars(newest_first(select(EnsembleRow), EnsembleRow, after, owner, limit)))
            more, rows = len(rows) > limit, rows[:limit]
            chunks = session.execute(select(EnsembleChunkRow.ensemble_id, *_CHUNK_STATE)
                                     .where(EnsembleChunkRow.ensemble_id.in_([r.id for r in rows]))).all()
        by_id: dict[str, list[Any]] = {}
        for c in chunks:
            by_id.setdefault(c.ensemble_id, []).append(c)
        return [_record(r, by_id.get(r.id, []), with_digests=False) for r in rows], more

    def with_prefix(self, prefix: str, owner: str | None, limit: int = 6) -> list[str]:
        """Ids starting with ``prefix`` (hex digits and dashes only) that ``owner`` may see, at most ``limit``."""
        return ids_with_prefix(self._session, EnsembleRow, prefix, owner, limit)

    def visible(self, ensemble_id: str, owner: str) -> bool:
        """Whether ``owner`` may see the ensemble (its own, or one without an owner): one indexed
        lookup that costs the same whether the ensemble does not exist or is another owner's."""
        with self._session() as session:
            return session.scalar(select(EnsembleRow.id).where(
                EnsembleRow.id == ensemble_id,
                or_(EnsembleRow.owner == owner, EnsembleRow.owner.is_(None)))) is not None

    def spec(self, ensemble_id: str) -> tuple[dict[str, Any], list[tuple[int, int]]] | None:
        """The request and the chunks' member ranges."""
        with self._session() as session:
            row = session.execute(select(EnsembleRow.request, EnsembleRow.chunks)
                                  .where(EnsembleRow.id == ensemble_id)).first()
        return None if row is None else (row.request, [tuple(c) for c in row.chunks])

    def is_cancelled(self, ensemble_id: str) -> bool:
        with self._session() as session:
            return bool(session.scalar(select(EnsembleRow.cancelled).where(EnsembleRow.id == ensemble_id)))

    def chunk_done(self, ensemble_id: str, chunk: int) -> bool:
        with self._session() as session:
            return bool(session.scalar(select(EnsembleChunkRow.done).where(
                EnsembleChunkRow.ensemble_id == ensemble_id, EnsembleChunkRow.chunk == chunk)))

    def chunk_members(self, ensemble_id: str, chunk: int) -> list[dict[str, Any]] | None:
        with self._session() as session:
            return session.scalar(select(EnsembleChunkRow.members).where(
                EnsembleChunkRow.ensemble_id == ensemble_id, EnsembleChunkRow.chunk == chunk))

    def pending_chunks(self, ensemble_id: str) -> list[int]:
        """Chunks not done, in order."""
        with self._session() as session:
            return list(session.scalars(select(EnsembleChunkRow.chunk).where(
                EnsembleChunkRow.ensemble_id == ensemble_id, EnsembleChunkRow.done.is_(False))
                .order_by(EnsembleChunkRow.chunk)))

    def unfinished(self) -> list[str]:
        """Ensembles not cancelled with a chunk pending, oldest first (to resume after a restart)."""
        with self._session() as session:
            return list(session.scalars(select(EnsembleRow.id)
                                        .where(EnsembleRow.cancelled.is_(False), _PENDING)
                                        .order_by(EnsembleRow.created, EnsembleRow.id)))

    def sent_before(self, broker_epoch: str, limit: int = 1000,
                    grace_s: float = UNSENT_GRACE_S) -> list[tuple[str, str | None, str | None]]:
        """Unfinished ensembles whose chunks were sent in another broker epoch (those messages are
        gone), or not sent ``grace_s`` after their creation (their API died first): (id, queue, epoch)."""
        unsent_before = datetime.now(UTC).timestamp() - grace_s
        with self._session() as session:
            rows = session.execute(select(EnsembleRow.id, EnsembleRow.queue, EnsembleRow.broker_epoch)
                                   .where(EnsembleRow.cancelled.is_(False), _PENDING,
                                          or_(and_(EnsembleRow.broker_epoch.is_(None),
                                                   EnsembleRow.created < unsent_before),
                                              EnsembleRow.broker_epoch != broker_epoch))
                                   .order_by(EnsembleRow.created).limit(limit))
            return [(ensemble_id, queue, epoch) for ensemble_id, queue, epoch in rows]
