"""Benchmark: a Lagrangian system of the user's own (issue 22, item 5): the first job's derivation and
compile, and the integration against scipy on the same derived equations at equal accuracy.

Run from the repository root::

    .venv/bin/python bench/bench_lagrangian.py [--runs 7]

For Chaplygin's sleigh (t = 20), the nonholonomic particle in a harmonic potential (t = 100), the tilted
Suslov problem in Euler angles (t = 100) and the rolling disk (t = 50):

1. the seconds of parsing and deriving the Lagrange–d'Alembert equations (sympy, multipliers
   eliminated: :func:`nonholonomic.lagrangian.derive`), the elimination in exact rational functions
   against the expression-tree elimination it replaced (ratio), the system's definition with its
   structure search (measure, integrals, Theorem 1), and the first integration (heyoka's compile, or
   its disk cache), in this fresh process;
2. the core's heyoka integration (tolerance = machine epsilon), median of ``--runs``, and its
   final-state error against a heyoka integrator in extended precision built from the same equations;
3. scipy's DOP853 on the same equations (sympy lambdify), its tolerance tightened from 1e-8 until its
   final-state error is no larger than heyoka's (or 1e-14 is reached): the ratio scipy / heyoka in wall
   time at that accuracy, and the energy and constraint drift of both.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
import sympy as sp  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

from bench.bench_integration import ExtendedReference, error_vs  # noqa: E402
from nonholonomic.lagrangian import derive, parse_system  # noqa: E402
from nonholonomic.numerics.integration import integrate  # noqa: E402
from nonholonomic.numerics.kernels import parameter_vector, state_vector  # noqa: E402
from nonholonomic.systems import lagrangian  # noqa: E402
from nonholonomic.systems.lagrangian_classics import CLASSICS  # noqa: E402

CASES: dict[str, dict[str, Any]] = {
    "sleigh": {"system": lagrangian.EXAMPLE_JOB["system"], "state": lagrangian.EXAMPLE_JOB["initial_state"],
               "t_final": 20.0},
    "particle": {"system": {"kind": "lagrangian", "coordinates": ["x", "y", "z"],
                            "L": "(x_dot**2 + y_dot**2 + z_dot**2)/2 - k*(x**2 + y**2)/2",
                            "constraints": ["z_dot - y*x_dot"], "parameters": {"k": 1.0}},
                 "state": {"q": [0.3, -0.2, 0.0], "q_dot": [0.5, 0.4, -0.1]}, "t_final": 100.0},
}
for _name in ("suslov_tilted", "rolling_disk"):
    _job = CLASSICS[_name]["job"]
    CASES[_name] = {"system": _job["system"], "state": _job["initial_state"], "t_final": _job["t_final"]}
#: scipy's DOP853 raises rtol to 100 eps (2.2e-14) below that: the tightest tolerance asked is its floor.
SCIPY_TOLERANCES = (1e-8, 1e-9, 1e-10, 1e-11, 1e-12, 1e-13, 2.3e-14)


def median_time(fn, runs: int) -> tuple[float, Any]:
    times, out = [], None
    for _ in range(runs):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), out


def drift(values: np.ndarray, scale: float) -> float:
    return float(np.max(np.abs(values - values[0])) / scale)


def run_case(name: str, case: dict[str, Any], runs: int) -> None:
    start = time.perf_counter()
    data = parse_system(case["system"])
    equations = derive(data)
    derived_s = time.perf_counter() - start
    from nonholonomic.lagrangian import equations as eq

    fraction_s = median_time(lambda: eq._derive(data), 3)[0]
    fast = eq._derive_in_fractions
    eq._derive_in_fractions = lambda data: None  # the expression-tree elimination it replaced
    try:
        tree_s = median_time(lambda: eq._derive(data), 1)[0]
    finally:
        eq._derive_in_fractions = fast
    start = time.perf_counter()
    system = lagrangian.define(data)
    define_s = time.perf_counter() - start
    structure = system.structure
    p = parameter_vector(system, dict(case["system"]["parameters"]))
    y0 = state_vector(system, case["state"], p)
    t_final = case["t_final"]
    start = time.perf_counter()
    integrate(system, p, y0, t_final, 2)
    first_s = time.perf_counter() - start
    heyoka_s, trajectory = median_time(lambda: integrate(system, p, y0, t_final, 2), runs)
    reference, roundtrip = ExtendedReference(system, p).final_state(y0, t_final)
    heyoka_error = error_vs(reference, trajectory.states[-1])

    values = dict(zip(equations.parameters, equations.values))
    state = list(equations.state)
    rhs = sp.lambdify(state, [sp.sympify(e).xreplace(values) for e in equations.rhs], "numpy")
    energy = sp.lambdify(state, equations.energy.xreplace(values), "numpy")
    constraint = sp.lambdify(state, [c.xreplace(values) for c in equations.constraints], "numpy")

    def scipy_run(tol: float):
        sol = solve_ivp(lambda t, y: rhs(*y), (0.0, t_final), y0, method="DOP853", rtol=tol, atol=tol)
        assert sol.success, sol.message
        return sol

    chosen, scipy_error = SCIPY_TOLERANCES[-1], float("inf")
    for tol in SCIPY_TOLERANCES:
        scipy_error = error_vs(reference, scipy_run(tol).y[:, -1])
        if scipy_error <= heyoka_error:
            chosen = tol
            break
    scipy_s, sol = median_time(lambda: scipy_run(chosen), max(3, runs // 2))
    e_scipy = np.array([energy(*y) for y in sol.y.T])
    e_heyoka = np.array([energy(*y) for y in np.vstack([y0, trajectory.step_states])])
    c_scipy = max(float(np.max(np.abs(constraint(*y)))) for y in sol.y.T)
    c_heyoka = max(float(np.max(np.abs(constraint(*y)))) for y in trajectory.step_states)
    scale = max(abs(float(e_heyoka[0])), 1e-300)
    print(f"\n{name}: {len(data.q)} coordinates, {len(data.constraints)} constraint(s), t = {t_final:g}")
    print(f"  parse + derive {derived_s:.2f} s; definition with the structure search {define_s:.2f} s (measure "
          f"{structure['measure']['verdict']} in {structure['measure']['seconds']:.2f} s, integrals "
          f"{len(structure['integrals']['found'])} in {structure['integrals']['seconds']:.2f} s, Theorem 1 "
          f"{structure['hamiltonization']['verdict']}); first integration {first_s:.2f} s (compile or heyoka's disk "
          "cache)")
    print(f"  elimination: exact rational functions {fraction_s:.3f} s, expression trees (cancel) {tree_s:.2f} s: "
          f"ratio {tree_s / fraction_s:.0f}x")
    print(f"  heyoka: {heyoka_s * 1e3:.2f} ms ({trajectory.steps} steps), final-state error {heyoka_error:.2e} "
          f"(extended-precision reference; its own round trip t -> 0 {roundtrip:.1e}, large where the backward "
          "flow expands)")
    print(f"  scipy DOP853 at rtol = atol = {chosen:g}: {scipy_s * 1e3:.2f} ms ({len(sol.t) - 1} steps), error "
          f"{scipy_error:.2e}{'' if scipy_error <= heyoka_error else ' (NOT reached: tightest tolerance)'}")
    reached = scipy_error <= heyoka_error
    lower_bound = "(scipy at its tightest tolerance, still less accurate: a lower bound)"
    print(f"  ratio scipy / heyoka {'at equal accuracy' if reached else lower_bound}: "
          f"{scipy_s / heyoka_s:.1f}x")
    print(f"  energy drift (relative): heyoka {drift(e_heyoka, scale):.1e}, scipy {drift(e_scipy, scale):.1e}; "
          f"max |A q_dot|: heyoka {c_heyoka:.1e}, scipy {c_scipy:.1e}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7)
    args = parser.parse_args()
    for name, case in CASES.items():
        run_case(name, case, args.runs)


if __name__ == "__main__":
    main()
