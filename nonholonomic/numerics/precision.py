"""mpmath's working precision, shared safely by the threads of one process.

mpmath keeps its precision in one global context (``mpmath.mp``): ``mpmath.workdps(50)`` in one thread sets
it for every thread, and restores on exit the value it found. Two threads evaluating at once then
interfere: one thread's exit drops the other to 15 digits in the middle of a 50-digit identity test,
whose comparison at 1e-40 then fails, and a proven Hamiltonization becomes ``undecided`` (seen in
embedded mode with two jobs running: the same request answered differently under load). Every
high-precision evaluation of the core goes through :func:`working_digits`, which holds one lock of the
process while the precision is changed: the threads take turns, and each computes at the precision it asked for.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager

import mpmath

__all__ = ["working_digits"]

_LOCK = threading.RLock()


@contextmanager
def working_digits(digits: int) -> Iterator[None]:
    """Evaluate with mpmath at ``digits`` decimal digits, alone among this process's threads.

    Parameters
    ----------
    digits : int
        mpmath's ``dps`` inside the block (15: double precision's).
    """
    with _LOCK, mpmath.workdps(digits):
        yield
