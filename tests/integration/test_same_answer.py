"""Issue 31: the same request gets the same answer, whatever the load, the caches or the mode.

Heavy requests (the tilted Suslov problem, Veselova's system and Chaplygin's sphere from their Lagrangians, a
hamiltonize and a bracket request; the rattleback's sampled search, the sphere's path, is left to its unit tests)
are sent three times: to a queue-mode API with a real Celery worker (two pool processes) and empty caches while busy
processes load both cores (at the lowest priority: in the suite, the other test processes are the load), to that API
again on a quiet machine (warm caches: what one pool process derived, the other reads back), and to an embedded API
with empty caches on a quiet machine. Every answer (the job's status, error and result; the symbolic routes' JSON)
is compared with the timing fields removed
(:func:`schemas.results.without_timing`): they must be identical, byte for byte. (The loaded run is the queue's:
its two pool processes derive side by side, and the busy loops spin only while the answers are computed. The
embedded API runs the jobs in threads of one process, several at once past a few seconds (the long lane): where
mpmath's one global precision once let one job's sympy drop another's 50-digit test to 15 digits,
nonholonomic/numerics/precision.py.)
"""

from __future__ import annotations

import json
import subprocess
import sys
import uuid
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import pytest

from nonholonomic.systems.lagrangian_classics import CLASSICS
from schemas.results import without_timing
from tests.lagrangian_examples import CHAPLYGIN_SPHERE, VESELOVA
from tests.support import (
    TEST_REDIS_URL,
    free_port,
    poll_job,
    redis_available,
    start_api,
    start_worker,
    stop,
    wait_healthy,
)

pytestmark = pytest.mark.integration

#: Hang guard of one job (a cold tilted Suslov problem with two busy loops beside it takes about a minute).
JOB_GUARD_S = 900.0


def _short(job: Mapping[str, Any], **changes: Any) -> dict[str, Any]:
    return {**json.loads(json.dumps(job)), "t_final": 2.0, "samples": 21, **changes}


JOBS: dict[str, dict[str, Any]] = {
    "suslov_tilted": _short(CLASSICS["suslov_tilted"]["job"]),
    "veselova": {"system": VESELOVA, "initial_state": {"q": [0.1, 1.0, 0.2], "q_dot": [0.3, 0.5, 0.0]},
                 "project_initial_state": True, "t_final": 2.0, "samples": 21, "checks": ["integrals", "measure"]},
    "chaplygin_sphere": {"system": CHAPLYGIN_SPHERE,
                         "initial_state": {"q": [0.0, 0.0, 0.1, 1.0, 0.2], "q_dot": [0.0, 0.0, 0.3, 0.5, -0.2]},
                         "project_initial_state": True, "t_final": 2.0, "samples": 21,
                         "checks": ["integrals", "measure"]},
}
BRACKET = {"variables": ["x", "y", "z"], "matrix": [["0", "z", "-y"], ["-z", "0", "x"], ["y", "-x", "0"]],
           "casimirs": {"norm": "x**2 + y**2 + z**2", "wrong": "x**2"}}


def _answers(base: str) -> dict[str, Any]:
    """Every request's answer, timing fields removed: the jobs sent together, then the symbolic routes."""
    out: dict[str, Any] = {}
    with httpx.Client(base_url=base, timeout=JOB_GUARD_S) as client:
        veselova = client.get("/v1/hamiltonize/examples").json()["examples"]["veselova"]
        locations = {}
        for name, body in JOBS.items():
            r = client.post("/v1/jobs", json=body)
            assert r.status_code == 202, (name, r.status_code, r.text)
            locations[name] = r.headers["location"]
        for name, location in locations.items():
            view = poll_job(client, location, timeout=JOB_GUARD_S, interval=0.2)
            out[name] = without_timing({k: view[k] for k in ("status", "error", "result")})
            assert view["status"] == "succeeded", (name, view["error"])
        for name, route, body in (("hamiltonize", "/v1/hamiltonize", veselova),
                                  ("brackets", "/v1/brackets/verify", BRACKET)):
            r = client.post(route, json=body)
            assert r.status_code == 200, (name, r.status_code, r.text)
            out[name] = without_timing(r.json())
    return out


