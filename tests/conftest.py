"""Test-wide settings.

Hypothesis runs derandomized under CI (``CI`` set): the same examples every run, so a red CI is
reproducible and no new counterexample's shrinking can blow the time limit. Locally it explores.
"""

from __future__ import annotations

import os
import tempfile
from collections import Counter

import pytest
from hypothesis import settings

# Embedded mode's job store: never the working directory's .nonholonomic/ (a module-scoped app uses
# this folder; each test gets a fresh one below), and one of its own for each pytest-xdist worker
# (the workers inherit the controller's environment: a shared SQLite file would be migrated twice).
_WORKER = os.environ.get("PYTEST_XDIST_WORKER")
if _WORKER or "NONHOLONOMIC_DATA_DIR" not in os.environ:
    os.environ["NONHOLONOMIC_DATA_DIR"] = tempfile.mkdtemp(prefix=f"nonholonomic-tests-{_WORKER or 'main'}-")

settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
settings.register_profile("dev", deadline=None, print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "dev")


@pytest.fixture(autouse=True)
def _fresh_job_store(monkeypatch, tmp_path) -> None:
    """Each test's embedded apps start with an empty job store (SQLite in the test's tmp_path)."""
    monkeypatch.setenv("NONHOLONOMIC_DATA_DIR", str(tmp_path / "store"))
    monkeypatch.delenv("NONHOLONOMIC_DATABASE_URL", raising=False)
    monkeypatch.delenv("DATABASE_URL", raising=False)


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:  # type: ignore[no-untyped-def]
    """List symbolic computations still running at the end: a thread past its budget keeps the
    interpreter busy and slows every later test (nonholonomic.bounded cannot stop it)."""
    from nonholonomic import bounded

    running = [key for key, task in list(bounded._tasks.items()) if not task.done.is_set()]
    if running:
        terminalreporter.write_sep("-", f"{len(running)} symbolic computation(s) still running")
        for key in running:
            terminalreporter.write_line(str(key)[:200])


#: The two longest files (minutes each, one test or three), handed out first: after them pytest-xdist's
#: order, the files of most tests first (the in-process unit files, which fill heyoka's disk cache before
#: the integration files start their servers). Last, either one was the suite's tail. (The integration files
#: that mostly wait, spread among the unit files from the start, made the run slower: 10 min 46 s against
#: 10 min 10 s; started cold, they compiled side by side what the unit files would have left in the cache.)
FIRST = ("integration/test_same_answer.py", "integration/test_tutorials.py")


def pytest_collection_modifyitems(config, items) -> None:  # type: ignore[no-untyped-def]
    """The files of :data:`FIRST`, then the others by their number of tests, most first (a stable sort;
    scripts/test.py passes ``--no-loadscope-reorder`` so that pytest-xdist keeps this order)."""
    counts = Counter(item.nodeid.split("::")[0] for item in items)
    first = {name: i for i, name in enumerate(FIRST)}

    def rank(item) -> tuple[int, int]:  # type: ignore[no-untyped-def]
        path = item.nodeid.split("::")[0]
        return first.get(path.removeprefix("tests/"), len(FIRST)), -counts[path]

    items.sort(key=rank)


@pytest.fixture(autouse=True)
def _no_memo_between_tests():  # type: ignore[no-untyped-def]
    """Each test starts with no memo installed in this process (an app's lifespan installs one for its
    own test): a proof remembered on disk by an earlier run must not answer a test that checks budgets
    and timeouts (seen in a second run of the suite)."""
    from nonholonomic import memo

    memo.install(None)
    yield
    memo.install(None)
