"""Benchmark: an ensemble of Chaplygin-ball trajectories, the core's batch mode against its references.

Run from the repository root::

    .venv/bin/python bench/bench_ensemble.py            # ~20 s on 2 cores
    .venv/bin/python bench/bench_ensemble.py --quick    # ~10 s: 200 trajectories, fewer repetitions

Workload: 1000 trajectories of Chaplygin's ball (U = 0, I = (2, 3, 4.5), D = 0.7) to t = 100 with
11 samples, from random states (γ uniform on |γ| = 1, M in a random direction scaled to H = 1;
seed 7). Measured in one process, trajectories per second:

A. the core as an ensemble chunk runs it, :func:`nonholonomic.numerics.integration_batch.integrate_batch`
   (heyoka batch mode, ``hy.recommended_simd_size()`` lanes, the right-hand side generated from the
   sympy definition, tolerance = machine epsilon; samples, τ and the states at
   :data:`~nonholonomic.analysis.ensemble.CHECK_POINTS` equally spaced times, all from one
   ``propagate_grid``) plus every member's integral evidence at those points
   (:func:`nonholonomic.evidence.integrals.integral_evidence_batch`); A-steps, for information: the
   same with the states at every accepted step (a step callback), as a single job keeps them;
B. heyoka written by hand in batch mode, as an expert would (:func:`ball_equations`): ω = J⁻¹M + k J⁻¹γ
   with the Sherman–Morrison factor k = D (J⁻¹γ, M) / (1 − D (γ, J⁻¹γ)) shared, J⁻¹ and det J^(−1/2)
   as parameters, the same τ density, the same lanes, tolerance and grid (``propagate_grid``); no
   step states, no evidence. Its operation count is printed beside the core's (and beside the
   literal ``hy.from_sympy`` transcription's, what the core generated before). B′, for information:
   the same with A-steps' step log (heyoka calls a Python step callback at every step, the GIL taken
   again each time: the cost of the step states to anyone);
C. the core one trajectory at a time (:func:`nonholonomic.numerics.integration.integrate`);
D. scipy ``solve_ivp(DOP853, rtol = atol = 1e-12)`` on a subset, extrapolated per second, with
   scipy's best case for a right-hand side: the same equations on Python floats (~3 µs a call;
   the core's own scipy engine, ``integrate(engine="scipy")`` on the numpy kernels, is ~10× slower).

A, A-steps, B and B′ alternate, ``--reps`` times each; the medians are compared. Targets: A/B >= 0.9,
A/D >= 250, A/C >= 2. Also printed: the largest difference between A's and B's final states
(relative to the state's size) and between A and C. A miss is reported, never turned into a
non-zero exit status.
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

import heyoka as hy  # noqa: E402
import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

from nonholonomic import get_system  # noqa: E402
from nonholonomic.analysis.ensemble import CHECK_POINTS  # noqa: E402
from nonholonomic.evidence.integrals import integral_evidence_batch  # noqa: E402
from nonholonomic.numerics.integration import MACHINE_EPSILON, Trajectory, integrate  # noqa: E402
from nonholonomic.numerics.integration_batch import integrate_batch  # noqa: E402
from nonholonomic.numerics.kernels import parameter_vector  # noqa: E402
from nonholonomic.numerics.taylor import taylor_system  # noqa: E402

INERTIA = np.array([2.0, 3.0, 4.5])
D = 0.7
T_FINAL = 100.0
SAMPLES = 11
ENERGY = 1.0
SEED = 7
TARGET_HAND = 0.9
TARGET_SCIPY = 250.0
TARGET_SINGLE = 2.0


def random_states(count: int, seed: int = SEED) -> np.ndarray:
    """``count`` states (M, γ): γ uniform on the unit sphere, M in a uniform direction scaled to H = 1."""
    rng = np.random.default_rng(seed)
    gamma = rng.normal(size=(count, 3))
    gamma /= np.linalg.norm(gamma, axis=1)[:, None]
    M = rng.normal(size=(count, 3))
    IQ = np.diag(INERTIA + D)[None] - D * gamma[:, :, None] * gamma[:, None, :]
    omega = np.linalg.solve(IQ, M[:, :, None])[:, :, 0]
    H = 0.5 * np.einsum("ij,ij->i", M, omega)
    return np.hstack([M * np.sqrt(ENERGY / H)[:, None], gamma])


def ball_equations() -> tuple[list[tuple[hy.expression, hy.expression]], np.ndarray]:
    """The ball's equations (eq. 2604-1, U = 0) and dτ = det I_Q^(−1/2) dt written directly in heyoka:
    ω = J⁻¹M + k J⁻¹γ with the Sherman–Morrison factor k = D (J⁻¹γ, M) / (1 − D (γ, J⁻¹γ)) shared.

    Returns the equations of (M1, M2, M3, γ1, γ2, γ3, τ) and their parameters
    ``(J⁻¹₁, J⁻¹₂, J⁻¹₃, D, det J^(−1/2))`` (``bench_poincare.py``'s hand-written reference uses them too).
    """
    M = list(hy.make_vars("M1", "M2", "M3"))
    g = list(hy.make_vars("gamma1", "gamma2", "gamma3"))
    tau = hy.make_vars("tau")
    j = [hy.par[0], hy.par[1], hy.par[2]]
    d, c = hy.par[3], hy.par[4]
    jg = [j[i] * g[i] for i in range(3)]  # J⁻¹γ
    den = 1.0 - d * hy.sum([g[i] * jg[i] for i in range(3)])  # 1 − D (γ, J⁻¹γ)
    k = d * hy.sum([jg[i] * M[i] for i in range(3)]) / den
    w = [j[i] * M[i] + k * jg[i] for i in range(3)]  # ω = I_Q⁻¹ M by Sherman–Morrison

    def cross(a: list, b: list) -> list:
        return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]

    rhs = cross(M, w) + cross(g, w) + [c * den**-0.5]
    pars = np.r_[1.0 / (INERTIA + D), D, 1.0 / np.sqrt(np.prod(INERTIA + D))]
    return list(zip(M + g + [tau], rhs)), pars


def hand_written(lanes: int) -> tuple[hy.taylor_adaptive_batch, np.ndarray]:
    """B: :func:`ball_equations` in heyoka's batch mode with ``lanes`` lanes.

    Returns the batch integrator and its parameter block, one column per lane.
    """
    equations, pars = ball_equations()
    ta = hy.taylor_adaptive_batch(equations, np.zeros((7, lanes)), pars=np.zeros((5, lanes)), tol=MACHINE_EPSILON)
    return ta, np.repeat(pars[:, None], lanes, axis=1)


def run_hand(ta: hy.taylor_adaptive_batch, pars: np.ndarray, Y0: np.ndarray, log_steps: bool = False) -> np.ndarray:
    """All members through the hand-written batch integrator (last batch padded); final states.

    ``log_steps``: also keep every step's state and time, as the core does for its evidence, with the
    leanest step callback heyoka allows (B′, for information: what the step states cost anyone).
    """
    lanes = ta.batch_size
    grid = np.repeat(np.linspace(0.0, T_FINAL, SAMPLES)[:, None], lanes, axis=1)
    finals = np.empty((len(Y0), 6))
    callback = None
    if log_steps:
        state, clock = memoryview(ta.state).cast("B"), memoryview(ta.time).cast("B")
        log = bytearray()
        append = log.extend

        def callback(_: hy.taylor_adaptive_batch) -> bool:
            append(state)
            append(clock)
            return True
    for first in range(0, len(Y0), lanes):
        block = Y0[first:first + lanes]
        padded = np.vstack([block, np.repeat(block[-1:], lanes - len(block), axis=0)])
        ta.set_time(0.0)
        ta.state[:6] = padded.T
        ta.state[6] = 0.0
        ta.pars[:] = pars
        ta.propagate_grid(grid, callback=callback)
        finals[first:first + len(block)] = ta.state[:6, :len(block)].T
    return finals


def fast_rhs(t: float, y: np.ndarray) -> list[float]:
    """f(t, y) of eq. (2604-1), U = 0, on Python floats (ω by Sherman–Morrison), and dτ/dt."""
    j1, j2, j3 = (1.0 / (i + D) for i in INERTIA)
    M1, M2, M3, g1, g2, g3, _ = y.tolist()
    a1, a2, a3 = j1 * g1, j2 * g2, j3 * g3
    den = 1.0 - D * (a1 * g1 + a2 * g2 + a3 * g3)
    k = D * (a1 * M1 + a2 * M2 + a3 * M3) / den
    w1, w2, w3 = j1 * M1 + a1 * k, j2 * M2 + a2 * k, j3 * M3 + a3 * k
    return [M2 * w3 - M3 * w2, M3 * w1 - M1 * w3, M1 * w2 - M2 * w1,
            g2 * w3 - g3 * w2, g3 * w1 - g1 * w3, g1 * w2 - g2 * w1, DET_J_INV_SQRT / den**0.5]


DET_J_INV_SQRT = float(1.0 / np.sqrt(np.prod(INERTIA + D)))


def run_scipy(Y0: np.ndarray) -> np.ndarray:
    """D: scipy DOP853 at rtol = atol = 1e-12, one trajectory at a time; final states."""
    grid = np.linspace(0.0, T_FINAL, SAMPLES)
    return np.array([solve_ivp(fast_rhs, (0.0, T_FINAL), np.append(y, 0.0), method="DOP853", rtol=1e-12, atol=1e-12,
                               t_eval=grid).y[:6, -1] for y in Y0])


def run_core(system, p: np.ndarray, Y0: np.ndarray, check_points: int | None = CHECK_POINTS
             ) -> tuple[list[Trajectory], list]:
    """A: the ensemble in batch mode and every member's integral evidence (``check_points=None``:
    A-steps, the evidence at every accepted step)."""
    P = np.repeat(p[None], len(Y0), axis=0)
    trajectories = integrate_batch(system, P, Y0, T_FINAL, SAMPLES, check_points=check_points)
    return trajectories, integral_evidence_batch(system, P, trajectories)


#: CPU seconds of this process (every thread) per timed call, beside the wall times: a ratio of CPU times
#: does not count the time another process held a core, so it moves less on a shared machine.
CPU_TIMES: dict[str, list[float]] = {}


def timed(fn: Callable[[], object], label: str | None = None) -> tuple[float, object]:
    """Wall time of ``fn()`` and its result; with ``label``, its process CPU time kept in :data:`CPU_TIMES`."""
    cpu, start = time.process_time(), time.perf_counter()
    out = fn()
    wall = time.perf_counter() - start
    if label is not None:
        CPU_TIMES.setdefault(label, []).append(time.process_time() - cpu)
    return wall, out


def verdict(value: float, target: float) -> str:
    return "PASS" if value >= target else "MISS"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="200 trajectories, 5 repetitions")
    parser.add_argument("--count", type=int, default=None, help="trajectories (default 1000, quick 200)")
    parser.add_argument("--reps", type=int, default=None, help="repetitions of A and B (default 9, quick 5)")
    args = parser.parse_args()
    count = args.count or (200 if args.quick else 1000)
    reps = args.reps or (5 if args.quick else 9)
    n_scipy = 10 if args.quick else 30

    system = get_system("chaplygin_ball")
    p = parameter_vector(system, {"inertia": INERTIA.tolist(), "D": D})
    Y0 = random_states(count)
    lanes = hy.recommended_simd_size()
    print(f"heyoka {hy.__version__}, numpy {np.__version__}; Chaplygin ball U = 0, I = {INERTIA.tolist()}, D = {D}; "
          f"{count} states on H = {ENERGY:g} (seed {SEED}), t = {T_FINAL:g}, {SAMPLES} samples, "
          f"tol = eps, {lanes} SIMD lanes")

    # Compilation (or heyoka's cache) is not timed.
    ta_hand, hand_pars = hand_written(lanes)
    ts = taylor_system(system)
    literal = hy.taylor_adaptive(
        [(v, hy.from_sympy(f, {**dict(zip(system.state_symbols, ts.variables)),
                               **{s: hy.par[i] for i, s in enumerate(system.parameter_symbols)}}))
         for v, f in zip(ts.variables, list(system.rhs) + [system.reduced_time.density])],
        np.zeros(7), pars=np.zeros(len(p)), tol=MACHINE_EPSILON)
    nv = len(ts.variables)
    ops = {"core (generated)": ts.operations, "hand-written": len(ta_hand.decomposition) - 2 * nv,
           "literal from_sympy (before)": len(literal.decomposition) - 2 * nv}
    run_core(system, p, Y0[:lanes])
    run_hand(ta_hand, hand_pars, Y0[:lanes])
    integrate(system, p, Y0[0], T_FINAL, SAMPLES)

    times_a, times_b, times_log, times_steps = [], [], [], []
    for _ in range(reps):  # A, B, B' and A-steps alternate, so they see the same machine load
        dt, (trajectories, evidence) = timed(lambda: run_core(system, p, Y0), "A")
        times_a.append(dt)
        dt, (_, evidence_steps) = timed(lambda: run_core(system, p, Y0, check_points=None), "A-steps")
        times_steps.append(dt)
        dt, hand_finals = timed(lambda: run_hand(ta_hand, hand_pars, Y0), "B")
        times_b.append(dt)
        times_log.append(timed(lambda: run_hand(ta_hand, hand_pars, Y0, log_steps=True), "B'")[0])
    a_s, b_s, log_s = statistics.median(times_a), statistics.median(times_b), statistics.median(times_log)
    steps_s = statistics.median(times_steps)
    single_s, singles = timed(lambda: [integrate(system, p, y, T_FINAL, SAMPLES) for y in Y0])
    scipy_s, scipy_finals = timed(lambda: run_scipy(Y0[:n_scipy]))

    rate = {"A core batch + evidence": count / a_s, "B hand-written batch": count / b_s,
            "B' hand-written + step log": count / log_s, "A-steps core, every step": count / steps_s,
            "C core one at a time": count / single_s, "D scipy DOP853 1e-12": n_scipy / scipy_s}
    finals = np.array([t.states[-1] for t in trajectories])
    size = np.max(np.abs(finals), axis=1)
    diff_ab = float(np.max(np.max(np.abs(finals - hand_finals), axis=1) / size))
    diff_ac = float(np.max([np.max(np.abs(a.states - c.states)) / np.max(np.abs(c.states))
                            for a, c in zip(trajectories, singles)]))
    drift = max(e.max_rel_drift for member in evidence for e in member)
    drift_steps = max(e.max_rel_drift for member in evidence_steps for e in member)
    failed = sum(not e.passed for member in evidence for e in member)
    steps = [t.steps for t in trajectories]

    print("\n==================== SUMMARY bench_ensemble ====================")
    for name, r in rate.items():
        print(f"{name:<27} {r:10.1f} trajectories/s")
    print("right-hand side operations: " + ", ".join(f"{k} {v}" for k, v in ops.items()))
    print(f"steps per member: mean {np.mean(steps):.1f}, max {max(steps)}; A's evidence at the {SAMPLES} samples "
          f"and {CHECK_POINTS} check points, A-steps' at every step")
    print(f"integral evidence: worst relative drift {drift:.2e} (A-steps: {drift_steps:.2e}) over {count} members, "
          f"{failed} failed checks")
    ratio_b = b_s / a_s
    print(f"A/B (core batch vs hand-written batch) = {ratio_b:.2f}   target >= {TARGET_HAND:g}: "
          f"{verdict(ratio_b, TARGET_HAND)}")
    print(f"for information: A-steps/B = {b_s / steps_s:.2f}, A-steps/B' (the same step log by hand) = "
          f"{log_s / steps_s:.2f}; B'/B (what logging the steps costs heyoka by hand) = {b_s / log_s:.2f}")
    cpu_a, cpu_b, cpu_log = (statistics.median(CPU_TIMES[k]) for k in ("A", "B", "B'"))
    print(f"the same ratios in process CPU time (medians; less moved by the other processes on the machine): "
          f"A/B = {cpu_b / cpu_a:.2f}, B'/B = {cpu_b / cpu_log:.2f}")
    ratio_d = rate["A core batch + evidence"] / rate["D scipy DOP853 1e-12"]
    print(f"A/D (core batch vs scipy DOP853) = {ratio_d:.0f}   target >= {TARGET_SCIPY:g}: "
          f"{verdict(ratio_d, TARGET_SCIPY)}")
    ratio_c = rate["A core batch + evidence"] / rate["C core one at a time"]
    print(f"A/C (batch vs one at a time) = {ratio_c:.2f}   target >= {TARGET_SINGLE:g}: "
          f"{verdict(ratio_c, TARGET_SINGLE)}")
    diff_ad = float(np.max(np.max(np.abs(finals[:n_scipy] - scipy_finals), axis=1) / size[:n_scipy]))
    print(f"final states, max relative difference: A vs B {diff_ab:.1e}; A vs C (all samples) {diff_ac:.1e}; "
          f"A vs D {diff_ad:.1e}")
    print("================================================================")


if __name__ == "__main__":
    main()
