"""The ensemble store (store/ensembles.py) on SQLite (embedded mode) and PostgreSQL (queue mode): a chunk
run twice is counted once, progress and cancellation, resumption, the broker-epoch claim, expiry."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from sqlalchemy import update

from store.ensembles import EnsembleStore
from store.jobs import JobStore
from store.models import EnsembleRow
from tests.support import drop_database, fresh_database_url

REQUEST = {"system": {"kind": "chaplygin_ball"}, "t_final": 1.0}
CHUNKS = [(0, 3), (3, 6), (6, 7)]


@pytest.fixture(params=["sqlite", "postgresql"])
def store(request, tmp_path) -> Iterator[EnsembleStore]:
    url = f"sqlite:///{tmp_path / 'store.sqlite3'}" if request.param == "sqlite" else fresh_database_url()
    jobs = JobStore(url, ttl_s=3600)
    jobs.migrate()
    yield EnsembleStore(jobs.engine, ttl_s=3600)
    jobs.close()
    if request.param == "postgresql":
        drop_database(url)


def _members(start: int, stop: int, value: float) -> list[dict]:
    return [{"index": i, "status": "succeeded", "x": [value, 1e-300, -2.5]} for i in range(start, stop)]


def test_a_chunk_run_twice_is_counted_once_with_its_results(store):
    store.create("e", REQUEST, CHUNKS, owner="alice", queue="q", broker_epoch="one")
    record = store.record("e")
    assert record["chunks"] == CHUNKS and record["owner"] == "alice" and not record["cancelled"]
    assert record["done"] == set() and record["progress"] == {} and store.pending_chunks("e") == [0, 1, 2]
    store.mark_started("e", 1)
    store.set_progress("e", 1, 2)
    assert store.record("e")["progress"] == {1: 2}
    for run in range(2):  # redelivered: the first run to finish is kept, the late one changes nothing
        store.mark_started("e", 0)
        stored = store.store_chunk("e", 0, _members(0, 3, 0.25), [{"d": 0.5}] * 3, f"worker-{run}")
        assert stored is (run == 0)
    record = store.record("e")
    assert record["done"] == {0} and record["starts"] == {0: 2, 1: 1} and record["workers"] == {0: "worker-0"}
    assert record["digests"] == {0: [{"d": 0.5}] * 3}
    assert store.chunk_members("e", 0) == _members(0, 3, 0.25)  # floats bit for bit, 1e-300 included
    assert store.chunk_members("e", 1) is None and store.chunk_done("e", 0) and not store.chunk_done("e", 1)
    store.store_chunk("e", 1, _members(3, 6, 1.0), [], "w")
    store.set_progress("e", 1, 1)  # a late progress write of a finished chunk changes nothing
    assert store.record("e")["progress"] == {} and store.pending_chunks("e") == [2]
    assert store.spec("e") == (REQUEST, CHUNKS) and store.spec("nothing") is None and store.record("nothing") is None


def test_unfinished_and_lost_ensembles_are_found_and_claimed_once(store):
    for name in ("a", "b", "c", "d"):
        store.create(name, REQUEST, CHUNKS, queue="q", broker_epoch="one")
    for chunk in range(3):
        store.store_chunk("b", chunk, [], [], "w")  # b finished
    store.cancel("c")
    assert store.is_cancelled("c") and not store.is_cancelled("a")
    assert store.unfinished() == ["a", "d"]
    assert [row[0] for row in store.sent_before("two")] == ["a", "d"] and store.sent_before("one") == []
    assert store.resend_claim("a", "one", "two") and not store.resend_claim("a", "one", "two")
    assert [row[0] for row in store.sent_before("two")] == ["d"]


def test_expiry_deletes_only_ended_ensembles_past_the_ttl(store):
    for name in ("old-done", "old-pending", "old-cancelled", "new-done"):
        store.create(name, REQUEST, [(0, 1)])
    for name in ("old-done", "new-done"):
        store.store_chunk(name, 0, [], [], "w")
    store.cancel("old-cancelled")
    with store._session.begin() as session:
        session.execute(update(EnsembleRow).where(EnsembleRow.id.like("old-%")).values(created=0.0))
    assert store.delete_expired() == 2
    assert store.record("old-done") is None and store.record("old-cancelled") is None
    assert store.chunk_members("old-done", 0) is None
    assert store.record("old-pending") is not None and store.record("new-done") is not None


def test_a_refused_ensemble_is_forgotten(store):
    store.create("e", REQUEST, CHUNKS)
    store.delete("e")
    assert store.record("e") is None and store.pending_chunks("e") == []


def test_work_an_api_recorded_but_did_not_send_is_found_by_the_sweep_after_its_grace(store):
    """An API that died between recording and sending leaves ``broker_epoch`` None (issue 34, item 1): the
    sweep's query finds such a job or ensemble once it is older than the grace, never while it is being sent."""
    from store.idempotency import IdempotencyKeys, KeyBinding

    jobs = JobStore(str(store.engine.url.render_as_string(hide_password=False)), ttl_s=3600)
    try:
        jobs.create("job-unsent", REQUEST, "alice", queue="q", binding=KeyBinding("alice:k1", "f"))
        jobs.create("job-sent", REQUEST, "alice", queue="q")
        jobs.mark_sent("job-sent", "one")
        assert jobs.sent_before("one") == []  # within the grace: its API may be sending it now
        assert [row[0] for row in jobs.sent_before("one", grace_s=-1.0)] == ["job-unsent"]
        jobs.mark_sent("job-unsent", "one")
        assert jobs.sent_before("one", grace_s=-1.0) == []
        store.create("e-unsent", REQUEST, CHUNKS, queue="q", binding=KeyBinding("alice:k2", "f"))
        assert store.sent_before("one") == [] and [r[0] for r in store.sent_before("one", grace_s=-1.0)] == ["e-unsent"]
        store.mark_sent("e-unsent", "one")
        assert store.sent_before("one", grace_s=-1.0) == []
        keys = IdempotencyKeys(store.engine)
        assert keys.bound("alice:k2") == ("f", "e-unsent")
        store.delete("e-unsent", "alice:k2")  # refused by the broker: the key is free with it
        assert keys.bound("alice:k2") is None and keys.bound("alice:k1") == ("f", "job-unsent")
    finally:
        jobs.close()
