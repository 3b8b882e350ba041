"""One statement on an autocommit connection (store/statements.py): a statement interrupted while it runs
(as a job's time limit interrupts a worker) lets its own exception through and spoils no later write."""

from __future__ import annotations

import signal

import pytest
from sqlalchemy import create_engine, text
from sqlalchemy.engine import make_url

from store.statements import autocommit, changed_one
from tests.support import TEST_DATABASE_URL


class Interrupted(Exception):
    """Stands for Celery's SoftTimeLimitExceeded, raised by a signal handler."""


def _interrupt(*_: object) -> None:
    raise Interrupted


def test_an_interrupted_statement_raises_its_interruption_and_the_next_one_runs():
    url = make_url(TEST_DATABASE_URL).set(database="postgres")  # a statement that touches no table
    engine = create_engine(url, pool_size=1, max_overflow=0)  # one connection: the next write reuses the pool
    try:
        writes = autocommit(engine)
        previous = signal.signal(signal.SIGALRM, _interrupt)
        try:
            signal.setitimer(signal.ITIMER_REAL, 0.2)
            with pytest.raises(Interrupted):  # not "another command is already in progress"
                changed_one(writes, text("SELECT pg_sleep(2)"))
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
        assert changed_one(writes, text("SELECT 1")) is True
        assert changed_one(writes, text("SELECT 1")) is True
    finally:
        engine.dispose()
