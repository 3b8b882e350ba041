"""The long run of the API fuzzer (tests/api/test_fuzz.py): new random examples every run.

    .venv/bin/python bench/fuzz_api.py --examples 2000     # ~15 min on 2 cores

Prints, for each request kind, the examples run and the time; a 500, a non-finite number in an answer
or a problem without fields fails the run (exit status 1) with hypothesis's falsifying example. The
reference it is compared with is the suite's short run (60 seeded examples per kind).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", type=int, default=2000, help="examples per request kind")
    args = parser.parse_args()
    env = {**os.environ, "NONHOLONOMIC_FUZZ_EXAMPLES": str(args.examples), "NONHOLONOMIC_FUZZ_RANDOM": "1"}
    start = time.perf_counter()
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--durations=0",
                          "tests/api/test_fuzz.py"], cwd=ROOT, env=env)
    elapsed = time.perf_counter() - start
    kinds = 3
    print("SUMMARY")
    print(f"  examples: {args.examples} per kind x {kinds} kinds (jobs, brackets, hamiltonize) in {elapsed:.0f} s; "
          f"{args.examples / 60:.0f}x the suite's seeded run")
    result = "OK: no 500, no non-finite number, every problem names its fields" if run.returncode == 0 else "FAIL"
    print(f"  result: {result}")
    return run.returncode


if __name__ == "__main__":
    raise SystemExit(main())
