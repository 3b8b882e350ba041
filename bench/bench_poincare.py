"""Benchmark: Poincaré sections of Chaplygin's ball, the core against heyoka's events written by hand.

Run from the repository root::

    .venv/bin/python bench/bench_poincare.py            # ~40 s on 2 cores
    .venv/bin/python bench/bench_poincare.py --quick    # ~15 s: t_final = 200, fewer repetitions

Compares, in one process, on the same orbits and ``t_final`` and the section γ3 = 0 (increasing),

A. the core, :func:`nonholonomic.analysis.poincare.section` (heyoka Taylor method at machine
   epsilon, non-terminal events, dense output, one Newton step per crossing, the points, the
   integrals' drift, propagated in pieces with the cooperative checks between them), and
H. heyoka written by hand, as its documentation shows a section: the ball's equations and τ written
   directly (``bench_ensemble.ball_equations``), a ``taylor_adaptive`` at the same tolerance with an
   ``nt_event`` on γ3 (increasing) whose callback records the time and the dense-output state
   (``update_d_output``) at each crossing, one ``propagate_until(t_final)``. heyoka's own event
   speed: the ceiling. A and H alternate, so both see the same machine load.

on speed (crossings per second, median wall time; target A/H >= 0.9) and on agreement (the largest
difference between A's and H's crossing times and states). Printed for information: scipy
``solve_ivp(method="DOP853", rtol=atol=1e-12, events=γ3)`` with two right-hand sides: B1, the
independent plain-numpy :func:`tests.reference.ball_rhs` that ``bench_integration.py`` uses (ω by
``np.linalg.solve``, ``np.cross``: ~100 µs a call on numpy 2), and B2, :func:`fast_ball_rhs`, the
same equations on Python floats (~3 µs a call), scipy's best case.

The accuracy of the crossings (times and states) is measured against a reference: heyoka in
extended precision (``fp_type=np.longdouble``, tol = long-double epsilon) with a long-double
non-terminal event, built from the same sympy definition. Target: the core's crossing states
>= 1e4x more accurate than B2's. Also printed: :func:`section_batch` (heyoka batch mode) against a
loop of :func:`section`. A miss is reported, never turned into a non-zero exit status.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from typing import Any, TypeVar  # noqa: E402

import heyoka as hy  # noqa: E402
import numpy as np  # noqa: E402
from bench_ensemble import ball_equations  # noqa: E402  (bench/ is the script's directory)
from scipy.integrate import solve_ivp  # noqa: E402

from nonholonomic import get_system  # noqa: E402
from nonholonomic.analysis.poincare import Section, section, section_batch  # noqa: E402
from nonholonomic.definition import MechanicalSystem  # noqa: E402
from nonholonomic.numerics.kernels import parameter_vector  # noqa: E402
from tests.reference import ball_rhs  # noqa: E402

T = TypeVar("T")

INERTIA = (2.0, 3.0, 4.5)
D = 0.7
GAMMA0 = (0.0, 0.6, 0.8)
#: Orbits (name, M0): bench_integration's orbit, and one spinning mostly about the middle axis
#: (near the unstable permanent rotation, where integration errors grow fastest).
CASES = (("house", (0.5, -0.2, 0.1)), ("middle", (0.1, -2.0, 0.3)))
SURFACE = "gamma3"
SCIPY_TOL = 1e-12
#: The core's crossings per second against heyoka written by hand (H).
SPEED_TARGET = 0.9
ACCURACY_TARGET = 1e4


def timed(fn: Callable[[], T], reps: int) -> tuple[float, T]:
    """Median wall time of ``reps`` calls of ``fn`` and the last call's result."""
    times: list[float] = []
    result: T
    for _ in range(reps):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def fast_ball_rhs(inertia: tuple[float, float, float], d: float) -> Callable[[float, np.ndarray], np.ndarray]:
    """f(t, y) of eq. (2604-1), U = 0, on Python floats: ω = I_Q⁻¹ M by Sherman–Morrison with J = I + D·1."""
    j1, j2, j3 = (1.0 / (i + d) for i in inertia)

    def f(t: float, y: np.ndarray) -> np.ndarray:
        M1, M2, M3, g1, g2, g3 = y.tolist()
        a1, a2, a3 = j1 * g1, j2 * g2, j3 * g3
        s = d * (a1 * M1 + a2 * M2 + a3 * M3) / (1.0 - d * (a1 * g1 + a2 * g2 + a3 * g3))
        w1, w2, w3 = j1 * M1 + a1 * s, j2 * M2 + a2 * s, j3 * M3 + a3 * s
        return np.array([M2 * w3 - M3 * w2, M3 * w1 - M1 * w3, M1 * w2 - M2 * w1,
                         g2 * w3 - g3 * w2, g3 * w1 - g1 * w3, g1 * w2 - g2 * w1])

    return f


