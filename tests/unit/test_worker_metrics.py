"""The workers' metrics (:mod:`workers.metrics`) where races and dead processes would make them wrong."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import threading
import time

from nonholonomic.numerics import tally
from tests.support import ROOT
from workers import metrics


def test_moving_the_tally_from_many_threads_counts_each_integration_once(monkeypatch):
    """Two scrapes (or tasks) moving the core's tally at once: no count moved twice, none negative. Reading
    the totals yields the thread, so the race, if there is one, happens."""
    totals = tally.totals

    def slow_totals() -> tuple[int, int]:
        read = totals()
        time.sleep(0.0002)
        return read

    monkeypatch.setattr(tally, "totals", slow_totals)

    def counted() -> tuple[float, int]:
        """The counter and the part of the tally it has taken (read together, under the tally's lock)."""
        with metrics._tally_lock:
            return metrics.metrics().integrations._value.get(), metrics._tally_seen[0]

    tally.count(integrations=5)  # a backlog not taken yet, as earlier work in this process leaves
    start, seen = counted()
    errors: list[BaseException] = []

    def work() -> None:
        try:
            for _ in range(300):
                tally.count(integrations=1)
                metrics.add_tally()
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=work) for _ in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    metrics.add_tally()
    assert not errors, errors
    # each taken once: the counter moved by exactly what it took of the tally (other tests' job threads in this
    # process may integrate meanwhile: at least the 1800 of these threads)
    end, seen_end = counted()
    assert end - start == seen_end - seen and seen_end - seen >= 1800


def test_a_kind_outside_the_catalog_is_other():
    assert metrics.job_kind({"system": {"kind": "chaplygin_ball"}}) == "chaplygin_ball"
    assert metrics.job_kind({"system": {"kind": "x" * 60}}) == "other"
    assert metrics.job_kind({"system": "nonsense"}) == "other"
    assert metrics.job_kind({"job": "paper_report"}) == "paper_report" and metrics.job_kind({}) == "other"


def test_a_pool_process_killed_without_a_word_leaves_the_memory_gauge():
    """A process that ends without ``worker_process_shutdown`` (a hard time limit, an OOM kill) leaves no
    series behind; a live one keeps its own."""
    script = textwrap.dedent("""
        import os, sys, tempfile
        os.environ["PROMETHEUS_MULTIPROC_DIR"] = tempfile.mkdtemp()
        from prometheus_client import CollectorRegistry, generate_latest
        from workers import metrics
        metrics.use_multiprocess()
        child = os.fork()
        if child == 0:
            metrics.note_memory()
            os._exit(0)  # killed: no word to the parent
        os.waitpid(child, 0)
        metrics.note_memory()
        registry = CollectorRegistry()
        registry.register(metrics._LiveProcessesCollector())
        text = generate_latest(registry).decode()
        lines = [line for line in text.splitlines() if line.startswith("nonholonomic_worker_resident_memory_bytes")]
        print(lines, child, os.getpid())
        assert len(lines) == 1 and f'pid="{os.getpid()}"' in lines[0], (lines, child)
    """)
    done = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
