"""The job store (store/): the migration builds the models' schema; statuses only move forward; the
list pages by (created, id); expiry deletes only ended jobs. SQLite here; PostgreSQL in queue mode."""

from __future__ import annotations

import time

import pytest
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy import update

from store.jobs import JobStore
from store.models import Base, JobRow

REQUEST = {"system": {"kind": "chaplygin_ball"}, "t_final": 1.0}


@pytest.fixture()
def store(tmp_path) -> JobStore:
    s = JobStore(f"sqlite:///{tmp_path / 'jobs.sqlite3'}", ttl_s=3600)
    s.migrate()
    return s


def test_the_migration_builds_exactly_the_models_schema(store):
    with store.engine.connect() as connection:
        diff = compare_metadata(MigrationContext.configure(connection), Base.metadata)
    assert diff == []
    store.migrate()  # a second upgrade is a no-op


def test_statuses_only_move_forward(store):
    store.create("a", REQUEST, owner="alice")
    assert store.status("a") == "queued" and store.start("a", "w1") and store.status("a") == "running"
    assert store.finish("a", "succeeded", result={"x": [1.5]})
    assert not store.cancel("a") and not store.start("a", "w1") and not store.finish("a", "failed", error={"m": "late"})
    job = store.get("a")
    assert job.status == "succeeded" and job.result == {"x": [1.5]} and job.error is None and job.attempts == 1
    store.create("b", REQUEST)
    assert store.cancel("b") and not store.start("b", "w1") and not store.finish("b", "succeeded", result={})
    assert store.get("b").status == "cancelled" and store.get("b").result is None
    with pytest.raises(ValueError):
        store.finish("b", "cancelled")


def test_unfinished_jobs_are_found_and_requeued_in_order(store):
    for job_id in ("q1", "r1", "done"):
        store.create(job_id, REQUEST)
        time.sleep(0.002)
    store.start("r1", "w1")
    store.start("done", "w1")
    store.finish("done", "failed", error={"type": "X", "message": "y"})
    assert [j.id for j in store.unfinished()] == ["q1", "r1"]
    store.requeue("r1")
    assert store.status("r1") == "queued" and store.get("r1").attempts == 1


def test_pages_are_newest_first_and_exact_with_ties(store):
    for i in range(7):
        store.create(f"j{i}", REQUEST, owner="alice" if i % 2 else None)
    with store.session() as session, session.begin():  # three jobs created at the same instant
        session.execute(update(JobRow).where(JobRow.id.in_(["j2", "j3", "j4"])).values(created=1e9))
    seen, after = [], None
    while True:
        page, more = store.page(None, 2, after)
        seen += [j.id for j in page]
        if not more:
            break
        after = (page[-1].created, page[-1].id)
    assert sorted(seen) == [f"j{i}" for i in range(7)] and len(seen) == 7
    assert seen[-3:] == ["j4", "j3", "j2"]  # the tie broken by id, descending
    bob = [j.id for j in store.page(None, 10, None, owner="bob")[0]]
    assert sorted(bob) == ["j0", "j2", "j4", "j6"]  # jobs without an owner, none of alice's
    assert store.active_count("alice") == 3 and store.active_count("bob") == 0


def test_expiry_deletes_only_ended_jobs_past_the_ttl(store):
    store.create("old-done", REQUEST)
    store.create("old-queued", REQUEST)
    store.create("new-done", REQUEST)
    for job_id in ("old-done", "new-done"):
        store.start(job_id, "w1")
        store.finish(job_id, "succeeded", result={})
    with store.session() as session, session.begin():
        session.execute(update(JobRow).where(JobRow.id.in_(["old-done", "old-queued"])).values(created=0.0))
    assert store.delete_expired() == 1
    assert store.get("old-done") is None and store.get("old-queued") is not None and store.get("new-done") is not None


def test_migrating_logs_one_line_when_the_schema_changes_and_nothing_from_alembic(tmp_path, caplog):
    """A worker's pool processes each migrate at start: Alembic's INFO lines flooded its log."""
    import logging

    caplog.set_level(logging.INFO)
    fresh = JobStore(f"sqlite:///{tmp_path / 'fresh.sqlite3'}", ttl_s=3600)
    fresh.migrate()
    assert not [r for r in caplog.records if r.name.startswith("alembic")]
    ours = [r.getMessage() for r in caplog.records if r.name == "store.jobs"]
    assert len(ours) == 1 and "migrated from revision (empty) to" in ours[0]
    caplog.clear()
    fresh.migrate()  # up to date: silent
    assert not [r for r in caplog.records if r.name.startswith("alembic") or r.name == "store.jobs"]


def test_a_job_started_max_attempts_times_is_quarantined_not_started_again(store):
    """Issue 34, item 4: each start counts; a job whose runner stopped under it ``max_attempts`` times (here
    2) is failed as quarantined at its next start, and one that ended or is running elsewhere is untouched."""
    store.create("poison", REQUEST)
    assert store.start("poison", "w1", max_attempts=2)  # its runner dies ...
    store.requeue("poison")
    assert store.start("poison", "w2", max_attempts=2)  # ... and again
    store.requeue("poison")
    assert not store.start("poison", "w3", max_attempts=2)
    job = store.get("poison")
    assert job.status == "failed" and job.attempts == 2 and job.error["type"] == "Quarantined"
    assert "started 2 times" in job.error["message"]
    store.create("busy", REQUEST)
    assert store.start("busy", "w1", max_attempts=1)
    assert not store.start("busy", "w2", max_attempts=1)  # running on w1: neither started nor quarantined
    assert store.status("busy") == "running" and not store.quarantine("busy", "w2", 1)
