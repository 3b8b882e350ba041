"""A job past its soft time limit logs where every thread of its process is (workers/limits.py), so the step
that took the time, e.g. a symbolic computation in a thread of its own, can be named afterwards."""

from __future__ import annotations

import logging
import threading

from workers.limits import log_thread_stacks

#: Hang guard (seconds) of the helper thread; never a result.
GUARD_S = 30.0


def _a_symbolic_step_that_waits(started: threading.Event, release: threading.Event) -> None:
    started.set()
    release.wait(GUARD_S)


def test_the_stacks_of_every_thread_are_logged_with_their_names(caplog):
    started, release = threading.Event(), threading.Event()
    thread = threading.Thread(target=_a_symbolic_step_that_waits, args=(started, release), name="bounded-search")
    thread.start()
    try:
        assert started.wait(GUARD_S)
        with caplog.at_level(logging.WARNING, logger="jobs"):
            log_thread_stacks(logging.getLogger("jobs"), "job abc past its soft time limit")
    finally:
        release.set()
        thread.join(GUARD_S)
    text = caplog.records[0].getMessage()
    assert text.startswith("job abc past its soft time limit; the threads of this process:")
    assert "-- thread bounded-search:" in text and "_a_symbolic_step_that_waits" in text
    assert f"-- thread {threading.current_thread().name}:" in text and "log_thread_stacks" in text
