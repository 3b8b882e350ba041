"""Embedded mode's job threads: a fixed number of threads taking work from one queue, first in first
out, where a thread stuck past a job's hard time limit is replaced, and a thread on a long job moves to
the long lane (:meth:`JobThreads.promote`): a new thread takes its place in the queue, so short jobs do
not wait behind a long one (issue 34, item 4).

A Python thread cannot be killed. A job that ignores its soft limit (code that never comes back to
Python, such as a compile in LLVM) is abandoned at its hard limit: :meth:`JobThreads.replace` starts
a new thread in its place, so the next job runs; the stuck thread ends when its work returns. Every
long loop of the computation core reports progress (and so stops at the soft limit or when
cancelled) within a fraction of a second, so abandoning is the last resort, not the rule.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from typing import Any

log = logging.getLogger(__name__)


class JobThreads:
    """``count`` daemon threads running submitted calls in order.

    Parameters
    ----------
    count : how many threads take calls from the queue.
    name : the threads' name prefix.
    long_lane : how many threads on long calls may be promoted out of the queue's ``count`` at once.
    """

    def __init__(self, count: int, name: str, long_lane: int = 0) -> None:
        self._work: queue.SimpleQueue[tuple[Callable[..., Any], tuple[Any, ...]] | None] = queue.SimpleQueue()
        self._name, self._lock, self._serial = name, threading.Lock(), 0
        self._threads: set[threading.Thread] = set()
        self.long_lane = long_lane
        #: Threads finishing a long call in the long lane (they end with it).
        self.promoted: set[threading.Thread] = set()
        #: Threads given up (stuck, or a cancelled job's) and replaced.
        self.let_go = 0
        self._closed = False
        with self._lock:
            for _ in range(count):
                self._start()

    def _start(self) -> None:
        self._serial += 1
        thread = threading.Thread(target=self._loop, daemon=True, name=f"{self._name}-{self._serial}")
        self._threads.add(thread)
        thread.start()

    def submit(self, fn: Callable[..., Any], *args: Any) -> None:
        """Run ``fn(*args)`` on the next free thread (nothing once closed)."""
        if not self._closed:
            self._work.put((fn, args))

    def pending(self) -> int:
        """Calls not started yet."""
        return self._work.qsize()

    def status(self) -> dict[str, Any]:
        """For ``/health``: the long lane's size and occupancy, and how many threads were let go."""
        with self._lock:
            return {"long_lane": {"size": self.long_lane, "running": len(self.promoted)}, "let_go": self.let_go}

    def replace(self, thread: threading.Thread, why: str) -> bool:
        """Give ``thread``'s place to a new thread (``thread`` is stuck, or runs a cancelled job that has not
        come back to Python yet); True if it was one of ours."""
        with self._lock:
            if self._closed:
                return False
            if thread in self.promoted:  # its place in the long lane is free again
                self.promoted.discard(thread)
                self.let_go += 1
                return True
            if thread not in self._threads:
                return False
            self._threads.discard(thread)
            self._start()
            self.let_go += 1
        log.error("job thread %s abandoned (%s); %s started in its place", thread.name, why,
                  f"{self._name}-{self._serial}")
        return True

    def promote(self, thread: threading.Thread) -> bool:
        """Move ``thread`` (on a long call) to the long lane if it has room: a new thread takes its place in
        the queue and ``thread`` ends with its call. True if moved."""
        with self._lock:
            if self._closed or thread not in self._threads or len(self.promoted) >= self.long_lane:
                return False
            self._threads.discard(thread)
            self.promoted.add(thread)
            self._start()
        log.info("job thread %s moved to the long lane; %s takes the next jobs", thread.name,
                 f"{self._name}-{self._serial}")
        return True

    def _loop(self) -> None:
        me = threading.current_thread()
        while True:
            item = self._work.get()
            if item is None:
                return
            fn, args = item
            try:
                fn(*args)
            except Exception:  # logged; the thread takes the next call
                log.exception("job thread %s: uncaught error", me.name)
            with self._lock:
                if me not in self._threads:  # promoted, or replaced while stuck: the new thread has its place
                    self.promoted.discard(me)
                    return

    def close(self, timeout: float) -> None:
        """Drop the calls not started and stop the threads, waiting up to ``timeout`` seconds for the
        running calls to return (they should be asked to stop first)."""
        with self._lock:
            self._closed = True
            threads = list(self._threads)
            promoted = list(self.promoted)
        while True:
            try:
                self._work.get_nowait()
            except queue.Empty:
                break
        for _ in threads:
            self._work.put(None)
        end = time.monotonic() + timeout
        for thread in threads + promoted:
            thread.join(max(0.0, end - time.monotonic()))