class ExtendedReference:
    """The crossings γ3 = 0 (increasing) by heyoka in extended precision (long double).

    Falls back to double precision at tol = eps (with a note) where long double is plain double.
    """

    def __init__(self, system: MechanicalSystem, p: np.ndarray) -> None:
        names = [str(s) for s in system.state_symbols]
        hvars = hy.make_vars(*names)
        mapping: dict[Any, Any] = dict(zip(system.state_symbols, hvars))
        mapping.update({s: hy.par[i] for i, s in enumerate(system.parameter_symbols)})
        eqs = list(zip(hvars, [hy.from_sympy(f, mapping) for f in system.rhs]))
        event = hvars[names.index("gamma3")]
        self.t: list[Any] = []
        self.x: list[np.ndarray] = []

        def on_crossing(ta: Any, t: Any, d_sgn: int) -> None:
            ta.update_d_output(t)
            self.t.append(t)
            self.x.append(ta.d_output.copy())

        start = time.perf_counter()
        self.dtype: type = np.longdouble
        try:
            if np.finfo(np.longdouble).eps >= np.finfo(np.float64).eps:
                raise TypeError("np.longdouble is plain double on this platform")
            self.ta = hy.taylor_adaptive(
                eqs, np.zeros(len(hvars), dtype=np.longdouble), pars=np.asarray(p, dtype=np.longdouble),
                tol=np.finfo(np.longdouble).eps, fp_type=np.longdouble,
                nt_events=[hy.nt_event(event, on_crossing, direction=hy.event_direction.positive,
                                       fp_type=np.longdouble)])
            self.note = f"heyoka long double (eps = {float(np.finfo(np.longdouble).eps):.3g})"
        except (TypeError, ValueError, RuntimeError) as exc:
            self.dtype = np.float64
            self.ta = hy.taylor_adaptive(eqs, [0.0] * len(hvars), pars=list(map(float, p)), tol=np.finfo(float).eps,
                                         nt_events=[hy.nt_event(event, on_crossing,
                                                                direction=hy.event_direction.positive)])
            self.note = f"NOTE: long double unavailable ({exc}); reference is heyoka DOUBLE at tol = eps"
        self.compile_s = time.perf_counter() - start

    def crossings(self, y0: np.ndarray, t_final: float) -> tuple[np.ndarray, np.ndarray]:
        """Crossing times and states, in the reference's precision."""
        self.t.clear()
        self.x.clear()
        self.ta.time = self.dtype(0.0)
        self.ta.state[:] = np.asarray(y0, dtype=self.dtype)
        outcome = self.ta.propagate_until(self.dtype(t_final))[0]
        assert outcome == hy.taylor_outcome.time_limit, outcome
        return np.asarray(self.t, dtype=self.dtype), np.asarray(self.x, dtype=self.dtype)


class HandWritten:
    """H: heyoka written by hand, as its documentation shows a Poincaré section: the ball's equations
    and τ (:func:`bench_ensemble.ball_equations`), an ``nt_event`` on γ3 (increasing) whose callback
    records the time and the dense-output state at the crossing, one ``propagate_until(t_final)``."""

    def __init__(self) -> None:
        equations, pars = ball_equations()
        self.t: list[float] = []
        self.x: list[np.ndarray] = []

        def on_crossing(ta: hy.taylor_adaptive, t: float, d_sgn: int) -> None:
            ta.update_d_output(t)
            self.t.append(t)
            self.x.append(ta.d_output.copy())

        gamma3 = equations[5][0]
        self.ta = hy.taylor_adaptive(equations, [0.0] * 7, pars=pars, tol=float(np.finfo(float).eps),
                                     nt_events=[hy.nt_event(gamma3, on_crossing,
                                                            direction=hy.event_direction.positive)])

    def crossings(self, y0: np.ndarray, t_final: float) -> tuple[np.ndarray, np.ndarray, int]:
        """Crossing times, states (M, γ, τ) and the steps taken."""
        self.t.clear()
        self.x.clear()
        self.ta.time = 0.0
        self.ta.state[:6] = y0
        self.ta.state[6] = 0.0
        outcome, _, _, steps, _, _ = self.ta.propagate_until(t_final)
        assert outcome == hy.taylor_outcome.time_limit, outcome
        return np.array(self.t), np.array(self.x).reshape(-1, 7), steps


