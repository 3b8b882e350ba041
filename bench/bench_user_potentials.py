"""Benchmark: potentials written by the user against the built-in ones (issue 12).

Run from the repository root::

    .venv/bin/python bench/bench_user_potentials.py [--potentials 200] [--runs 15]

1. Speed and agreement: Chaplygin's ball with the built-in linear potential (a, γ) against the same
   U written as ``a1*gamma1 + a2*gamma2 + a3*gamma3``: the same heyoka integration to t = 1000
   (machine-epsilon tolerance), median of ``--runs``; the ratio user / built-in (target ≤ 1.2) and the
   largest difference of the samples (target ≤ 1e-13). The reference is the built-in, in the same run.
2. The first job with a new expression: the seconds to build its definition (sympy), compile its
   integrator (heyoka) and its numpy kernels, against a job whose expression is cached.
3. Memory: the process's resident memory while ``--potentials`` distinct expressions are compiled
   one after the other (the caches keep the last 128 definitions, 64 kernel sets, 32 integrators).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from nonholonomic.integration import MACHINE_EPSILON, heyoka_template, integrate  # noqa: E402
from nonholonomic.kernels import numeric, parameter_vector, state_vector  # noqa: E402
from nonholonomic.systems import get_system, user_potential  # noqa: E402

A = [0.3, -0.2, 0.5]
BASE = {"inertia": [2.0, 3.0, 4.5], "D": 0.7}
STATE = {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}
T_FINAL, SAMPLES = 1000.0, 1001


def rss_mib() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def timed_runs(system, values: dict, runs: int) -> tuple[float, np.ndarray]:
    p = parameter_vector(system, values)
    y0 = state_vector(system, STATE, p)
    integrate(system, p, y0, T_FINAL, SAMPLES)  # compile (or load) first
    times, states = [], None
    for _ in range(runs):
        start = time.perf_counter()
        states = integrate(system, p, y0, T_FINAL, SAMPLES).states
        times.append(time.perf_counter() - start)
    return statistics.median(times), states


def first_job_seconds(text: str) -> tuple[float, float, float]:
    """Seconds to define, compile the integrator, and compile the kernels of a new expression."""
    start = time.perf_counter()
    system = get_system("chaplygin_ball", user_potential("chaplygin_ball", text, ("q",)))
    defined = time.perf_counter()
    heyoka_template(system, MACHINE_EPSILON)
    compiled = time.perf_counter()
    numeric(system).compile_all()
    return defined - start, compiled - defined, time.perf_counter() - compiled


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--potentials", type=int, default=200)
    parser.add_argument("--runs", type=int, default=15)
    args = parser.parse_args()

    builtin = get_system("chaplygin_ball", "linear")
    mine = get_system("chaplygin_ball", user_potential("chaplygin_ball", "a1*gamma1 + a2*gamma2 + a3*gamma3",
                                                       ("a1", "a2", "a3")))
    t_builtin, s_builtin = timed_runs(builtin, {**BASE, "a": A}, args.runs)
    t_mine, s_mine = timed_runs(mine, {**BASE, "a1": A[0], "a2": A[1], "a3": A[2]}, args.runs)
    ratio, diff = t_mine / t_builtin, float(np.max(np.abs(s_mine - s_builtin)))

    first = first_job_seconds("q*gamma3**2 + gamma1*gamma2*gamma3")
    start = time.perf_counter()
    first_job_seconds("q*gamma3**2 + gamma1*gamma2*gamma3")  # cached now
    cached = time.perf_counter() - start

    memory = [(0, rss_mib())]
    compile_times = []
    for i in range(1, args.potentials + 1):
        start = time.perf_counter()
        first_job_seconds(f"q*gamma3**2 + {i}/1000*gamma1*gamma2")
        compile_times.append(time.perf_counter() - start)
        if i % 50 == 0 or i == args.potentials:
            memory.append((i, rss_mib()))
            print(f"  {i} distinct potentials compiled, RSS {memory[-1][1]:.0f} MiB", flush=True)

    print("\n==================== SUMMARY bench_user_potentials ====================")
    print(f"ball to t = {T_FINAL:g}, {SAMPLES} samples, machine epsilon, median of {args.runs}:")
    print(f"  built-in linear {t_builtin * 1e3:.2f} ms, the same U as an expression {t_mine * 1e3:.2f} ms: "
          f"ratio {ratio:.3f} (target <= 1.2: {'PASS' if ratio <= 1.2 else 'MISS'})")
    print(f"  largest difference of the samples {diff:.1e} (target <= 1e-13: {'PASS' if diff <= 1e-13 else 'MISS'})")
    print(f"first job with a new expression: define {first[0]:.2f} s, integrator {first[1]:.2f} s, kernels "
          f"{first[2]:.2f} s (total {sum(first):.2f} s); cached: {cached * 1e3:.2f} ms")
    print(f"{args.potentials} distinct expressions: compile median {statistics.median(compile_times):.2f} s, "
          f"max {max(compile_times):.2f} s; RSS " + ", ".join(f"{n}: {m:.0f} MiB" for n, m in memory))
    growth = memory[-1][1] - memory[len(memory) // 2][1]
    print(f"  RSS growth over the second half: {growth:.0f} MiB (bounded caches: it levels off)")


if __name__ == "__main__":
    main()
