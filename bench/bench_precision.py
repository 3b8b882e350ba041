"""Benchmark: what mpmath's per-thread precision (nonholonomic/numerics/precision.py) costs.

Run from the repository root::

    .venv/bin/python bench/bench_precision.py

1. ``mpf`` arithmetic (200,000 multiply-adds) on ``mpmath.mp``, whose precision is now per thread, against a
   private ``mpmath.MPContext()`` (mpmath's own context, one plain precision): the cost of every operation's
   look-up of the thread's precision.
2. Whole cold jobs (Veselova's system and the tilted Suslov problem from their Lagrangians: the symbolic searches,
   the 50-digit identity tests, the integration and the checks), each in a fresh process with an empty cache,
   with the per-thread precision and with mpmath's global one restored (``--global`` in the child): the cost
   where it matters.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

JOBS = ("veselova", "suslov_tilted")


def _arithmetic(ctx: object, n: int = 200_000) -> float:
    mpf = ctx.mpf  # type: ignore[attr-defined]
    x, a, b = mpf(1) / 3, mpf("1.0000001"), mpf("1e-9")
    tic = time.perf_counter()
    for _ in range(n):
        x = x * a + b
    return time.perf_counter() - tic


def _global_again() -> None:
    """mpmath's one global precision back (what :func:`install` replaced), for the comparison only."""
    import mpmath

    ctx = mpmath.mp
    prec, rounding, dps = ctx.prec, ctx._prec_rounding[1], ctx.dps
    shared = [prec, rounding]
    ctx.__class__ = type(ctx).__mro__[1]
    ctx.__dict__.update({"_prec": prec, "_dps": dps, "_prec_rounding": shared})
    for t in (ctx.mpf, ctx.mpc, ctx.constant):
        t._ctxdata[2] = shared


def _child(mode: str) -> None:
    import json

    import nonholonomic.numerics.precision as precision

    if mode == "--global":
        _global_again()
    assert precision.installed() == (mode != "--global")
    from tests.integration.test_same_answer import JOBS as BODIES
    from workers.jobs import run_job

    out = {}
    for name in JOBS:
        tic = time.perf_counter()
        run_job(BODIES[name])
        out[name] = time.perf_counter() - tic
    print(json.dumps(out))


def main() -> None:
    import json

    import mpmath

    import nonholonomic.numerics.precision  # noqa: F401

    print(f"load average {os.getloadavg()[0]:.2f}")
    private = mpmath.MPContext()
    shared = min(_arithmetic(mpmath.mp) for _ in range(3))
    own = min(_arithmetic(private) for _ in range(3))
    print(f"mpf arithmetic, 200,000 multiply-adds: per-thread mp {shared:.3f} s, mpmath's own context {own:.3f} s, "
          f"ratio {shared / own:.2f}")
    totals = {"per-thread": 0.0, "global": 0.0}
    for run in range(2):
        for mode in ("--per-thread", "--global"):
            with tempfile.TemporaryDirectory() as cache:
                env = {**os.environ, "NONHOLONOMIC_CACHE_DIR": cache}
                out = subprocess.run([sys.executable, __file__, mode], capture_output=True, text=True, env=env,
                                     check=True, cwd=ROOT)
            times = json.loads(out.stdout.strip().splitlines()[-1])
            totals[mode[2:]] += sum(times.values())
            print(f"run {run + 1} {mode[2:]:>10}: " + ", ".join(f"{k} {v:.2f} s" for k, v in times.items()))
    ratio = totals["per-thread"] / totals["global"]
    print("SUMMARY")
    print(f"  arithmetic ratio (per-thread / mpmath's own): {shared / own:.2f}")
    print(f"  cold jobs, 2 runs each: per-thread {totals['per-thread']:.1f} s, global {totals['global']:.1f} s, "
          f"ratio {ratio:.2f} (load {os.getloadavg()[0]:.2f})")


if __name__ == "__main__":
    if len(sys.argv) > 1:
        _child(sys.argv[1])
    else:
        main()
