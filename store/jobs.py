"""The job store: records, statuses and results of jobs in a database (SQLAlchemy).

Statuses move ``queued → running → succeeded | failed``, or to ``cancelled`` from either of the
first two; a job that ended never changes again (:meth:`JobStore.finish` and :meth:`JobStore.cancel`
only act on a job that has not ended). Finished jobs are deleted ``ttl_s`` after their creation
(:meth:`JobStore.delete_expired`).
"""

from __future__ import annotations

import logging
import zlib
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, cast

from sqlalchemy import Engine, Table, and_, create_engine, delete, event, func, insert, or_, select, text, update
from sqlalchemy.engine import CursorResult, make_url
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from store.expiry import Expiry
from store.idempotency import KeyBinding, KeyBound, KeyInProgress, bind, delete_expired as delete_expired_keys, unbind
from store.listing import ids_with_prefix, newest_first
from store.models import JobRow
from store.statements import autocommit, changed_one

log = logging.getLogger(__name__)

_JOBS = cast(Table, JobRow.__table__)  # declared with __tablename__: a Table (typed FromClause)
#: Statuses of a job that has not ended.
ACTIVE = ("queued", "running")
#: Statuses of a job that ended.
ENDED = ("succeeded", "failed", "cancelled")
#: First key of the PostgreSQL advisory locks that serialize one owner's admissions (the second is the
#: owner's CRC-32): two owners sharing a CRC only wait for each other.
OWNER_LOCK_CLASS = 726458
#: Seconds after its creation a job not sent yet (:meth:`JobStore.mark_sent`) is taken as lost by its API
#: and sent by the workers' sweep: far longer than recording and sending take, so a job in between is not
#: sent twice (a second message would only be dropped by the worker that gets it).
UNSENT_GRACE_S = 30.0
#: The columns of a job read without its result (lists, resumption).
_WITHOUT_RESULT = (JobRow.id, JobRow.status, JobRow.request, JobRow.created_at, JobRow.created, JobRow.owner,
                   JobRow.error, JobRow.attempts)


@dataclass
class StoredJob:
    """A job as stored (``result`` only when asked for)."""

    id: str
    status: str
    request: dict[str, Any]
    created_at: str
    created: float
    owner: str | None = None
    result: dict[str, Any] | None = None
    error: dict[str, Any] | None = None
    attempts: int = 0
    queue: str | None = None


class ActiveBoundReached(Exception):
    """The owner already has ``active`` queued or running jobs, its bound: nothing was recorded."""

    def __init__(self, active: int) -> None:
        super().__init__(f"{active} active jobs")
        self.active = active


def _startable_by(worker: str) -> Any:
    """A job ``worker`` may start: queued, or running on ``worker`` itself (its pool process died and the worker
    took it again)."""
    return or_(_JOBS.c.status == "queued", and_(_JOBS.c.status == "running", _JOBS.c.worker == worker))


def quarantined_error(attempts: int) -> dict[str, str]:
    """The error of a job not started again after ``attempts`` starts (:meth:`JobStore.quarantine`)."""
    return {"type": "Quarantined", "message": (
        f"the job was started {attempts} times and each run ended without a result (the service or its worker "
        "stopped, or its runner died, while it ran); it is not started again. If it is a long job, it may "
        "need more than the service's time limits; send it again to run it once more")}


def owner_lock_key(owner: str) -> tuple[int, int]:
    """The two int4 keys of ``owner``'s advisory lock (``pg_advisory_xact_lock(k1, k2)``)."""
    return OWNER_LOCK_CLASS, zlib.crc32(owner.encode()) - (1 << 31)


def _now() -> datetime:
    return datetime.now(UTC)


def make_engine(url: str) -> Engine:
    """An engine for ``url``; a SQLite file's folder is created, and SQLite waits for its lock and
    runs in WAL mode (readers do not block the writer)."""
    if url.startswith("sqlite"):
        path = url.split("///", 1)[1] if "///" in url else ""
        if path and path != ":memory:":
            Path(path).parent.mkdir(parents=True, exist_ok=True)
        engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": 30})

        @event.listens_for(engine, "connect")
        def _pragmas(connection: Any, _: Any) -> None:
            cursor = connection.cursor()
            cursor.execute("PRAGMA journal_mode=WAL")
            cursor.execute("PRAGMA synchronous=NORMAL")
            cursor.close()

        return engine
    return create_engine(url, pool_pre_ping=True, pool_size=10, max_overflow=10)


