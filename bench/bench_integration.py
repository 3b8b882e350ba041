"""Benchmark: the core heyoka integrator vs scipy DOP853 on Chaplygin's ball.

Run from the repository root::

    .venv/bin/python bench/bench_integration.py

Compares, in one process,

A. the core, :func:`nonholonomic.numerics.integration.integrate` (heyoka Taylor method generated from the
   symbolic definition, default tolerance = machine epsilon), and
B. scipy ``solve_ivp(method="DOP853", rtol=atol=1e-12)`` on the independent plain-numpy right-hand
   side :func:`tests.reference.ball_rhs`,

on speed (median wall time), first-integral drift over the accepted steps, and the error of the
final state against a tighter reference: a heyoka integrator in extended precision
(``fp_type=np.longdouble``, tol = longdouble epsilon) built from the same sympy definition.

Targets: speed ratio scipy/heyoka >= 100x, drift ratio scipy/heyoka >= 1000x. A miss is reported,
never turned into a non-zero exit status.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import statistics  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from typing import Any, TypeVar  # noqa: E402

import heyoka as hy  # noqa: E402
import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

from nonholonomic import get_system  # noqa: E402
from nonholonomic.definition import MechanicalSystem  # noqa: E402
from nonholonomic.evidence.integrals import integral_evidence  # noqa: E402
from nonholonomic.numerics.integration import MACHINE_EPSILON, Trajectory, integrate  # noqa: E402
from nonholonomic.numerics.kernels import parameter_vector  # noqa: E402
from tests.reference import ball_rhs  # noqa: E402

T = TypeVar("T")

INERTIA = (2.0, 3.0, 4.5)
D = 0.7
M0 = (0.5, -0.2, 0.1)
GAMMA0 = (0.0, 0.6, 0.8)
T_FINAL = 1000.0
#: Sample grid of the core run (the drift is evaluated on these samples and every accepted step).
SAMPLES = 1001
SCIPY_TOL = 1e-12
HEYOKA_REPS = 25
SCIPY_REPS = 3
SPEED_TARGET = 100.0
DRIFT_TARGET = 1000.0


@dataclass(frozen=True)
class Case:
    """One system/potential to benchmark.

    ``t_compare`` is the time at which final states are compared with the extended-precision
    reference (None: no comparison). ``full`` prints the detailed per-integral table.
    """

    name: str
    potential: str
    extra: dict[str, Any] = field(default_factory=dict)
    a: tuple[float, float, float] | None = None
    k: float = 0.0
    t_compare: float | None = T_FINAL
    full: bool = False


CASES = (
    Case("zero", "zero", full=True),
    # Chaotic: final states diverge at t = 1000, so compare at t = 100 only.
    Case("linear", "linear", {"a": [0.3, -0.2, 0.5]}, a=(0.3, -0.2, 0.5), t_compare=100.0),
    Case("brun", "brun", {"k": 0.4}, k=0.4),
)


@dataclass
class CaseResult:
    """Numbers of one case."""

    name: str
    heyoka_first_s: float
    heyoka_s: float
    scipy_s: float
    heyoka_steps: int
    scipy_steps: int
    heyoka_drift: float
    heyoka_drift_numpy: float
    scipy_drift: float
    heyoka_drift_by_integral: dict[str, float]
    scipy_drift_by_integral: dict[str, float]
    t_compare: float | None = None
    heyoka_error: float | None = None
    scipy_error: float | None = None
    reference_roundtrip: float | None = None
    reference_note: str = ""

    @property
    def speed_ratio(self) -> float:
        return self.scipy_s / self.heyoka_s

    @property
    def drift_ratio(self) -> float:
        return self.scipy_drift / self.heyoka_drift if self.heyoka_drift > 0 else float("inf")


def timed(fn: Callable[[], T], reps: int) -> tuple[float, T]:
    """Median wall time of ``reps`` calls of ``fn`` and the last call's result."""
    times: list[float] = []
    result: T
    for _ in range(reps):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def numpy_integrals(y: np.ndarray, case: Case) -> tuple[list[str], np.ndarray, np.ndarray]:
    """The ball's first integrals with plain numpy (independent of the core's kernels).

    Parameters
    ----------
    y : states, shape ``(n, 6)`` = (M, gamma).
    case : gives the potential.

    Returns
    -------
    names, values of shape ``(n, k)``, natural scales at ``y[0]`` of shape ``(k,)``
        H = (M, omega)/2 + U (scale T + |U|), (gamma, gamma) (scale 1), (M, gamma) (scale |M||gamma|)
        and, for U = 0, F = (M, M).
    """
    inertia = np.asarray(INERTIA)
    M, g = y[:, :3], y[:, 3:]
    # omega = I_Q^-1 M with I_Q = diag(I + D) - D gamma gamma^T, by a batched linear solve.
    IQ = np.diag(inertia + D)[None, :, :] - D * g[:, :, None] * g[:, None, :]
    omega = np.linalg.solve(IQ, M[:, :, None])[:, :, 0]
    kinetic = 0.5 * np.einsum("ij,ij->i", M, omega)
    a = np.zeros(3) if case.a is None else np.asarray(case.a)
    U = g @ a + 0.5 * case.k * np.einsum("ij,j,ij->i", g, inertia, g)
    gg = np.einsum("ij,ij->i", g, g)
    MM = np.einsum("ij,ij->i", M, M)
    names = ["energy", "geometric", "area"]
    cols = [kinetic + U, gg, np.einsum("ij,ij->i", M, g)]
    scales = [kinetic[0] + abs(U[0]), 1.0, np.sqrt(MM[0] * gg[0])]
    if case.potential == "zero":
        names.append("F")
        cols.append(MM)
        scales.append(MM[0])
    return names, np.stack(cols, axis=1), np.asarray(scales)


