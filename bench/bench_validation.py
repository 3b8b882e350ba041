"""/health while the audit's expensive expressions are validated (issue 19, item 1).

    .venv/bin/python bench/bench_validation.py [--rounds 3] [--cap 120]

Starts the API (embedded mode, uvicorn) and posts, ``--rounds`` times, the three bodies of the audit at
once: a Poincaré surface ``(M1+gamma2+gamma3+1)**64`` (152 s to answer on main), a surface Phi of 59
nested sin (51 s) and a potential that is a long sum of distinct terms (16 s). A process of its own
polls ``GET /health`` every 20 ms meanwhile. Prints each POST's status and seconds and /health's p50,
p99 and max (the goal: p99 <= 100 ms). The first two are refused at once by deterministic measures of their
work (422), the third is read to its end (202); ``--cap`` is the validation's safety cap (a 503 past it).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import argparse  # noqa: E402
import os  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402

import httpx  # noqa: E402

from tests.api.test_validation_budget import LONG_SUM, NESTED_PHI, POWER_SURFACE  # noqa: E402
from tests.integration.test_validation_health import PROBE  # noqa: E402
from tests.support import free_port, start_api, stop, wait_healthy  # noqa: E402

BODIES = {"poincare.surface": POWER_SURFACE, "system.surface.Phi": NESTED_PHI, "system.potential.U": LONG_SUM}


def _post(base: str, field: str, body: dict, out: list[tuple[str, int, float, str]]) -> None:
    with httpx.Client(base_url=base, timeout=600) as client:
        start = time.perf_counter()
        r = client.post("/v1/jobs", json=body)
        reason = "" if r.status_code == 202 else "; ".join(f"{e['field']}: {e['reason'][:60]}"
                                                            for e in r.json().get("errors", []))
        out.append((field, r.status_code, time.perf_counter() - start, reason))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3, help="times the three bodies are posted (at once)")
    parser.add_argument("--cap", type=float, default=120.0, help="NONHOLONOMIC_VALIDATION_SAFETY_CAP_S")
    args = parser.parse_args()
    port = free_port()
    log = Path(tempfile.mkdtemp(prefix="bench-validation-")) / "api.log"
    api = start_api(port, log, {"REDIS_URL": "", "NONHOLONOMIC_WARM_UP": "false",
                                "NONHOLONOMIC_VALIDATION_SAFETY_CAP_S": str(args.cap)})
    base = f"http://127.0.0.1:{port}"
    prober = None
    try:
        wait_healthy(base, timeout=180)
        prober = subprocess.Popen([sys.executable, "-c", PROBE, base], stdout=subprocess.PIPE, text=True)
        time.sleep(1.0)
        posts: list[tuple[str, int, float, str]] = []
        for _ in range(args.rounds):
            threads = [threading.Thread(target=_post, args=(base, f, b, posts)) for f, b in BODIES.items()]
            for t in threads:
                t.start()
            for t in threads:
                t.join()
        time.sleep(0.5)
        prober.terminate()
        health = sorted(float(line) for line in prober.communicate(timeout=10)[0].split())
        prober = None
    finally:
        if prober is not None:
            prober.kill()
        stop(api)
    print(f"load: {os.getloadavg()[0]:.1f} (1 min), safety cap {args.cap:g} s, {args.rounds} rounds of 3 POSTs")
    for field, status, seconds, reason in posts:
        print(f"  POST {field:20s} {status}  {seconds:6.2f} s  {reason}")
    ms = [1000 * s for s in health]
    p99 = ms[min(len(ms) - 1, int(0.99 * len(ms)))]
    print(f"/health: {len(ms)} polls, p50 {statistics.median(ms):.1f} ms, p99 {p99:.1f} ms, max {ms[-1]:.1f} ms, "
          f"errors {sum(1 for s in health if s >= 99)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