def errors(t_ref: np.ndarray, x_ref: np.ndarray, t: np.ndarray, x: np.ndarray) -> tuple[float, float]:
    """Max-abs error of the crossing times and states, in the reference's precision (same crossings)."""
    if len(t) != len(t_ref):
        raise AssertionError(f"{len(t)} crossings against the reference's {len(t_ref)}")
    dt = np.abs(np.asarray(t, dtype=t_ref.dtype) - t_ref)
    dx = np.abs(np.asarray(x, dtype=x_ref.dtype) - x_ref)
    return float(np.max(dt)), float(np.max(dx))


@dataclass
class Engine:
    """One engine's numbers on one orbit."""

    label: str
    seconds: float
    runs: int
    count: int
    steps: int
    dt: float
    dx: float
    residual: float

    @property
    def rate(self) -> float:
        return self.count / self.seconds


@dataclass
class CaseResult:
    """Numbers of one orbit: the core (A), heyoka by hand (H), scipy with the reference RHS (B1) and
    with the fast RHS (B2)."""

    name: str
    m0: tuple[float, float, float]
    first_s: float
    ours: Engine
    hand: Engine
    scipy_ref: Engine
    scipy_fast: Engine
    reference_count: int
    drift: dict[str, float]
    hand_dt: float
    hand_dx: float

    def speed(self, other: Engine) -> float:
        return self.ours.rate / other.rate

    def accuracy(self, other: Engine) -> float:
        return other.dx / self.ours.dx if self.ours.dx > 0 else float("inf")


def alternate(first: Callable[[], T], second: Callable[[], Any], reps: int) -> tuple[float, T, float, Any]:
    """Median wall times of ``reps`` calls of each, alternating (the same machine load), and the last results."""
    times_a: list[float] = []
    times_b: list[float] = []
    for _ in range(reps):
        start = time.perf_counter()
        a = first()
        times_a.append(time.perf_counter() - start)
        start = time.perf_counter()
        b = second()
        times_b.append(time.perf_counter() - start)
    return statistics.median(times_a), a, statistics.median(times_b), b