def relative_drift(values: np.ndarray, scales: np.ndarray) -> np.ndarray:
    """``max_t |I(t) - I(0)| / max(|I(0)|, scale)`` per integral, as the core defines it."""
    reference = np.maximum(np.abs(values[0]), np.abs(scales))
    reference = np.where(reference > 0, reference, 1.0)
    return np.max(np.abs(values - values[0]), axis=0) / reference


class ExtendedReference:
    """A heyoka integrator of the same sympy definition in extended precision (long double).

    Falls back to double precision at tol = machine epsilon (with a note) if heyoka or the
    platform has no real extended type.
    """

    def __init__(self, system: MechanicalSystem, p: np.ndarray) -> None:
        names = [str(s) for s in system.state_symbols]
        hvars = hy.make_vars(*names)
        mapping: dict[Any, Any] = dict(zip(system.state_symbols, hvars))
        mapping.update({s: hy.par[i] for i, s in enumerate(system.parameter_symbols)})
        sys_ = list(zip(hvars, [hy.from_sympy(f, mapping) for f in system.rhs]))
        dim = len(hvars)
        start = time.perf_counter()
        self.dtype: type = np.longdouble
        self.note = ""
        try:
            if np.finfo(np.longdouble).eps >= np.finfo(np.float64).eps:
                raise TypeError("np.longdouble is plain double on this platform")
            self.ta = hy.taylor_adaptive(sys_, np.zeros(dim, dtype=np.longdouble),
                                         pars=np.asarray(p, dtype=np.longdouble),
                                         tol=np.finfo(np.longdouble).eps, fp_type=np.longdouble)
            self.note = f"heyoka long double (eps = {float(np.finfo(np.longdouble).eps):.3g})"
        except (TypeError, ValueError, RuntimeError) as exc:
            self.dtype = np.float64
            self.ta = hy.taylor_adaptive(sys_, [0.0] * dim, pars=list(map(float, p)), tol=MACHINE_EPSILON)
            self.note = f"NOTE: long double unavailable ({exc}); reference is heyoka DOUBLE at tol = eps"
        self.compile_s = time.perf_counter() - start

    def final_state(self, y0: np.ndarray, t: float) -> tuple[np.ndarray, float]:
        """State at ``t`` from ``y0`` and the round-trip error ``|y(t -> 0) - y0|_inf`` (its own accuracy)."""
        self.ta.time = self.dtype(0.0)
        self.ta.state[:] = np.asarray(y0, dtype=self.dtype)
        outcome = self.ta.propagate_until(self.dtype(t))[0]
        assert outcome == hy.taylor_outcome.time_limit, outcome
        final = self.ta.state.copy()
        self.ta.propagate_until(self.dtype(0.0))
        roundtrip = float(np.max(np.abs(self.ta.state - np.asarray(y0, dtype=self.dtype))))
        return final, roundtrip


