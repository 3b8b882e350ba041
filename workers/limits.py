"""A job's time limits, the same in queue mode (Celery) and embedded mode (a thread of the API).

The soft limit is checked cooperatively: every long loop of the computation core (integration
segments, Poincaré pieces, Lyapunov pieces, ensemble batches) reports progress at least every
fraction of a second, and the job's progress callback calls :meth:`Deadline.check`, which raises
:class:`JobTimeout` once the soft limit has passed. This is what makes the limit hold while heyoka
runs in C++: Celery's own soft limit is a signal whose Python handler runs only when control comes
back to Python, so a job inside one long ``propagate`` call ran on to the hard limit.
"""

from __future__ import annotations

import logging
import sys
import threading
import time
import traceback


class JobTimeout(RuntimeError):
    """The job ran past its time limit."""


def soft_limit_message(limit_s: float) -> str:
    """The error message of a job stopped at its soft time limit."""
    return f"the job exceeded its time limit of {limit_s:g} s"


def hard_limit_message(limit_s: float) -> str:
    """The error message of a job killed at its hard time limit."""
    return f"the job was killed at its hard time limit of {limit_s:g} s"


def log_thread_stacks(log: logging.Logger, why: str) -> None:
    """Log where every thread of this process is (a job past its soft limit: which step of it took the time,
    e.g. a symbolic computation in its own thread, :mod:`nonholonomic.bounded`), for the operator and the
    developers; the job's own error stays :func:`soft_limit_message`."""
    names = {t.ident: t.name for t in threading.enumerate()}
    parts = [f"{why}; the threads of this process:"]
    for ident, frame in sys._current_frames().items():
        parts.append(f"-- thread {names.get(ident, ident)}:\n" + "".join(traceback.format_stack(frame, limit=25)))
    log.warning("\n".join(parts))


class Deadline:
    """The soft time limit of one job, counted from its start.

    Parameters
    ----------
    limit_s : the soft limit in seconds (``settings.job_soft_time_limit_s``).
    """

    def __init__(self, limit_s: float) -> None:
        self.limit_s = limit_s
        self.at = time.monotonic() + limit_s

    @property
    def passed(self) -> bool:
        """Whether the limit has passed."""
        return time.monotonic() >= self.at

    def check(self) -> None:
        """Raise :class:`JobTimeout` (naming the limit) once the limit has passed."""
        if self.passed:
            raise JobTimeout(soft_limit_message(self.limit_s))