@contextmanager
def _busy(count: int = 2) -> Iterator[None]:
    """``count`` processes spinning on a core each (the machine's load, not the test's work), at the lowest
    priority (nice 19): run alone, this test's answers are computed beside them on two busy cores; in the
    suite, where the other test processes keep the cores busy, they take what those leave idle instead of
    slowing them down."""
    loops = [subprocess.Popen([sys.executable, "-c", "import os; os.nice(19)\nwhile True: pass"])
             for _ in range(count)]
    try:
        yield
    finally:
        for loop in loops:
            loop.kill()
            loop.wait()


def _diff(a: Any, b: Any, path: str = "") -> list[str]:
    """Where two JSON values differ (paths), for the failure message."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [d for k in sorted(set(a) | set(b)) for d in _diff(a.get(k), b.get(k), f"{path}.{k}")]
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in _diff(x, y, f"{path}[{i}]")]
    return [] if a == b else [f"{path}: {json.dumps(a)[:200]} != {json.dumps(b)[:200]}"]


def test_heavy_requests_get_identical_answers_loaded_and_quiet_cold_and_warm_embedded_and_queue(tmp_path: Path):
    if not redis_available():
        pytest.fail(f"no Redis at {TEST_REDIS_URL}: run the README's test command, which starts one")
    # 1. queue mode (the API, a real Celery worker with two pool processes, Redis, PostgreSQL), empty
    # caches, both cores loaded by other processes; 2. again, quiet and warm
    queue = f"same-{uuid.uuid4().hex[:8]}"  # its job store: the queue's own (tests.support.queue_database_url)
    env = {"NONHOLONOMIC_QUEUE": queue, "NONHOLONOMIC_WARM_UP": "false"}
    port = free_port()
    api = start_api(port, tmp_path / "api.log", {"REDIS_URL": TEST_REDIS_URL, **env,
                                                 "NONHOLONOMIC_CACHE_DIR": str(tmp_path / "cache-api")})
    worker_cache = tmp_path / "cache-worker"  # the worker's own, to see what its pool processes keep
    worker = start_worker(TEST_REDIS_URL, queue, tmp_path / "worker.log", concurrency=2,
                          extra_env={**env, "NONHOLONOMIC_CACHE_DIR": str(worker_cache)})
    try:
        wait_healthy(f"http://127.0.0.1:{port}", timeout=180)
        with _busy():  # from the first request to the last answer
            loaded = _answers(f"http://127.0.0.1:{port}")
        derived = sorted(p.name for p in worker_cache.glob("*.memo"))
        warm = _answers(f"http://127.0.0.1:{port}")
        # the worker's pool processes keep what they derived (without a warm-up too), and the warm run,
        # whichever process takes each job, reads it back: nothing is derived again
        assert len(derived) > 10, derived
        assert sorted(p.name for p in worker_cache.glob("*.memo")) == derived
    except Exception:
        # the worker's log whole enough for the threads' stacks it logs when a job passes its soft limit
        print((tmp_path / "api.log").read_text()[-4000:], (tmp_path / "worker.log").read_text()[-30000:], sep="\n")
        raise
    finally:
        stop(worker)
        stop(api)
    # 3. embedded mode (jobs in the API's own thread), empty caches, quiet
    port = free_port()
    api = start_api(port, tmp_path / "embedded.log", {"REDIS_URL": "", "NONHOLONOMIC_WARM_UP": "false",
                                                      "NONHOLONOMIC_CACHE_DIR": str(tmp_path / "cache-embedded")})
    try:
        wait_healthy(f"http://127.0.0.1:{port}", timeout=180)
        quiet = _answers(f"http://127.0.0.1:{port}")
    except Exception:
        print((tmp_path / "embedded.log").read_text()[-30000:])
        raise
    finally:
        stop(api)
    assert list(loaded) == list(quiet) == list(warm)
    for name in loaded:
        assert loaded[name] == quiet[name], (name, _diff(loaded[name], quiet[name])[:10])
        assert quiet[name] == warm[name], (name, _diff(quiet[name], warm[name])[:10])
    # the structure verdicts this comparison covers are the searches' own, not "not started" or a clock's
    structures = {name: loaded[name]["result"]["system"]["structure"] for name in JOBS}
    assert "MAX_FRACTION_TERMS" in structures["chaplygin_sphere"]["measure"]["reason"]
    assert structures["suslov_tilted"]["hamiltonization"]["verdict"] == "none"
    assert structures["veselova"]["hamiltonization"]["verdict"] == "found"