def run_case(name: str, m0: tuple[float, float, float], t_final: float, system: MechanicalSystem, p: np.ndarray,
             ref: ExtendedReference, hand: HandWritten, heyoka_reps: int, scipy_reps: int) -> CaseResult:
    """Time the engines on one orbit and measure their crossings against the reference."""
    y0 = np.array(m0 + GAMMA0)
    t_ref, x_ref = ref.crossings(y0, t_final)

    # A: the core. The first call compiles the integrator with its event (or loads heyoka's disk cache).
    def core() -> Section:
        return section(system, p, y0, t_final, SURFACE, max_points=100_000)

    start = time.perf_counter()
    core()
    first = time.perf_counter() - start
    hand.crossings(y0, t_final)
    heyoka_s, s, hand_s, (hand_t, hand_x, hand_steps) = alternate(core, lambda: hand.crossings(y0, t_final),
                                                                  heyoka_reps)
    ours_x = np.hstack([s.points["M"], s.points["gamma"]])
    ours = Engine("heyoka (core)", heyoka_s, heyoka_reps, s.count, s.steps, *errors(t_ref, x_ref, s.t, ours_x),
                  residual=float(np.max(np.abs(ours_x[:, 5]))))
    by_hand = Engine("heyoka by hand", hand_s, heyoka_reps, len(hand_t), hand_steps,
                     *errors(t_ref, x_ref, hand_t, hand_x[:, :6]), residual=float(np.max(np.abs(hand_x[:, 5]))))
    if len(hand_t) != s.count:
        raise AssertionError(f"the core found {s.count} crossings, heyoka by hand {len(hand_t)}")
    hand_dt = float(np.max(np.abs(s.t - hand_t)))
    hand_dx = float(np.max(np.abs(np.hstack([ours_x, s.tau[:, None]]) - hand_x)))

    # B: scipy DOP853 with an event function.
    def gamma3(t: float, y: np.ndarray) -> float:
        return y[5]
    gamma3.direction = 1  # type: ignore[attr-defined]

    def scipy_engine(label: str, rhs: Callable[[float, np.ndarray], np.ndarray]) -> Engine:
        def run() -> Any:
            sol = solve_ivp(rhs, (0.0, t_final), y0, method="DOP853", rtol=SCIPY_TOL, atol=SCIPY_TOL, events=gamma3)
            assert sol.success, sol.message
            return sol
        seconds, sol = timed(run, scipy_reps)
        return Engine(label, seconds, scipy_reps, len(sol.t_events[0]), len(sol.t) - 1,
                      *errors(t_ref, x_ref, sol.t_events[0], sol.y_events[0]),
                      residual=float(np.max(np.abs(sol.y_events[0][:, 5]))))

    scipy_ref = scipy_engine("scipy, ball_rhs", ball_rhs(np.asarray(INERTIA), D))
    scipy_fast = scipy_engine("scipy, fast rhs", fast_ball_rhs(INERTIA, D))
    return CaseResult(name, m0, first, ours, by_hand, scipy_ref, scipy_fast, len(t_ref), s.integral_drift_max,
                      hand_dt, hand_dx)