def ensure_database(url: str) -> None:
    """Create the PostgreSQL database of ``url`` if it does not exist (connecting to ``postgres``)."""
    target = make_url(url)
    admin = create_engine(target.set(database="postgres"), isolation_level="AUTOCOMMIT")
    try:
        with admin.connect() as connection:
            exists = connection.scalar(text("SELECT 1 FROM pg_database WHERE datname = :name"),
                                       {"name": target.database})
            if not exists:
                try:
                    connection.execute(text(f'CREATE DATABASE "{target.database}"'))
                except Exception:  # created meanwhile by another process
                    pass
    finally:
        admin.dispose()


class JobStore:
    """Jobs in the database at ``url``; finished ones kept ``ttl_s`` seconds after their creation."""

    def __init__(self, url: str, ttl_s: int) -> None:
        self.url, self.ttl_s = url, ttl_s
        self.engine = make_engine(url)
        self._session = sessionmaker(self.engine, expire_on_commit=False)
        self._autocommit = autocommit(self.engine)
        self._expiry = Expiry(self.delete_expired)

    def migrate(self) -> None:
        """Create the database if it is missing (PostgreSQL) and bring the schema to the newest revision
        (Alembic ``upgrade head``); on PostgreSQL under an advisory lock, so that the API and several
        workers starting at once migrate one after the other."""
        from alembic import command
        from alembic.config import Config
        from alembic.runtime.migration import MigrationContext

        if self.engine.dialect.name == "postgresql":
            ensure_database(self.url)
        config = Config()
        config.set_main_option("script_location", str(Path(__file__).parent / "migrations"))
        # Alembic's INFO lines ("Context impl", "Will assume transactional DDL") came from every process
        # and every pool process at each start: a worker's log was full of them. One line of ours instead,
        # when the schema did change.
        logging.getLogger("alembic").setLevel(logging.WARNING)
        with self.engine.begin() as connection:
            if connection.dialect.name == "postgresql":
                connection.execute(text("SELECT pg_advisory_xact_lock(726457)"))
            before = MigrationContext.configure(connection).get_current_revision()
            config.attributes["connection"] = connection
            command.upgrade(config, "head")
            after = MigrationContext.configure(connection).get_current_revision()
        if after != before:
            log.info("job store %s migrated from revision %s to %s", self.engine.url.render_as_string(),
                     before or "(empty)", after)

    def close(self) -> None:
        self.engine.dispose()

    def ping(self) -> bool:
        """Whether the database answers ``SELECT 1``."""
        try:
            with self.engine.connect() as connection:
                connection.execute(text("SELECT 1"))
            return True
        except Exception:
            return False

    # -- writing ---------------------------------------------------------------------------------
    # Each write is one statement on an autocommit connection (Core, not the ORM's unit of work): one
    # round trip, atomic by itself; the hot path of a job is one INSERT, one UPDATE to start, one to end.

    def _changed(self, statement: Any) -> bool:
        return changed_one(self._autocommit, statement)

    def create(self, job_id: str, request: dict[str, Any], owner: str | None = None, queue: str | None = None,
               broker_epoch: str | None = None, max_active: int | None = None,
               binding: KeyBinding | None = None) -> str:
        """Record a queued job (sent to ``queue`` in the broker's ``broker_epoch``; None: not sent yet, see
        :meth:`mark_sent`); returns its ``created_at`` (ISO 8601, UTC).

        With ``max_active`` (and an ``owner``) the job is recorded only if the owner has fewer queued
        or running jobs: the count and the insert run in one transaction under the owner's advisory
        lock (PostgreSQL), so concurrent submissions of one owner, from any number of API processes,
        cannot both see room for one more. Raises :class:`ActiveBoundReached` otherwise.

        With ``binding`` the Idempotency-Key is bound to the job in the same transaction
        (:func:`store.idempotency.bind`): raises :class:`store.idempotency.KeyBound` or
        :class:`store.idempotency.KeyInProgress` (nothing recorded) if it cannot be.
        """
        now = _now()
        row = insert(_JOBS).values(id=job_id, owner=owner, status="queued", request=request, created=now.timestamp(),
                                   created_at=now.isoformat(), attempts=0, queue=queue, broker_epoch=broker_epoch)
        bounded = max_active is not None and owner is not None
        if not bounded and binding is None:
            self._changed(row)
        else:
            self._create_in_transaction(row, job_id, now.timestamp(), owner if bounded else None, max_active,
                                        binding)
        self._expiry.now_and_then(now.timestamp())
        return now.isoformat()

    def _create_in_transaction(self, row: Any, job_id: str, created: float, owner: str | None,
                               max_active: int | None, binding: KeyBinding | None) -> None:
        # The locks are the transaction's: released by its commit or rollback, or when the connection
        # dies with the API process (no lease to outlive it). On SQLite (one embedded API process) the
        # caller's process lock does this job.
        with self.engine.connect() as connection:
            try:
                with connection.begin():
                    if binding is not None:
                        bind(connection, binding, job_id, created)
                    if owner is not None and max_active is not None:
                        if connection.dialect.name == "postgresql":
                            first, second = owner_lock_key(owner)
                            connection.execute(text("SELECT pg_advisory_xact_lock(:first, :second)"),
                                               {"first": first, "second": second})
                        active = int(connection.scalar(select(func.count()).select_from(_JOBS).where(
                            _JOBS.c.owner == owner, _JOBS.c.status.in_(ACTIVE))) or 0)
                        if active >= max_active:
                            raise ActiveBoundReached(active)
                    connection.execute(row)
            except (ActiveBoundReached, KeyBound, KeyInProgress):
                raise
            except BaseException:
                connection.invalidate()  # as store.statements.changed_one: never pool a busy connection
                raise

    def ensure(self, job_id: str, request: dict[str, Any], queue: str | None = None,
               broker_epoch: str | None = None) -> bool:
        """Record a queued job unless one with this id exists (a job sent straight to the broker);
        True if this call created it."""
        if self.status(job_id) is not None:
            return False
        try:
            self.create(job_id, request, None, queue, broker_epoch)
        except IntegrityError:  # created meanwhile by another process
            return False
        return True

    def delete(self, job_id: str, slot: str | None = None) -> None:
        """Forget a job that could not be sent (the broker refused it), and free the Idempotency-Key
        ``slot`` bound to it, in one transaction."""
        with self.engine.begin() as connection:
            connection.execute(delete(_JOBS).where(_JOBS.c.id == job_id, _JOBS.c.status == "queued"))
            if slot is not None:
                unbind(connection, slot, job_id)

    def mark_sent(self, job_id: str, broker_epoch: str) -> None:
        """The job's message is in the broker (epoch ``broker_epoch``). Until this is recorded the job
        is "not sent yet"; one still so :data:`UNSENT_GRACE_S` after its creation was recorded by an
        API that died before sending it, and the workers' sweep sends it (:meth:`sent_before`)."""
        self._changed(update(_JOBS).where(_JOBS.c.id == job_id, _JOBS.c.broker_epoch.is_(None))
                      .values(broker_epoch=broker_epoch))

    def start(self, job_id: str, worker: str, max_attempts: int | None = None) -> bool:
        """Mark the job running on ``worker`` if it is queued, or was running on that same worker (its
        pool process died and the worker took it again); False otherwise: it ended, was cancelled, or
        runs elsewhere (do not run it). With ``max_attempts``, a job started that many times already
        (its runner stopped each time before it ended) is not started but quarantined (:meth:`quarantine`)."""
        condition = [_JOBS.c.id == job_id, _startable_by(worker)]
        if max_attempts is not None:
            condition.append(_JOBS.c.attempts < max_attempts)
        if self._changed(update(_JOBS).where(*condition)
                         .values(status="running", worker=worker, attempts=_JOBS.c.attempts + 1)):
            return True
        if max_attempts is not None:
            self.quarantine(job_id, worker, max_attempts)
        return False

    def quarantine(self, job_id: str, worker: str, max_attempts: int) -> bool:
        """Fail a job ``worker`` could start (queued, or running on ``worker`` itself) that was started
        ``max_attempts`` times already, saying so (a poison job: each run stopped its runner, or the service
        stopped under it); True if this call did. A job running on another worker is left alone (a message
        delivered twice). Issue 34, item 4: such a job is not run again blindly."""
        return self._changed(update(_JOBS).where(_JOBS.c.id == job_id, _JOBS.c.attempts >= max_attempts,
                                                 _startable_by(worker))
                             .values(status="failed", worker=None, finished=_now().timestamp(),
                                     error=quarantined_error(max_attempts)))

    def finish(self, job_id: str, status: str, result: dict[str, Any] | None = None,
               error: dict[str, Any] | None = None) -> bool:
        """Record the end of a job that has not ended (not cancelled meanwhile); True if recorded."""
        if status not in ("succeeded", "failed"):
            raise ValueError(f"not an end a worker records: {status!r}")
        return self._changed(update(_JOBS).where(_JOBS.c.id == job_id, _JOBS.c.status.in_(ACTIVE))
                             .values(status=status, result=result, error=error, finished=_now().timestamp()))

    def cancel(self, job_id: str) -> bool:
        """Cancel a job that has not ended; True if it was cancelled by this call."""
        return self._changed(update(_JOBS).where(_JOBS.c.id == job_id, _JOBS.c.status.in_(ACTIVE))
                             .values(status="cancelled", finished=_now().timestamp()))

    def requeue(self, job_id: str, worker: str | None = None, broker_epoch: str | None = None) -> bool:
        """Put a job that was running (on ``worker``, if given) back to ``queued``, to be sent again in
        ``broker_epoch``; True if this call did (so that one caller sends it)."""
        condition = [_JOBS.c.id == job_id, _JOBS.c.status == "running"]
        if worker is not None:
            condition.append(_JOBS.c.worker == worker)
        return self._changed(update(_JOBS).where(*condition).values(status="queued", worker=None,
                                                                    broker_epoch=broker_epoch))

    def resend_claim(self, job_id: str, old_epoch: str | None, broker_epoch: str) -> bool:
        """Claim a queued job sent in ``old_epoch`` for sending again in ``broker_epoch``; True for the
        one caller that claims it."""
        epoch = _JOBS.c.broker_epoch.is_(None) if old_epoch is None else _JOBS.c.broker_epoch == old_epoch
        return self._changed(update(_JOBS).where(_JOBS.c.id == job_id, _JOBS.c.status == "queued", epoch)
                             .values(broker_epoch=broker_epoch))

    def sent_before(self, broker_epoch: str, limit: int = 1000,
                    grace_s: float = UNSENT_GRACE_S) -> list[tuple[str, dict[str, Any], str | None, str | None]]:
        """Queued jobs sent in another broker epoch (their messages are gone), and those not sent
        ``grace_s`` after their creation (their API died between recording and sending them):
        (id, request, queue, epoch)."""
        unsent_before = _now().timestamp() - grace_s
        with self._session() as session:
            rows = session.execute(select(JobRow.id, JobRow.request, JobRow.queue, JobRow.broker_epoch)
                                   .where(JobRow.status == "queued",
                                          or_(and_(JobRow.broker_epoch.is_(None), JobRow.created < unsent_before),
                                              JobRow.broker_epoch != broker_epoch))
                                   .order_by(JobRow.created).limit(limit))
            return [tuple(row) for row in rows]

    def running_on(self) -> dict[str, list[str]]:
        """Running jobs by the worker running them."""
        with self._session() as session:
            found: dict[str, list[str]] = {}
            for job_id, worker in session.execute(select(JobRow.id, JobRow.worker).where(JobRow.status == "running")):
                found.setdefault(worker or "", []).append(job_id)
            return found

    def delete_expired(self) -> int:
        """Delete ended jobs created more than ``ttl_s`` ago; returns how many."""
        horizon = _now().timestamp() - self.ttl_s
        with self._session.begin() as session:
            done = cast("CursorResult[Any]",  # a DELETE's result (typed Result): it has the rowcount
                        session.execute(delete(JobRow).where(JobRow.created < horizon, JobRow.status.in_(ENDED))))
            delete_expired_keys(session.connection(), horizon)
            return int(done.rowcount)

    # -- reading ---------------------------------------------------------------------------------

    @staticmethod
    def _stored(row: Any, with_result: bool) -> StoredJob:
        return StoredJob(id=row.id, status=row.status, request=row.request, created_at=row.created_at,
                         created=row.created, owner=row.owner, result=row.result if with_result else None,
                         error=row.error, attempts=row.attempts, queue=getattr(row, "queue", None))

    def get(self, job_id: str) -> StoredJob | None:
        with self.engine.connect() as connection:
            row = connection.execute(select(_JOBS).where(_JOBS.c.id == job_id)).first()
        return None if row is None else self._stored(row, with_result=True)

    def visible(self, job_id: str, owner: str) -> bool:
        """Whether ``owner`` may see the job ``job_id`` (its own, or one without an owner): one indexed
        lookup that costs the same whether the job does not exist or is another owner's."""
        with self.engine.connect() as connection:
            return connection.scalar(select(_JOBS.c.id).where(
                _JOBS.c.id == job_id, or_(_JOBS.c.owner == owner, _JOBS.c.owner.is_(None)))) is not None

    def existing(self, job_ids: list[str]) -> set[str]:
        """Those of ``job_ids`` that are recorded (one query)."""
        if not job_ids:
            return set()
        with self.engine.connect() as connection:
            return set(connection.scalars(select(_JOBS.c.id).where(_JOBS.c.id.in_(job_ids))))

    def with_prefix(self, prefix: str, owner: str | None, limit: int = 6) -> list[str]:
        """Ids starting with ``prefix`` (hex digits and dashes only) that ``owner`` may see, at most ``limit``."""
        return ids_with_prefix(self._session, JobRow, prefix, owner, limit)

    def status(self, job_id: str) -> str | None:
        with self.engine.connect() as connection:
            return connection.scalar(select(_JOBS.c.status).where(_JOBS.c.id == job_id))

    def unfinished(self) -> list[StoredJob]:
        """Jobs queued or running, oldest first (to resume after a restart)."""
        with self._session() as session:
            rows = session.execute(select(*_WITHOUT_RESULT).where(JobRow.status.in_(ACTIVE))
                                   .order_by(JobRow.created, JobRow.id))
            return [self._stored(row, with_result=False) for row in rows]

    def page(self, status: str | None, limit: int, after: tuple[float, str] | None,
             owner: str | None = None) -> tuple[list[StoredJob], bool]:
        """Newest first by ``(created, id)``, strictly after ``after``; only ``status`` if given, only
        what ``owner`` may see if given (its own jobs and those without an owner). Returns the page
        (without results) and whether more follow."""
        query = select(*_WITHOUT_RESULT)
        if status is not None:
            query = query.where(JobRow.status == status)
        query = newest_first(query, JobRow, after, owner, limit)
        with self._session() as session:
            rows = [self._stored(row, with_result=False) for row in session.execute(query)]
        return rows[:limit], len(rows) > limit

    def active_count(self, owner: str) -> int:
        """Queued and running jobs of ``owner``."""
        with self._session() as session:
            return int(session.scalar(select(func.count()).select_from(JobRow)
                                      .where(JobRow.owner == owner, JobRow.status.in_(ACTIVE))) or 0)

    def count_by_status(self, engine: Engine | None = None, timeout_ms: int | None = None) -> dict[str, int]:
        """Jobs in the store by status (one indexed ``GROUP BY``; for the metrics), on ``engine``'s
        connections if given (a scrape's own, with a connect timeout), within ``timeout_ms`` on PostgreSQL."""
        with (engine or self.engine).connect() as connection:
            if timeout_ms is not None and connection.dialect.name == "postgresql":
                connection.execute(text(f"SET LOCAL statement_timeout = {int(timeout_ms)}"))
            rows = connection.execute(select(JobRow.status, func.count()).group_by(JobRow.status))
            return {str(status): int(n) for status, n in rows}

    def session(self) -> Session:
        """A session, for tests and tools."""
        return self._session()
