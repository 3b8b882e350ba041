"""How much this process has integrated: trajectories integrated and section crossings found.

Counted where the work happens (:func:`nonholonomic.numerics.integration.integrate`, the batch, the
sections, the periodic-orbit flows); read by the service and the workers for their metrics
(``nonholonomic_integrations_total``, ``nonholonomic_crossings_total``). Pure bookkeeping: a lock and
two integers, no I/O.
"""

from __future__ import annotations

import threading

_lock = threading.Lock()
_integrations = 0
_crossings = 0


def count(integrations: int = 0, crossings: int = 0) -> None:
    """Add ``integrations`` integrated trajectories and ``crossings`` section crossings to the totals."""
    global _integrations, _crossings
    with _lock:
        _integrations += integrations
        _crossings += crossings


def totals() -> tuple[int, int]:
    """``(integrations, crossings)`` since the process started (monotone)."""
    with _lock:
        return _integrations, _crossings
