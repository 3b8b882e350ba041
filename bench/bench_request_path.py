"""A user's Lagrangian on the request path (issue 31): what a POST now does against what it did.

    .venv/bin/python bench/bench_request_path.py

For each heavy system (the rattleback, the tilted Suslov problem, the rolling disk, Veselova's system and
Chaplygin's sphere from their Lagrangians), each in a fresh process (cold caches): the request's check as it
is now (parse, sample-point checks, the outline: the plain elimination's field, the initial state by numbers;
``JobRequest.problems``) against the check as it was (the same with the derived equations,
``validation_definition``: the exact elimination, its kernels compiled for the field's check). Prints the
seconds of each and their ratio, with the load beside them.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1])
from schemas.jobs import JobRequest
from nonholonomic.initial_state import initial_state_problems
body = json.loads(sys.argv[2])
job = JobRequest.model_validate(body)
start = time.perf_counter()
if sys.argv[3] == "now":
    problems = job.problems()
else:  # as before issue 31: the derived equations, the field checked by its compiled kernel
    system = job.system.validation_definition()
    problems = initial_state_problems(system, job.system.parameter_values(), job.initial_state,
                                      job.project_initial_state)
print(json.dumps({"seconds": time.perf_counter() - start, "problems": [p.reason for p in problems]}))
"""


def bodies() -> dict[str, dict]:
    sys.path.insert(0, str(ROOT))
    from nonholonomic.systems.lagrangian_classics import CLASSICS
    from tests.integration.test_same_answer import JOBS

    return {"rattleback": CLASSICS["rattleback"]["job"], "suslov_tilted": CLASSICS["suslov_tilted"]["job"],
            "rolling_disk": CLASSICS["rolling_disk"]["job"], "veselova": JOBS["veselova"],
            "chaplygin_sphere": JOBS["chaplygin_sphere"]}


def run(body: dict, how: str) -> dict:
    env = {**os.environ, "NONHOLONOMIC_CACHE_DIR": "off"}
    out = subprocess.run([sys.executable, "-c", CHILD, str(ROOT), json.dumps(body), how], capture_output=True,
                         text=True, env=env, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> int:
    print(f"load: {os.getloadavg()[0]:.2f} (1 min), one fresh process per measurement, no memo")
    print(f"{'system':18} {'now (s)':>9} {'before (s)':>11} {'before/now':>11}  problems")
    for name, body in bodies().items():
        now, before = run(body, "now"), run(body, "before")
        print(f"{name:18} {now['seconds']:9.3f} {before['seconds']:11.3f} {before['seconds'] / now['seconds']:11.1f}"
              f"  {now['problems'] or 'none'}")
    print(f"load: {os.getloadavg()[0]:.2f} (1 min)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
