"""Issue 19, item 1 under a real uvicorn, with issue 31's rule: the audit's expensive expressions (a Poincaré
surface ``(M1+gamma2+gamma3+1)**64``, a surface Phi of 59 nested sin) are 422s naming the measure of their work
and its limit, a long sum of distinct terms within the measures is accepted (202): the same answers at any load;
``/health``, polled meanwhile from a process of its own, answers every time (on main: 152 s for one POST,
/health 4.4 s). Its latency is measured in bench/bench_validation.py, not asserted here."""

from __future__ import annotations

import subprocess
import sys
import threading
import time

import httpx
import pytest

from tests.api.test_validation_budget import LONG_SUM, NESTED_PHI, POWER_SURFACE, REFUSED
from tests.support import free_port, start_api, stop, wait_healthy

pytestmark = pytest.mark.integration

#: Prints the seconds of each ``GET /health`` (99 for an error) until terminated.
PROBE = """
import sys, time, httpx
with httpx.Client(base_url=sys.argv[1], timeout=30) as client:
    while True:
        start = time.perf_counter()
        try:
            ok = client.get("/health").status_code == 200
        except httpx.HTTPError:
            ok = False
        print(time.perf_counter() - start if ok else 99.0, flush=True)
        time.sleep(0.02)
"""
#: Hang guards (not the target: bench/bench_validation.py measures /health's p99 against 100 ms).
POST_GUARD_S = 120.0
HEALTH_GUARD_S = 30.0


def test_expensive_expressions_are_refused_by_their_measures_and_health_answers(tmp_path):
    port = free_port()
    api = start_api(port, tmp_path / "api.log", {"REDIS_URL": "", "NONHOLONOMIC_WARM_UP": "false"})
    base = f"http://127.0.0.1:{port}"
    prober = None
    try:
        wait_healthy(base, timeout=120)
        prober = subprocess.Popen([sys.executable, "-c", PROBE, base], stdout=subprocess.PIPE, text=True)
        time.sleep(0.5)
        answers: dict[str, httpx.Response] = {}

        def post(name: str, body: dict) -> None:
            with httpx.Client(base_url=base, timeout=POST_GUARD_S * 2) as client:
                answers[name] = client.post("/v1/jobs", json=body)

        fields = {"poincare.surface": POWER_SURFACE, "system.surface.Phi": NESTED_PHI, "system.potential.U": LONG_SUM}
        posters = [threading.Thread(target=post, args=item) for item in fields.items()]
        for t in posters:
            t.start()
        for t in posters:
            t.join()
        time.sleep(0.5)
        prober.terminate()
        health_s = [float(line) for line in prober.communicate(timeout=10)[0].split()]
        prober = None
        for field, r in answers.items():  # the client's timeout (2 x POST_GUARD_S) is the hang guard
            if field in REFUSED:
                errors = {e["field"]: e["reason"] for e in r.json()["errors"]}
                assert r.status_code == 422 and list(errors) == [field] and REFUSED[field] in errors[field], errors
            else:
                assert r.status_code == 202, (field, r.status_code, r.text)
        assert len(health_s) >= 10, health_s
        assert max(health_s) < HEALTH_GUARD_S, sorted(health_s)[-5:]  # every probe answered (99: an error)
    finally:
        if prober is not None:
            prober.kill()
        stop(api)
