"""Admission control under a real uvicorn: the symbolic pool refuses what it cannot hold with a 503 and
``Retry-After`` (never a 408 storm), and ``/health`` keeps answering 200 while it is full (its latency is
measured in ``bench/bench_admission.py`` and ``bench/bench_load.py``, not here)."""

from __future__ import annotations

import json
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
#: Hang guard (seconds) of one ``GET /health`` of the probe: far above its hundredths of a second.
HEALTH_GUARD_S = 60.0
#: Prints each ``GET /health``'s status and the symbolic pool it reports, as a JSON line, until terminated
#: (a request past the hang guard prints status 0).
PROBE = """
import json, sys, time, httpx
with httpx.Client(base_url=sys.argv[1], timeout=float(sys.argv[2])) as client:
    while True:
        try:
            r = client.get("/health")
            line = {"status": r.status_code, "symbolic": r.json().get("symbolic")}
        except httpx.TimeoutException:
            line = {"status": 0, "symbolic": None}
        print(json.dumps(line), flush=True)
        time.sleep(0.02)
"""
#: The issue's storm was 44 concurrent symbolic requests.
CONCURRENT = 44


def test_a_storm_of_symbolic_requests_gets_503s_with_retry_after_and_health_keeps_answering(tmp_path):
    port = free_port()
    api = start_api(port, tmp_path / "api.log", {"REDIS_URL": "", "NONHOLONOMIC_WARM_UP": "false",
                                                 "NONHOLONOMIC_SYMBOLIC_WORKERS": "2",
                                                 "NONHOLONOMIC_SYMBOLIC_QUEUE": "4",
                                                 # every request computed: an answer remembered by an earlier
                                                 # test would come back at once and never fill the pool
                                                 "NONHOLONOMIC_CACHE_DIR": "off"})
    base = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(base, timeout=300)  # a hang guard: an API starts within seconds
        # /health is probed from a process of its own, so that the storm's client threads do not delay it
        prober = subprocess.Popen([sys.executable, "-c", PROBE, base, str(HEALTH_GUARD_S)], stdout=subprocess.PIPE,
                                  text=True)
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
        out = prober.communicate(timeout=HEALTH_GUARD_S)[0]
        probes = [json.loads(line) for line in out.splitlines() if line.endswith("}")]  # not one cut short

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
        # /health needs no request thread: it keeps answering 200 while every slot and the queue are taken
        # (how fast is bench/bench_admission.py's and bench/bench_load.py's, its p99 against 100 ms)
        assert probes and all(p["status"] == 200 for p in probes), [p for p in probes if p["status"] != 200][:5]
        full = {"size": 2, "queue": 4, "running": 2, "waiting": 4}
        assert any({k: p["symbolic"][k] for k in full} == full for p in probes), probes[:: max(1, len(probes) // 20)]
        pool = httpx.get(f"{base}/health").json()["symbolic"]
        assert pool == {"size": 2, "queue": 4, "running": 0, "waiting": 0, "refused": len(busy)}
        # after the storm, the pool serves again
        assert httpx.post(f"{base}/v1/brackets/verify", json=SO3, timeout=60).status_code == 200
    except Exception:
        print((tmp_path / "api.log").read_text()[-4000:])
        raise
    finally:
        stop(api)
