"""Test-wide settings.

Hypothesis runs derandomized under CI (``CI`` set): the same examples every run, so a red CI is
reproducible and no new counterexample's shrinking can blow the time limit. Locally it explores.
"""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
settings.register_profile("dev", deadline=None, print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "dev")


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:  # type: ignore[no-untyped-def]
    """List symbolic computations still running at the end: a thread past its budget keeps the
    interpreter busy and slows every later test (nonholonomic.bounded cannot stop it)."""
    from nonholonomic import bounded

    running = [key for key, task in list(bounded._tasks.items()) if not task.done.is_set()]
    if running:
        terminalreporter.write_sep("-", f"{len(running)} symbolic computation(s) still running")
        for key in running:
            terminalreporter.write_line(str(key)[:200])
