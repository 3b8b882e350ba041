"""A job's time limits in embedded mode (issue 19, item 3): the soft limit at the job's progress reports
and, for Python code that reports none, raised in its thread by the watchdog; the hard limit for code
that never comes back to Python (a C call stands in for heyoka's C++): the job is recorded failed and
its thread replaced, so the next job runs. A cancelled job stops at its next progress report.

These tests replace ``run_job`` by small stand-ins to reach each path on purpose; the real jobs are in
``tests/integration/test_embedded_limits.py``."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest

from schemas.settings import Settings
from service.backends import embedded
from service.backends.embedded import EmbeddedBackend
from service.backends.job_threads import JobThreads
from workers.limits import Deadline, JobTimeout

#: The limits of these tests: the soft one's reaction (a progress report, or the watchdog's exception) may
#: come 2.5 s late on a loaded machine and still be the soft limit's, not the hard one's.
SOFT, HARD = 0.5, 3.0
#: Hang guard of every wait (far above the fraction of a second to the few seconds each step needs).
GUARD_S = 60.0


def _wait_end(backend: EmbeddedBackend, job_id: str) -> str:
    end = time.monotonic() + GUARD_S
    while time.monotonic() < end:
        status = backend.get(job_id).status
        if status in ("succeeded", "failed", "cancelled"):
            return status
        time.sleep(0.02)
    raise TimeoutError(f"hang guard: job {job_id} did not end within {GUARD_S:g} s")


@pytest.fixture()
def backend(tmp_path) -> Iterator[EmbeddedBackend]:
    b = EmbeddedBackend(Settings(data_dir=str(tmp_path), warm_up=False, job_soft_time_limit_s=SOFT,
                                 job_time_limit_s=HARD))
    yield b
    b.close()


def test_a_deadline_raises_naming_its_limit_once_passed(monkeypatch):
    from workers import limits

    now = [1000.0]  # the deadline's clock, moved by the test (not by the machine's speed)
    monkeypatch.setattr(limits, "time", type("Clock", (), {"monotonic": staticmethod(lambda: now[0])}))
    deadline = Deadline(0.05)
    deadline.check()
    now[0] += 0.049
    deadline.check()  # not yet
    now[0] += 0.001
    with pytest.raises(JobTimeout, match="the job exceeded its time limit of 0.05 s"):
        deadline.check()


def test_a_job_reporting_progress_stops_at_its_soft_limit(backend, monkeypatch):
    def integrating(request, progress):  # a long integration: reports progress between segments
        while True:
            progress(0.5)
            time.sleep(0.01)

    monkeypatch.setattr(embedded, "run_job", integrating)
    job = backend.submit({"t": 1})
    assert _wait_end(backend, job.id) == "failed"
    assert backend.get(job.id).error == {"type": "JobTimeout", "message": "the job exceeded its time limit of 0.5 s"}


def test_python_code_without_progress_gets_the_soft_limit_raised_in_its_thread(backend, monkeypatch):
    stuck_until = time.monotonic() + GUARD_S

    def symbolic(request, progress):  # pure Python, no progress report (sympy, say)
        while time.monotonic() < stuck_until:
            sum(range(1000))
        return {"never": True}

    monkeypatch.setattr(embedded, "run_job", symbolic)
    job = backend.submit({"t": 1})
    assert _wait_end(backend, job.id) == "failed"
    assert backend.get(job.id).error == {"type": "JobTimeout", "message": "the job exceeded its time limit of 0.5 s"}
    monkeypatch.setattr(embedded, "run_job", lambda request, progress: {"ok": True})
    assert _wait_end(backend, backend.submit({"t": 2}).id) == "succeeded"  # the same thread runs the next job


def test_a_job_stuck_outside_python_fails_at_the_hard_limit_and_its_thread_is_replaced(backend, monkeypatch):
    release = threading.Event()
    threads: list[threading.Thread] = []

    def compiling(request, progress):  # a C call that never comes back to Python (LLVM compiling, say)
        threads.append(threading.current_thread())
        if request["t"] == 1:
            release.wait(GUARD_S)
        return {"t": request["t"]}

    monkeypatch.setattr(embedded, "run_job", compiling)
    stuck = backend.submit({"t": 1})
    small = backend.submit({"t": 2})  # queued behind it: the one thread is taken
    assert _wait_end(backend, stuck.id) == "failed"
    assert backend.get(stuck.id).error == {
        "type": "JobTimeout",
        "message": f"the job was stopped at its hard time limit of {HARD:g} s "
                   "(its thread did not return and was replaced)"}
    assert _wait_end(backend, small.id) == "succeeded"
    assert threads[1] is not threads[0]  # a new thread took the stuck one's place
    release.set()  # the stuck call returns at last: its thread ends, the job's record stays as it was
    threads[0].join(GUARD_S)
    assert not threads[0].is_alive()
    assert backend.get(stuck.id).status == "failed" and backend.get(stuck.id).result is None


def test_a_cancelled_job_stops_at_its_next_progress_report(backend, monkeypatch):
    running = threading.Event()

    def integrating(request, progress):
        from nonholonomic.numerics.integration import IntegrationCancelled

        while progress(0.1):
            running.set()
            time.sleep(0.01)
        raise IntegrationCancelled("cancelled")

    monkeypatch.setattr(embedded, "run_job", integrating)
    job = backend.submit({"t": 1})
    assert running.wait(GUARD_S)
    backend.cancel(job.id)
    assert _wait_end(backend, job.id) == "cancelled"
    monkeypatch.setattr(embedded, "run_job", lambda request, progress: {"ok": True})
    assert _wait_end(backend, backend.submit({"t": 2}).id) == "succeeded"


def test_job_threads_run_in_order_and_close_drops_what_did_not_start():
    threads = JobThreads(1, "test-job")
    done: list[int] = []
    gate = threading.Event()
    threads.submit(gate.wait, GUARD_S)
    for i in range(3):
        threads.submit(done.append, i)
    assert threads.pending() in (3, 4)  # the first call taken by the thread, or not yet
    gate.set()
    end = time.monotonic() + GUARD_S
    while len(done) < 3:
        assert time.monotonic() < end, f"hang guard: {done} after {GUARD_S:g} s"
        time.sleep(0.01)
    assert done == [0, 1, 2]
    threads.close(GUARD_S)
    threads.submit(done.append, 9)
    assert threads.pending() == 0
