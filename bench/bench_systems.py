"""Every system's catalog example: the core (heyoka) against scipy DOP853 at equal accuracy.

For each kind, the example of its module (``EXAMPLE``) is integrated to ``T = 100``:

- the reference is heyoka in extended precision built from the same sympy definition;
- scipy ``solve_ivp(DOP853, rtol = atol = 1e-12)`` with the core's numpy right-hand side gives a
  final-state error ``E_scipy`` and an integral drift;
- heyoka at machine epsilon (the service's default) gives its time, error and drift;
- "equal accuracy": the loosest heyoka tolerance in a ladder whose final-state error is still
  ``<= E_scipy``; the speed ratio scipy / heyoka is printed at that tolerance and at eps.

T = 100 keeps the comparison about the integrators: at longer times the chaotic cases amplify
round-off and both engines' errors are meaningless.

Run: ``.venv/bin/python bench/bench_systems.py`` (about a minute; compilation is not timed).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "bench")]

import numpy as np  # noqa: E402
from bench_integration import ExtendedReference, error_vs, timed  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

from nonholonomic.numerics.integration import MACHINE_EPSILON, integrate  # noqa: E402
from nonholonomic.numerics.kernels import numeric, parameter_vector, state_vector  # noqa: E402
from nonholonomic.systems import SYSTEMS  # noqa: E402
from schemas.jobs import JobRequest  # noqa: E402

T = 100.0
SCIPY_TOL = 1e-12
LADDER = (1e-15, 1e-14, 1e-13, 1e-12, 1e-11, 1e-10, 1e-9)


def max_relative_drift(kernels, states: np.ndarray, p: np.ndarray) -> float:
    """Largest relative drift over the integrals, as the core defines it."""
    values = kernels.integrals(states, p)
    scale = np.max(np.abs(kernels.integral_scales(states, p)), axis=0)
    reference = np.maximum(np.abs(values[0]), scale)
    reference = np.where(reference > 0, reference, 1.0)
    return float(np.max(np.max(np.abs(values - values[0]), axis=0) / reference))


def bench_kind(kind: str) -> dict[str, object]:
    request = JobRequest.model_validate(SYSTEMS[kind].EXAMPLE)
    system = request.system.definition()
    p = parameter_vector(system, request.system.parameter_values())
    y0 = state_vector(system, request.initial_state, p)
    kernels = numeric(system)
    reference, roundtrip = ExtendedReference(system, p).final_state(y0, T)

    def scipy_run():
        return solve_ivp(lambda t, y: kernels.rhs_single(y, p), (0.0, T), y0, method="DOP853",
                         rtol=SCIPY_TOL, atol=SCIPY_TOL)

    t_scipy, sol = timed(scipy_run, 3)
    e_scipy = error_vs(reference, sol.y[:, -1])
    d_scipy = max_relative_drift(kernels, sol.y.T, p)

    def heyoka_run(tol: float):
        return integrate(system, p, y0, T, 2, tolerance=tol)

    heyoka_run(MACHINE_EPSILON)  # compile
    t_eps, traj = timed(lambda: heyoka_run(MACHINE_EPSILON), 15)
    e_eps = error_vs(reference, traj.states[-1])
    d_eps = max_relative_drift(kernels, np.vstack([traj.states, traj.step_states]), p)

    equal_tol, t_equal, e_equal = MACHINE_EPSILON, t_eps, e_eps
    for tol in LADDER:
        heyoka_run(tol)  # compile
        t_tol, traj_tol = timed(lambda tol=tol: heyoka_run(tol), 15)
        err = error_vs(reference, traj_tol.states[-1])
        if err <= e_scipy:
            equal_tol, t_equal, e_equal = tol, t_tol, err
    return {"kind": kind, "potential": system.potential, "ref_roundtrip": roundtrip,
            "scipy_ms": 1e3 * t_scipy, "scipy_err": e_scipy, "scipy_drift": d_scipy, "scipy_steps": len(sol.t) - 1,
            "eps_ms": 1e3 * t_eps, "eps_err": e_eps, "eps_drift": d_eps, "eps_steps": traj.steps,
            "equal_tol": equal_tol, "equal_ms": 1e3 * t_equal, "equal_err": e_equal}


def main() -> None:
    rows = [bench_kind(kind) for kind in SYSTEMS]
    print(f"\n==================== SUMMARY bench_systems (T = {T:g}, scipy DOP853 rtol = atol = {SCIPY_TOL:g}) "
          "====================")
    print(f"{'kind':<24}{'pot':<7}{'scipy ms':>9}{'err':>9}{'drift':>9} | {'hy eps ms':>9}{'err':>9}{'drift':>9}"
          f"{'speed x':>9} | {'equal tol':>9}{'ms':>8}{'err':>9}{'speed x':>9}")
    for r in rows:
        print(f"{r['kind']:<24}{r['potential']:<7}{r['scipy_ms']:>9.1f}{r['scipy_err']:>9.1e}"
              f"{r['scipy_drift']:>9.1e} | "
              f"{r['eps_ms']:>9.2f}{r['eps_err']:>9.1e}{r['eps_drift']:>9.1e}{r['scipy_ms'] / r['eps_ms']:>9.0f} | "
              f"{r['equal_tol']:>9.0e}{r['equal_ms']:>8.2f}{r['equal_err']:>9.1e}{r['scipy_ms'] / r['equal_ms']:>9.0f}")
    print("err: max-abs final-state error vs heyoka long double; drift: max relative integral drift; "
          "speed x: scipy time / heyoka time")


if __name__ == "__main__":
    main()
