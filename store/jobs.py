"""The job store: records, statuses and results of jobs in a database (SQLAlchemy).

Statuses move ``queued → running → succeeded | failed``, or to ``cancelled`` from either of the
first two; a job that ended never changes again (:meth:`JobStore.finish` and :meth:`JobStore.cancel`
only act on a job that has not ended). Finished jobs are deleted ``ttl_s`` after their creation
(:meth:`JobStore.delete_expired`).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from sqlalchemy import Engine, and_, create_engine, delete, event, func, or_, select, update
from sqlalchemy.orm import Session, sessionmaker

from store.models import JobRow

#: Statuses of a job that has not ended.
ACTIVE = ("queued", "running")
#: Statuses of a job that ended.
ENDED = ("succeeded", "failed", "cancelled")


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


def _now() -> datetime:
    return datetime.now(timezone.utc)


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


class JobStore:
    """Jobs in the database at ``url``; finished ones kept ``ttl_s`` seconds after their creation."""

    def __init__(self, url: str, ttl_s: int) -> None:
        self.url, self.ttl_s = url, ttl_s
        self.engine = make_engine(url)
        self._session = sessionmaker(self.engine, expire_on_commit=False)
        self._cleaned = 0.0
        self._cleaning = threading.Lock()

    def migrate(self) -> None:
        """Bring the schema to the newest revision (Alembic ``upgrade head``)."""
        from alembic import command
        from alembic.config import Config

        config = Config()
        config.set_main_option("script_location", str(Path(__file__).parent / "migrations"))
        with self.engine.begin() as connection:
            config.attributes["connection"] = connection
            command.upgrade(config, "head")

    def close(self) -> None:
        self.engine.dispose()

    # -- writing ---------------------------------------------------------------------------------

    def create(self, job_id: str, request: dict[str, Any], owner: str | None = None) -> str:
        """Record a queued job; returns its ``created_at`` (ISO 8601, UTC)."""
        now = _now()
        with self._session.begin() as session:
            session.add(JobRow(id=job_id, owner=owner, status="queued", request=request, created=now.timestamp(),
                               created_at=now.isoformat(), attempts=0))
        self._clean_now_and_then(now.timestamp())
        return now.isoformat()

    def start(self, job_id: str) -> bool:
        """Mark a queued (or interrupted running) job running; False if it ended (do not run it)."""
        with self._session.begin() as session:
            done = session.execute(update(JobRow).where(JobRow.id == job_id, JobRow.status.in_(ACTIVE))
                                   .values(status="running", attempts=JobRow.attempts + 1))
            return done.rowcount == 1  # type: ignore[attr-defined]

    def finish(self, job_id: str, status: str, result: dict[str, Any] | None = None,
               error: dict[str, Any] | None = None) -> bool:
        """Record the end of a job that has not ended (not cancelled meanwhile); True if recorded."""
        if status not in ("succeeded", "failed"):
            raise ValueError(f"not an end a worker records: {status!r}")
        with self._session.begin() as session:
            done = session.execute(update(JobRow).where(JobRow.id == job_id, JobRow.status.in_(ACTIVE))
                                   .values(status=status, result=result, error=error,
                                           finished=_now().timestamp()))
            return done.rowcount == 1  # type: ignore[attr-defined]

    def cancel(self, job_id: str) -> bool:
        """Cancel a job that has not ended; True if it was cancelled by this call."""
        with self._session.begin() as session:
            done = session.execute(update(JobRow).where(JobRow.id == job_id, JobRow.status.in_(ACTIVE))
                                   .values(status="cancelled", finished=_now().timestamp()))
            return done.rowcount == 1  # type: ignore[attr-defined]

    def requeue(self, job_id: str) -> None:
        """Put a job that was running when its runner stopped back to ``queued``."""
        with self._session.begin() as session:
            session.execute(update(JobRow).where(JobRow.id == job_id, JobRow.status == "running")
                            .values(status="queued"))

    def delete_expired(self) -> int:
        """Delete ended jobs created more than ``ttl_s`` ago; returns how many."""
        horizon = _now().timestamp() - self.ttl_s
        with self._session.begin() as session:
            done = session.execute(delete(JobRow).where(JobRow.created < horizon, JobRow.status.in_(ENDED)))
            return int(done.rowcount)  # type: ignore[attr-defined]

    def _clean_now_and_then(self, now: float, every_s: float = 60.0) -> None:
        if now - self._cleaned < every_s or not self._cleaning.acquire(blocking=False):
            return
        try:
            self._cleaned = now
            self.delete_expired()
        finally:
            self._cleaning.release()

    # -- reading ---------------------------------------------------------------------------------

    @staticmethod
    def _stored(row: Any, with_result: bool) -> StoredJob:
        return StoredJob(id=row.id, status=row.status, request=row.request, created_at=row.created_at,
                         created=row.created, owner=row.owner, result=row.result if with_result else None,
                         error=row.error, attempts=row.attempts)

    def get(self, job_id: str) -> StoredJob | None:
        with self._session() as session:
            row = session.get(JobRow, job_id)
            return None if row is None else self._stored(row, with_result=True)

    def status(self, job_id: str) -> str | None:
        with self._session() as session:
            return session.scalar(select(JobRow.status).where(JobRow.id == job_id))

    def unfinished(self) -> list[StoredJob]:
        """Jobs queued or running, oldest first (to resume after a restart)."""
        with self._session() as session:
            rows = session.execute(select(JobRow.id, JobRow.status, JobRow.request, JobRow.created_at, JobRow.created,
                                          JobRow.owner, JobRow.error, JobRow.attempts)
                                   .where(JobRow.status.in_(ACTIVE)).order_by(JobRow.created, JobRow.id))
            return [self._stored(row, with_result=False) for row in rows]

    def page(self, status: str | None, limit: int, after: tuple[float, str] | None,
             owner: str | None = None) -> tuple[list[StoredJob], bool]:
        """Newest first by ``(created, id)``, strictly after ``after``; only ``status`` if given, only
        what ``owner`` may see if given (its own jobs and those without an owner). Returns the page
        (without results) and whether more follow."""
        query = select(JobRow.id, JobRow.status, JobRow.request, JobRow.created_at, JobRow.created, JobRow.owner,
                       JobRow.error, JobRow.attempts)
        if after is not None:
            score, last = after
            query = query.where(or_(JobRow.created < score, and_(JobRow.created == score, JobRow.id < last)))
        if status is not None:
            query = query.where(JobRow.status == status)
        if owner is not None:
            query = query.where(or_(JobRow.owner == owner, JobRow.owner.is_(None)))
        query = query.order_by(JobRow.created.desc(), JobRow.id.desc()).limit(limit + 1)
        with self._session() as session:
            rows = [self._stored(row, with_result=False) for row in session.execute(query)]
        return rows[:limit], len(rows) > limit

    def active_count(self, owner: str) -> int:
        """Queued and running jobs of ``owner``."""
        with self._session() as session:
            return int(session.scalar(select(func.count()).select_from(JobRow)
                                      .where(JobRow.owner == owner, JobRow.status.in_(ACTIVE))) or 0)

    def session(self) -> Session:
        """A session, for tests and tools."""
        return self._session()