def error_vs(reference: np.ndarray, state: np.ndarray) -> float:
    """Max-abs difference, computed in the reference's precision."""
    return float(np.max(np.abs(np.asarray(state, dtype=reference.dtype) - reference)))


def run_case(case: Case) -> CaseResult:
    """Time both engines on ``case``, measure their drift and final-state error."""
    system = get_system("chaplygin_ball", case.potential)
    p = parameter_vector(system, {"inertia": list(INERTIA), "D": D, **case.extra})
    y0 = np.array(M0 + GAMMA0)
    rhs = ball_rhs(np.asarray(INERTIA), D, None if case.a is None else np.asarray(case.a), case.k)

    # A: the core. The first call compiles the Taylor integrator (or finds it cached).
    def core(t: float = T_FINAL) -> Trajectory:
        return integrate(system, p, y0, t, SAMPLES)

    start = time.perf_counter()
    core()
    first = time.perf_counter() - start
    heyoka_s, traj = timed(core, HEYOKA_REPS)

    # B: scipy DOP853 with the plain-numpy RHS (sol.y holds every accepted step).
    def scipy_run(t: float = T_FINAL) -> Any:
        sol = solve_ivp(rhs, (0.0, t), y0, method="DOP853", rtol=SCIPY_TOL, atol=SCIPY_TOL)
        assert sol.success, sol.message
        return sol

    scipy_s, sol = timed(scipy_run, SCIPY_REPS)

    # Drift: the core's own evidence for heyoka, plain numpy for scipy (and for heyoka, as a cross-check).
    evidence = integral_evidence(system, p, traj)
    names, values, scales = numpy_integrals(sol.y.T, case)
    scipy_drift = relative_drift(values, scales)
    _, hvalues, hscales = numpy_integrals(np.vstack([y0, traj.step_states]), case)
    heyoka_drift_numpy = relative_drift(hvalues, hscales)

    result = CaseResult(
        name=case.name, heyoka_first_s=first, heyoka_s=heyoka_s, scipy_s=scipy_s,
        heyoka_steps=traj.steps, scipy_steps=len(sol.t) - 1,
        heyoka_drift=max(e.max_rel_drift for e in evidence),
        heyoka_drift_numpy=float(np.max(heyoka_drift_numpy)),
        scipy_drift=float(np.max(scipy_drift)),
        heyoka_drift_by_integral={e.name: e.max_rel_drift for e in evidence},
        scipy_drift_by_integral=dict(zip(names, map(float, scipy_drift))),
    )

    # Final state against the extended-precision reference.
    if case.t_compare is not None:
        ref = ExtendedReference(system, p)
        final_ref, roundtrip = ref.final_state(y0, case.t_compare)
        h_final = traj.states[-1] if case.t_compare == T_FINAL else core(case.t_compare).states[-1]
        s_final = sol.y[:, -1] if case.t_compare == T_FINAL else scipy_run(case.t_compare).y[:, -1]
        result.t_compare = case.t_compare
        result.heyoka_error = error_vs(final_ref, h_final)
        result.scipy_error = error_vs(final_ref, s_final)
        result.reference_roundtrip = roundtrip
        result.reference_note = f"{ref.note}, compiled in {ref.compile_s:.1f} s"
    return result


def verdict(value: float, target: float) -> str:
    return "PASS" if value >= target else "MISS"


