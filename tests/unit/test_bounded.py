"""The one runner of symbolic work (:mod:`nonholonomic.bounded`): every computation runs to its end
("done", or "error" when sympy raises), identical calls share it, finished results are cached and
remembered; the clock is only a safety cap that fails the caller (never a verdict)."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest

from nonholonomic import bounded, memo

#: Hang guard of the waits below (the computations take milliseconds).
HANG_GUARD_S = 60.0


def _slow(event: threading.Event, value: int) -> tuple[bool, str]:
    event.wait(HANG_GUARD_S)
    return True, f"proved {value}"


def _unique(name: str) -> tuple[str, str, float]:
    """A key no other test (or earlier run of this one in the process) used."""
    return ("test-bounded", name, time.monotonic())


@pytest.fixture
def cap() -> Iterator[None]:
    """The safety cap restored after the test (whatever it set)."""
    before = bounded.safety_cap_s()
    try:
        yield
    finally:
        bounded.set_safety_cap(before)


def test_a_computation_runs_to_its_end_and_its_detail_holds_no_time() -> None:
    outcome = bounded.run(_unique("done"), lambda: (True, "proved identically zero"))
    assert outcome.status == "done" and outcome.value == (True, "proved identically zero")
    assert bounded.verdict(outcome) == (True, "proved identically zero", None)
    assert bounded.prove(_unique("prove"), lambda: (False, "a non-zero numerator", {"terms": 3})) == \
        (False, "a non-zero numerator")


def test_an_exception_is_an_undecided_verdict_not_a_crash() -> None:
    def fails() -> tuple[bool, str]:
        raise ZeroDivisionError("division by zero")

    outcome = bounded.run(_unique("error"), fails)
    assert outcome.status == "error" and outcome.message == "ZeroDivisionError: division by zero"
    assert bounded.verdict(outcome) == (None, "sympy could not decide: ZeroDivisionError: division by zero", None)


def test_the_same_key_shares_one_computation_and_its_result() -> None:
    release = threading.Event()
    key = _unique("shared")
    task = bounded.start(key, _slow, (release, 1))
    assert bounded.start(key, _slow, (release, 2)) is task  # the running task, not a new one
    release.set()
    first = bounded.run(key, _slow, (release, 3))
    again = bounded.run(key, _slow, (release, 4))  # finished: the cached result
    assert first.status == again.status == "done" and first.value == again.value == (True, "proved 1")
    assert bounded.prove(key, _slow, (release, 5)) == (True, "proved 1")


def test_proofs_started_together_run_side_by_side() -> None:
    """``start`` several, then ``run`` each with the same key: the waits overlap."""
    release = threading.Event()
    keys = [_unique(f"together-{i}") for i in range(3)]
    tasks = [bounded.start(k, _slow, (release, i)) for i, k in enumerate(keys)]
    assert not any(t.done.is_set() for t in tasks)  # all three are running at once
    release.set()
    assert [bounded.prove(k, _slow, (release, 9)) for k in keys] == [(True, f"proved {i}") for i in range(3)]


class _Dict:
    """A memo in a dict (the protocol of :class:`nonholonomic.memo.Memo`)."""

    def __init__(self) -> None:
        self.data: dict[str, bytes] = {}

    def load(self, key: str) -> bytes | None:
        return self.data.get(key)

    def save(self, key: str, data: bytes) -> None:
        self.data[key] = data

    def discard(self, key: str) -> None:
        self.data.pop(key, None)


def test_a_result_is_remembered_across_processes_with_the_same_detail(monkeypatch: pytest.MonkeyPatch) -> None:
    store = _Dict()
    previous = memo.installed()
    memo.install(store)
    try:
        key = _unique("memo")
        first = bounded.run(key, _proof_of, (7,))
        assert first.status == "done" and not first.remembered and len(store.data) == 1
        monkeypatch.setattr(bounded, "_tasks", type(bounded._tasks)())  # a new process: nothing cached
        second = bounded.run(key, _proof_of, (8,))
        assert second.remembered and second.value == first.value == (True, "proved 7")
        assert bounded.verdict(second) == bounded.verdict(first)  # the same words, remembered or not
    finally:
        memo.install(previous)


def _proof_of(value: int) -> tuple[bool, str]:
    return True, f"proved {value}"


def test_an_error_is_not_remembered() -> None:
    store = _Dict()
    previous = memo.installed()
    memo.install(store)
    try:
        assert bounded.run(_unique("memo-error"), _divide, (0,)).status == "error"
        assert store.data == {}
    finally:
        memo.install(previous)


def _divide(x: int) -> tuple[bool, str]:
    return True, f"{1 / x}"


def test_past_the_safety_cap_the_caller_fails_and_the_next_call_gets_the_result(cap: None) -> None:
    release = threading.Event()
    key = _unique("cap")
    bounded.set_safety_cap(0.05)
    try:
        with pytest.raises(bounded.SafetyCapExceeded, match="safety cap of 0.05 s") as caught:
            bounded.run(key, _slow, (release, 1))
        assert "no verdict was given" in str(caught.value) and caught.value.seconds == 0.05
    finally:
        release.set()
    bounded.set_safety_cap(HANG_GUARD_S)
    # the computation went on in its thread: the same key gets its result, not a new computation
    assert bounded.run(key, _slow, (release, 2)).value == (True, "proved 1")


def _outer(release: threading.Event, inner_key: tuple) -> tuple[bool, str]:
    inner = bounded.run(inner_key, _slow, (release, 1))
    return True, f"outer after {inner.value[1]}"


def test_an_inner_steps_cap_fails_the_outer_computation_too_and_is_not_cached(cap: None) -> None:
    """A nested ``bounded.run`` past the cap raises in the outer computation's thread: the outer caller
    gets the same failure (no verdict), and the outer key is forgotten, so a later call computes again."""
    release = threading.Event()
    inner_key, outer_key = _unique("inner"), _unique("outer")
    bounded.set_safety_cap(0.05)
    try:
        task = bounded.start(outer_key, _outer, (release, inner_key))
        assert task.done.wait(HANG_GUARD_S)  # the outer computation ended: its inner wait hit the cap
        with pytest.raises(bounded.SafetyCapExceeded, match="_slow"):
            bounded.run(outer_key, _outer, (release, inner_key))
        assert outer_key not in bounded._tasks
    finally:
        release.set()
    bounded.set_safety_cap(HANG_GUARD_S)
    again = bounded.run(outer_key, _outer, (release, inner_key))  # computed again, the inner one finished
    assert again.status == "done" and again.value == (True, "outer after proved 1")


def test_past_max_running_a_computation_runs_in_its_callers_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bounded, "MAX_RUNNING", bounded._running())
    where = bounded.run(_unique("inline"), lambda: threading.current_thread().name)
    assert where.status == "done" and where.value == threading.current_thread().name


def test_there_is_no_timeout_verdict() -> None:
    """Only "done" and "error" exist: no status, message or function that a clock decides."""
    assert not {"cut_short", "cut_short_count", "peeking"} & set(dir(bounded))
    outcome = bounded.run(_unique("statuses"), lambda: (None, "undecided: not rational in tan(q/2)"))
    assert outcome.status in ("done", "error")
    assert bounded.verdict(outcome) == (None, "undecided: not rational in tan(q/2)", None)
