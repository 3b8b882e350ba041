"""Deleting expired records now and then, from the writes themselves (no timer thread)."""

from __future__ import annotations

import threading
from collections.abc import Callable


class Expiry:
    """Calls ``delete_expired()`` at most every ``every_s`` seconds, from whichever write comes first
    (the others do not wait for it)."""

    def __init__(self, delete_expired: Callable[[], int], every_s: float = 60.0) -> None:
        self._delete_expired, self.every_s = delete_expired, every_s
        self._last = 0.0
        self._lock = threading.Lock()

    def now_and_then(self, now: float) -> None:
        if now - self._last < self.every_s or not self._lock.acquire(blocking=False):
            return
        try:
            self._last = now
            self._delete_expired()
        finally:
            self._lock.release()