def print_case(r: CaseResult, t_final: float) -> None:
    print(f"\n--- orbit {r.name!r}: M0 = {r.m0}, gamma0 = {GAMMA0}, t_final = {t_final:g}; "
          f"reference: {r.reference_count} crossings ---")
    print(f"heyoka (core) first call {r.first_s * 1e3:.1f} ms (includes compile if not cached)")
    print(f"{'engine':<16} {'median ms':>10} {'runs':>4} {'crossings':>9} {'steps':>6} {'crossings/s':>12} "
          f"{'err t':>9} {'err state':>9} {'|gamma3|':>8}")
    for e in (r.ours, r.hand, r.scipy_ref, r.scipy_fast):
        print(f"{e.label:<16} {e.seconds * 1e3:>10.3f} {e.runs:>4} {e.count:>9} {e.steps:>6} {e.rate:>12,.1f} "
              f"{e.dt:>9.2e} {e.dx:>9.2e} {e.residual:>8.1e}")
    print(f"speed ratio (crossings/s) core / heyoka by hand: {r.speed(r.hand):.3f}; core / scipy: "
          f"{r.speed(r.scipy_fast):.1f}x (fast rhs), {r.speed(r.scipy_ref):.1f}x (ball_rhs)")
    print(f"core vs heyoka by hand: crossing times differ by at most {r.hand_dt:.1e}, states (M, gamma, tau) "
          f"by {r.hand_dx:.1e} (the core's Newton step moves each point onto the surface)")
    print(f"accuracy ratio (crossing states) scipy/heyoka: {r.accuracy(r.scipy_fast):.3g}x (fast rhs), "
          f"{r.accuracy(r.scipy_ref):.3g}x (ball_rhs); crossing times: "
          f"{r.scipy_fast.dt / r.ours.dt if r.ours.dt else float('inf'):.3g}x")
    print("integral drift at the crossings (heyoka): " + ", ".join(f"{k} {v:.1e}" for k, v in r.drift.items()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="t_final = 200, fewer repetitions")
    args = parser.parse_args()
    t_final = 200.0 if args.quick else 1000.0
    # A and H take milliseconds: many alternating runs, so that the medians see the same machine load
    heyoka_reps, scipy_reps = (41, 1) if args.quick else (101, 2)

    system = get_system("chaplygin_ball", "zero")
    p = parameter_vector(system, {"inertia": list(INERTIA), "D": D})
    y_check = np.array([0.3, -0.7, 1.1, 0.6, 0.0, 0.8])
    gap = np.max(np.abs(fast_ball_rhs(INERTIA, D)(0.0, y_check) - ball_rhs(np.asarray(INERTIA), D)(0.0, y_check)))
    assert gap <= 1e-14, f"fast_ball_rhs disagrees with tests.reference.ball_rhs by {gap:.1e}"
    print(f"heyoka {hy.__version__}, numpy {np.__version__}; ball U = 0, I = {INERTIA}, D = {D}; "
          f"section {SURFACE} = 0 increasing, t_final = {t_final:g}")
    ref = ExtendedReference(system, p)
    print(f"reference: {ref.note}, compiled in {ref.compile_s:.1f} s; fast_ball_rhs agrees with ball_rhs to {gap:.0e}")
    hand = HandWritten()

    results = [run_case(name, m0, t_final, system, p, ref, hand, heyoka_reps, scipy_reps) for name, m0 in CASES]
    for r in results:
        print_case(r, t_final)

    # Batch mode: 2 SIMD widths of members near the main orbit, against a loop of section().
    y0 = np.array(CASES[0][1] + GAMMA0)
    n_members = 2 * hy.recommended_simd_size()
    Y = np.tile(y0, (n_members, 1)) * np.linspace(1.0, 1.1, n_members)[:, None]
    Y[:, 3:] /= np.linalg.norm(Y[:, 3:], axis=1)[:, None]
    section_batch(system, p, Y, 10.0, SURFACE)  # compile (not timed)
    reps = 3
    batch_s, batch = timed(lambda: section_batch(system, p, Y, t_final, SURFACE, max_points=100_000), reps)
    loop_s, loop = timed(lambda: [section(system, p, y, t_final, SURFACE, max_points=100_000) for y in Y], reps)
    batch_count = sum(b.count for b in batch if isinstance(b, Section))
    print(f"\n--- batch mode: {n_members} members near orbit {CASES[0][0]!r}, t_final = {t_final:g} ---")
    print(f"section_batch {batch_s * 1e3:.1f} ms ({batch_count / batch_s:,.0f} crossings/s) | loop of section "
          f"{loop_s * 1e3:.1f} ms ({sum(s.count for s in loop) / loop_s:,.0f} crossings/s); "
          f"ratio {loop_s / batch_s:.2f}x")

    print("\n==================== SUMMARY bench_poincare ====================")
    print(f"Chaplygin ball U = 0, section {SURFACE} = 0 (increasing), t = {t_final:g}, tol = eps: the core's section "
          f"(A) vs heyoka's nt_event written by hand (H); scipy DOP853 events (tol = {SCIPY_TOL:g}) for information; "
          f"errors vs {ref.note.split(' (')[0]}")
    print(f"{'orbit':<7} {'core /s':>8} {'hand /s':>8} {'A/H':>6} {'A-H t':>8} {'A-H x':>8} {'sp fast /s':>10} "
          f"{'sp ref /s':>9} {'vs sp':>6} {'err x hy':>9} {'err x sp':>9} {'acc x':>8} {'err t hy':>9} {'err t sp':>9}")
    for r in results:
        print(f"{r.name:<7} {r.ours.rate:>8,.0f} {r.hand.rate:>8,.0f} {r.speed(r.hand):>6.3f} {r.hand_dt:>8.1e} "
              f"{r.hand_dx:>8.1e} {r.scipy_fast.rate:>10,.1f} {r.scipy_ref.rate:>9,.1f} {r.speed(r.scipy_fast):>6.1f} "
              f"{r.ours.dx:>9.2e} {r.scipy_fast.dx:>9.2e} {r.accuracy(r.scipy_fast):>8.3g} {r.ours.dt:>9.2e} "
              f"{r.scipy_fast.dt:>9.2e}")
    for r in results:
        speed, accuracy = r.speed(r.hand), r.accuracy(r.scipy_fast)
        print(f"{r.name:<7} crossings/s core / heyoka by hand {speed:6.3f}  target >= {SPEED_TARGET:g}: "
              f"{'PASS' if speed >= SPEED_TARGET else 'MISS'};  "
              f"crossing-state accuracy ratio vs scipy {accuracy:8.3g}x  "
              f"target >= {ACCURACY_TARGET:g}x: {'PASS' if accuracy >= ACCURACY_TARGET else 'MISS'}")
    print("================================================================")


if __name__ == "__main__":
    main()
