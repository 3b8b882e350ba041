"""Admission control under a real uvicorn: the symbolic pool refuses what it cannot hold with a 503 and
``Retry-After`` (never a 408 storm), and ``/health`` keeps answering 200 while it is full (its latency is
measured in ``bench/``)."""

from __future__ import annotations

import statistics
import subprocess
import sys
import threading
import time

import httpx
import pytest

from tests.support import free_port, start_api, stop, wait_healthy

pytestmark = pytest.mark.integration

SO3 = {"variables": ["x", "y", "z"], "matrix": [["0", "z", "-y"], ["-z", "0", "x"], ["y", "-x", "0"]],
       "casimirs": {"|x|^2": "x**2 + y**2 + z**2"}}
#: Prints the seconds of each ``GET /health`` (200 only) until terminated.
PROBE = """
import sys, time, httpx
with httpx.Client(base_url=sys.argv[1], timeout=5) as client:
    while True:
        start = time.perf_counter()
        status = client.get("/health").status_code
        print(time.perf_counter() - start if status == 200 else 99.0, flush=True)
        time.sleep(0.02)
"""
#: The issue's storm was 44 concurrent symbolic requests.
CONCURRENT = 44


def test_a_storm_of_symbolic_requests_gets_503s_with_retry_after_and_health_stays_fast(tmp_path):
    port = free_port()
    api = start_api(port, tmp_path / "api.log", {"REDIS_URL": "", "NONHOLONOMIC_WARM_UP": "false",
                                                 "NONHOLONOMIC_SYMBOLIC_WORKERS": "2",
                                                 "NONHOLONOMIC_SYMBOLIC_QUEUE": "4",
                                                 # every request computed: an answer remembered by an earlier
                                                 # test would come back at once and never fill the pool
                                                 "NONHOLONOMIC_CACHE_DIR": "off"})
    base = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(base, timeout=60)
        # /health is probed from a process of its own, so that the storm's client threads do not delay it
        prober = subprocess.Popen([sys.executable, "-c", PROBE, base], stdout=subprocess.PIPE, text=True)
        time.sleep(0.5)
        answers: list[httpx.Response] = []
        clients = [httpx.Client(base_url=base, timeout=120) for _ in range(CONCURRENT)]

        def post(client: httpx.Client) -> None:
            with client:
                answers.append(client.post("/v1/brackets/verify", json=SO3))

        posters = [threading.Thread(target=post, args=(client,)) for client in clients]
        for t in posters:
            t.start()
        for t in posters:
            t.join()
        prober.terminate()
        health_s = [float(line) for line in prober.communicate(timeout=10)[0].split()]

        codes = sorted(r.status_code for r in answers)
        assert set(codes) <= {200, 503}, codes  # no 408, no 500
        ok, busy = codes.count(200), [r for r in answers if r.status_code == 503]
        assert ok >= 6 and busy, codes  # the 2 running and 4 waiting are served; the rest refused at once
        for r in busy:
            problem = r.json()
            assert problem["type"] == "/problems/overloaded" and "symbolic_workers=2" in problem["detail"]
            assert int(r.headers["retry-after"]) >= 1
        for r in answers:
            if r.status_code == 200:
                assert r.json()["jacobi"]["passed"] and r.json()["casimirs"][0]["passed"]
        # /health needs no request thread: it keeps answering 200 while every slot and the queue are taken.
        # A hang guard, not a latency result (0.01 s median quiet, 0.2 s max with two busy processes beside
        # the suite; its p99 is measured in bench/bench_admission.py and bench/bench_load.py)
        assert len(health_s) >= 5 and max(health_s) < 2.0, (max(health_s), statistics.median(health_s))
        pool = httpx.get(f"{base}/health").json()["symbolic"]
        assert pool == {"size": 2, "queue": 4, "running": 0, "waiting": 0, "refused": len(busy)}
        # after the storm, the pool serves again
        assert httpx.post(f"{base}/v1/brackets/verify", json=SO3, timeout=60).status_code == 200
    except Exception:
        print((tmp_path / "api.log").read_text()[-4000:])
        raise
    finally:
        stop(api)
