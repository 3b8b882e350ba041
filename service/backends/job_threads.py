"""Embedded mode's job threads: a fixed number of threads taking work from one queue, first in first
out, where a thread stuck past a job's hard time limit is replaced.

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
    count : how many calls run at once.
    name : the threads' name prefix.
    """

    def __init__(self, count: int, name: str) -> None:
        self._work: queue.SimpleQueue[tuple[Callable[..., Any], tuple[Any, ...]] | None] = queue.SimpleQueue()
        self._name, self._lock, self._serial = name, threading.Lock(), 0
        self._threads: set[threading.Thread] = set()
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

    def replace(self, thread: threading.Thread) -> bool:
        """Give ``thread``'s place to a new thread (``thread`` is stuck); True if it was one of ours."""
        with self._lock:
            if thread not in self._threads or self._closed:
                return False
            self._threads.discard(thread)
            self._start()
        log.error("job thread %s abandoned (stuck past a job's hard time limit); %s started in its place",
                  thread.name, f"{self._name}-{self._serial}")
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
                if me not in self._threads:  # replaced while stuck: the new thread has its place
                    return

    def close(self, timeout: float) -> None:
        """Drop the calls not started and stop the threads, waiting up to ``timeout`` seconds for the
        running calls to return (they should be asked to stop first)."""
        with self._lock:
            self._closed = True
            threads = list(self._threads)
        while True:
            try:
                self._work.get_nowait()
            except queue.Empty:
                break
        for _ in threads:
            self._work.put(None)
        end = time.monotonic() + timeout
        for thread in threads:
            thread.join(max(0.0, end - time.monotonic()))
