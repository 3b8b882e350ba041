"""One writing statement on an autocommit connection: one round trip, atomic by itself (no
BEGIN/COMMIT, no ORM unit of work). The hot writes of jobs and ensembles go through it."""

from __future__ import annotations

from typing import Any

from sqlalchemy import Engine


def autocommit(engine: Engine) -> Engine:
    """``engine`` with each statement committed as it runs."""
    return engine.execution_options(isolation_level="AUTOCOMMIT")


def changed_one(engine: Engine, statement: Any) -> bool:
    """Execute ``statement`` on ``engine`` (from :func:`autocommit`); True if it changed exactly one row."""
    with engine.connect() as connection:
        return connection.execute(statement).rowcount == 1
