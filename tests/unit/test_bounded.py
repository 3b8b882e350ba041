"""The one runner for symbolic work under a budget (:mod:`nonholonomic.bounded`)."""

from __future__ import annotations

import threading
import time

import pytest

from nonholonomic import bounded


def _slow(event: threading.Event, value: int) -> tuple[bool, str]:
    event.wait(10.0)
    return True, f"proved {value}"


def test_timeout_then_the_cached_result_answers_the_next_call() -> None:
    release = threading.Event()
    key = ("test-bounded", "timeout")
    first = bounded.run(key, _slow, (release, 1), 0.05)
    assert first.status == "timeout" and "continues in the background" in first.message
    release.set()
    second = bounded.run(key, _slow, (release, 2), 5.0)  # same key: the running task, not a new one
    assert second.status == "done" and second.value == (True, "proved 1")
    proven, detail = bounded.prove(key, _slow, (release, 3), 0.0)
    assert proven is True and detail.startswith("proved 1") and "cached per process" in detail


def test_an_exception_is_an_undecided_verdict_not_a_crash() -> None:
    def fails() -> tuple[bool, str]:
        raise ZeroDivisionError("division by zero")

    outcome = bounded.run(("test-bounded", "error"), fails, (), 5.0)
    assert outcome.status == "error" and "ZeroDivisionError" in outcome.message
    assert bounded.verdict(outcome)[0] is None


def test_runaway_computations_are_capped(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bounded, "MAX_RUNNING", bounded._running() + 2)
    release = threading.Event()
    try:
        for i in range(2):
            assert bounded.run(("test-bounded", "cap", i), _slow, (release, i), 0.0).status == "timeout"
        refused = bounded.run(("test-bounded", "cap", 2), _slow, (release, 2), 1.0)
        assert refused.status == "busy" and "already running" in refused.message
        proven, detail = bounded.prove(("test-bounded", "cap", 3), _slow, (release, 3), 1.0)
        assert proven is None and "not started" in detail
    finally:
        release.set()
    deadline = time.monotonic() + 5.0
    while bounded._running() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert bounded.run(("test-bounded", "cap", 4), _slow, (release, 4), 5.0).status == "done"


def test_every_computation_a_budget_or_a_busy_process_left_undone_is_counted(monkeypatch: pytest.MonkeyPatch) -> None:
    """The count that decides whether a whole answer may be remembered (a symbolic request's, the paper
    report's): a timeout and a refusal move it, a finished computation does not."""
    release = threading.Event()
    try:
        start = bounded.cut_short_count()
        assert bounded.run(("test-bounded", "count", 0), _slow, (release, 0), 0.01).status == "timeout"
        assert bounded.cut_short_count() == start + 1
        monkeypatch.setattr(bounded, "MAX_RUNNING", bounded._running())
        assert bounded.run(("test-bounded", "count", 1), _slow, (release, 1), 1.0).status == "busy"
        assert bounded.cut_short_count() == start + 2
        monkeypatch.undo()
        release.set()
        assert bounded.run(("test-bounded", "count", 0), _slow, (release, 0), 5.0).status == "done"
        assert bounded.cut_short_count() == start + 2
    finally:
        release.set()