def print_case(r: CaseResult, full: bool) -> None:
    """Details of one case."""
    print(f"\n--- case {r.name!r}: t_final = {T_FINAL:g}, samples = {SAMPLES} ---")
    print(f"heyoka (core)  first call {r.heyoka_first_s * 1e3:8.2f} ms (includes compile if not cached)")
    print(f"heyoka (core)  median {r.heyoka_s * 1e3:10.3f} ms over {HEYOKA_REPS} runs, {r.heyoka_steps} steps")
    print(f"scipy DOP853   median {r.scipy_s * 1e3:10.3f} ms over {SCIPY_REPS} runs, {r.scipy_steps} steps "
          f"(rtol = atol = {SCIPY_TOL:g})")
    print(f"speed ratio scipy/heyoka = {r.speed_ratio:.1f}x")
    if full:
        print(f"{'integral':<10} {'heyoka (core evidence)':>24} {'scipy (numpy)':>16}")
        for name, h in r.heyoka_drift_by_integral.items():
            print(f"{name:<10} {h:>24.3e} {r.scipy_drift_by_integral.get(name, float('nan')):>16.3e}")
    print(f"max rel drift: heyoka {r.heyoka_drift:.3e} (numpy recheck on its steps {r.heyoka_drift_numpy:.3e}), "
          f"scipy {r.scipy_drift:.3e}; ratio {r.drift_ratio:.1f}x")
    if r.t_compare is not None:
        print(f"final state at t = {r.t_compare:g} vs reference [{r.reference_note}]:")
        print(f"  heyoka max-abs error {r.heyoka_error:.3e}, scipy {r.scipy_error:.3e}; "
              f"reference round-trip error {r.reference_roundtrip:.3e}")


def main() -> None:
    print(f"heyoka {hy.__version__}, numpy {np.__version__}; ball I = {INERTIA}, D = {D}, "
          f"M0 = {M0}, gamma0 = {GAMMA0}")
    results = []
    for case in CASES:
        r = run_case(case)
        print_case(r, case.full)
        results.append(r)

    main_r = results[0]
    print("\n==================== SUMMARY bench_integration ====================")
    print(f"Chaplygin ball, U = 0, t = {T_FINAL:g}: heyoka core (tol = eps) vs scipy DOP853 (tol = {SCIPY_TOL:g})")
    print(f"time   heyoka {main_r.heyoka_s * 1e3:.3f} ms ({main_r.heyoka_steps} steps) | "
          f"scipy {main_r.scipy_s * 1e3:.1f} ms ({main_r.scipy_steps} steps)")
    print(f"speed ratio scipy/heyoka = {main_r.speed_ratio:.1f}x   target >= {SPEED_TARGET:g}x: "
          f"{verdict(main_r.speed_ratio, SPEED_TARGET)}")
    print(f"drift  heyoka {main_r.heyoka_drift:.3e} | scipy {main_r.scipy_drift:.3e}")
    print(f"drift ratio scipy/heyoka = {main_r.drift_ratio:.1f}x   target >= {DRIFT_TARGET:g}x: "
          f"{verdict(main_r.drift_ratio, DRIFT_TARGET)}")
    print(f"final-state max-abs error at t = {main_r.t_compare:g} vs extended-precision heyoka: "
          f"heyoka {main_r.heyoka_error:.3e} | scipy {main_r.scipy_error:.3e} "
          f"(reference round-trip {main_r.reference_roundtrip:.1e})")
    print(f"{'potential':<9} {'heyoka ms':>10} {'scipy ms':>9} {'speed x':>8} {'drift hy':>10} {'drift sp':>10} "
          f"{'drift x':>9} {'t_cmp':>6} {'err hy':>9} {'err sp':>9}")
    for r in results:
        err = (f"{r.t_compare:>6g} {r.heyoka_error:>9.2e} {r.scipy_error:>9.2e}" if r.t_compare is not None
               else f"{'-':>6} {'-':>9} {'-':>9}")
        print(f"{r.name:<9} {r.heyoka_s * 1e3:>10.3f} {r.scipy_s * 1e3:>9.1f} {r.speed_ratio:>8.1f} "
              f"{r.heyoka_drift:>10.2e} {r.scipy_drift:>10.2e} {r.drift_ratio:>9.1f} {err}")
    print("===================================================================")


if __name__ == "__main__":
    main()
