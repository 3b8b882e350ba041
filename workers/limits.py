"""A job's time limits, the same in queue mode (Celery) and embedded mode (a thread of the API).

The soft limit is checked cooperatively: every long loop of the computation core (integration
segments, Poincaré pieces, Lyapunov pieces, ensemble batches) reports progress at least every
fraction of a second, and the job's progress callback calls :meth:`Deadline.check`, which raises
:class:`JobTimeout` once the soft limit has passed. This is what makes the limit hold while heyoka
runs in C++: Celery's own soft limit is a signal whose Python handler runs only when control comes
back to Python, so a job inside one long ``propagate`` call ran on to the hard limit.
"""

from __future__ import annotations

import time


class JobTimeout(RuntimeError):
    """The job ran past its time limit."""


def soft_limit_message(limit_s: float) -> str:
    """The error message of a job stopped at its soft time limit."""
    return f"the job exceeded its time limit of {limit_s:g} s"


def hard_limit_message(limit_s: float) -> str:
    """The error message of a job killed at its hard time limit."""
    return f"the job was killed at its hard time limit of {limit_s:g} s"


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
