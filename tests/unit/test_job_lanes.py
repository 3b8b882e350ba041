"""Embedded mode's lanes (issue 34, item 4), on the backend itself with a stand-in for the job function:
a long job moves to the long lane and a short job sent after it succeeds while it still runs; a cancelled
job stuck in code that does not come back to Python (a compile) gives its thread's place up. The
stand-ins block until the test releases them, so without the lanes the short job would never run before
the long one ended: the hang guard, not a time, decides. Real jobs: tests/integration/test_embedded_limits.py."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

import service.backends.embedded as embedded
from schemas.settings import Settings
from service.backends.embedded import EmbeddedBackend

#: Hang guard (seconds) of each wait; never a result.
GUARD_S = 60.0


def _until(predicate: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + GUARD_S
    while not predicate():
        if time.monotonic() > deadline:
            pytest.fail(f"hang guard: {what} after {GUARD_S:g} s")
        time.sleep(0.01)


@pytest.fixture(params=[1])
def lanes(request, tmp_path, monkeypatch) -> Iterator[tuple[EmbeddedBackend, threading.Event]]:
    """The backend with a long lane of ``request.param`` threads, and the event that releases the stand-ins."""
    release = threading.Event()

    def run_job(request: dict[str, Any], progress: Callable[[float], bool]) -> dict[str, Any]:
        if request["kind"] == "long":  # reports progress while it runs (the pathological job)
            while not release.wait(0.05):
                if not progress(0.1):
                    raise embedded.IntegrationCancelled("cancelled")
        elif request["kind"] == "compiling":  # no progress report until released (an LLVM compile)
            release.wait(GUARD_S * 2)
            progress(0.5)
        return {"kind": request["kind"]}

    monkeypatch.setattr(embedded, "run_job", run_job)
    backend = EmbeddedBackend(Settings(database_url=f"sqlite:///{tmp_path / 'jobs.db'}", redis_url=None,
                                       warm_up=False, embedded_long_after_s=0.5, embedded_long_lane=request.param))
    try:
        yield backend, release
    finally:
        release.set()
        backend.close()


def _status(backend: EmbeddedBackend, job_id: str) -> str:
    record = backend.get(job_id)
    assert record is not None
    return record.status


def test_a_short_job_runs_beside_a_long_one_in_the_long_lane(lanes):
    backend, release = lanes
    long_job = backend.submit({"kind": "long"}).id
    _until(lambda: _status(backend, long_job) == "running", "the long job to start")
    short = backend.submit({"kind": "short"}).id
    _until(lambda: _status(backend, short) == "succeeded", "the short job beside the long one")
    assert _status(backend, long_job) == "running" and backend.health()["workers"]["long_lane"]["running"] == 1
    second_long = backend.submit({"kind": "long"}).id  # the lane is full (size 1): this one keeps the thread
    _until(lambda: _status(backend, second_long) == "running", "the second long job to start")
    time.sleep(1.0)  # past embedded_long_after_s: not promoted, the lane has no room
    assert backend.health()["workers"]["long_lane"]["running"] == 1
    release.set()
    _until(lambda: _status(backend, long_job) == "succeeded" and _status(backend, second_long) == "succeeded",
           "the long jobs to end once released")


@pytest.mark.parametrize("lanes", [0], indirect=True)  # no long lane: only the let-go frees the thread
def test_a_cancelled_job_stuck_in_a_compile_gives_its_place_up(lanes):
    backend, release = lanes
    stuck = backend.submit({"kind": "compiling"}).id
    _until(lambda: _status(backend, stuck) == "running", "the compiling job to start")
    assert backend.cancel(stuck).status == "cancelled"
    short = backend.submit({"kind": "short"}).id
    _until(lambda: _status(backend, short) == "succeeded", "the short job after the cancelled one")
    assert not release.is_set() and backend.health()["workers"]["let_go"] == 1  # still compiling, let go
    release.set()
    time.sleep(0.2)
    assert _status(backend, stuck) == "cancelled"  # its late end changes nothing
