"""One writing statement on an autocommit connection: one round trip, atomic by itself (no
BEGIN/COMMIT, no ORM unit of work). The hot writes of jobs and ensembles go through it."""

from __future__ import annotations

from typing import Any

from sqlalchemy import Engine


def autocommit(engine: Engine) -> Engine:
    """``engine`` with each statement committed as it runs."""
    return engine.execution_options(isolation_level="AUTOCOMMIT")


def changed_one(engine: Engine, statement: Any) -> bool:
    """Execute ``statement`` on ``engine`` (from :func:`autocommit`); True if it changed exactly one row.

    A statement interrupted while it runs (a job's time limit is a signal that raises in the middle of
    the driver's wait) leaves its connection busy: it is invalidated, not rolled back and pooled, so the
    interruption itself propagates (not "another command is already in progress") and the next write
    gets a fresh connection.
    """
    with engine.connect() as connection:
        try:
            return connection.execute(statement).rowcount == 1
        except BaseException:
            connection.invalidate()
            raise
