"""Benchmark: the core's Lyapunov spectrum vs the same QR method on scipy with finite differences.

Run from the repository root::

    .venv/bin/python bench/bench_lyapunov.py            # ~20 s on 2 cores
    .venv/bin/python bench/bench_lyapunov.py --quick    # ~5 s

Chaplygin's ball in a linear field (I = (2, 3, 4.5), D = 0.7, a = (0.3, -0.2, 0.5), M(0) =
(0.5, -0.2, 0.1), γ(0) = (0, 0.6, 0.8): a chaotic orbit), the full spectrum (6 exponents), QR
re-orthonormalisation every 1 time unit, in one process:

A. the core, :func:`nonholonomic.analysis.lyapunov.spectrum`: heyoka's variational equations
   (``var_ode_sys``, order 1, from the sympy definition), tolerance machine epsilon;
B. the reference: scipy ``solve_ivp(method="DOP853", rtol=atol=1e-12)`` on n + 1 = 7 trajectories
   (the orbit and the orbit displaced by δ q_j along each tangent vector, δ = 1e-7), stacked in one
   42-dimensional system whose right-hand side is plain numpy (ω = I_Q⁻¹ M by a batched
   ``np.linalg.solve``, independent of the core's sympy chain); every interval the differences
   (x_j − x)/δ are QR-factorised, log|R_ii| accumulated and the displaced trajectories restarted at
   x + δ q'_j. Same initial frame as the core.

Printed: both rates (time units of the full spectrum per second of wall time), their ratio (target
≥ 30×), the largest difference between the two spectra over the same run (the reference's own
accuracy bounds it), and, on a longer core run, how far each estimate still moves over the last
20 % of the run, the sum against the measure's prediction and the observed zeros. A missed target
is reported as ``MISS``; the exit status stays 0.
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

import heyoka as hy  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

from nonholonomic import get_system  # noqa: E402
from nonholonomic.analysis.lyapunov import Spectrum, initial_frame, spectrum  # noqa: E402
from nonholonomic.numerics.kernels import parameter_vector  # noqa: E402

INERTIA = np.array([2.0, 3.0, 4.5])
D = 0.7
A = np.array([0.3, -0.2, 0.5])
Y0 = np.array([0.5, -0.2, 0.1, 0.0, 0.6, 0.8])
INTERVAL = 1.0
SCIPY_TOL = 1e-12
DELTA = 1e-7
RATIO_TARGET = 30.0


def fmt(a: np.ndarray, spec: str = ".2e") -> str:
    return "[" + ", ".join(f"{v:{spec}}" for v in a) + "]"


def ball_rhs_stacked(y: np.ndarray) -> np.ndarray:
    """d/dt of k stacked ball states (flattened (k, 6)): dM/dt = M×ω + γ×a, dγ/dt = γ×ω, I_Q ω = M
    (eq. 2604-1 with U = (a, γ)), ω by one batched linear solve."""
    Y = y.reshape(-1, 6)
    M, g = Y[:, :3], Y[:, 3:]
    IQ = np.diag(INERTIA + D)[None] - D * g[:, :, None] * g[:, None, :]
    w = np.linalg.solve(IQ, M[:, :, None])[:, :, 0]
    return np.concatenate([np.cross(M, w) + np.cross(g, A), np.cross(g, w)], axis=1).ravel()


def reference_spectrum(t_final: float) -> tuple[np.ndarray, float, int]:
    """The QR method with finite-difference tangent vectors on scipy DOP853.

    Returns the exponents (descending), the wall time and the number of accepted steps.
    """
    n = 6
    Q = initial_frame(n)
    x = Y0.copy()
    logs = np.zeros(n)
    steps = 0
    start = time.perf_counter()
    k = int(round(t_final / INTERVAL))
    for i in range(k):
        stacked = np.vstack([x, x + DELTA * Q.T])  # row 0: the orbit; row j + 1: displaced along q_j
        sol = solve_ivp(lambda t, y: ball_rhs_stacked(y), (i * INTERVAL, (i + 1) * INTERVAL), stacked.ravel(),
                        method="DOP853", rtol=SCIPY_TOL, atol=SCIPY_TOL)
        assert sol.success, sol.message
        steps += len(sol.t) - 1
        end = sol.y[:, -1].reshape(n + 1, n)
        x = end[0]
        Q, R = np.linalg.qr(((end[1:] - x) / DELTA).T)
        logs += np.log(np.abs(np.diag(R)))
    return np.sort(logs / t_final)[::-1], time.perf_counter() - start, steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs (~5 s)")
    args = parser.parse_args()
    t_rate, t_ref, t_long, reps = (200.0, 30.0, 1000.0, 1) if args.quick else (1000.0, 300.0, 20_000.0, 5)

    system = get_system("chaplygin_ball", "linear")
    p = parameter_vector(system, {"inertia": INERTIA.tolist(), "D": D, "a": A.tolist()})
    print(f"heyoka {hy.__version__}, numpy {np.__version__}, scipy {scipy.__version__}; ball I = {INERTIA.tolist()}, "
          f"D = {D}, a = {A.tolist()}, y0 = {Y0.tolist()}, interval = {INTERVAL:g}")

    # A: the core. The first call compiles the variational integrator (or finds it in heyoka's cache).
    start = time.perf_counter()
    spectrum(system, p, Y0, 1.0, interval=INTERVAL)
    first = time.perf_counter() - start
    walls = []
    for _ in range(reps):
        s = spectrum(system, p, Y0, t_rate, interval=INTERVAL)
        walls.append(s.wall_time_s)
    core_wall = statistics.median(walls)
    core_rate = t_rate / core_wall
    print(f"\nA. core spectrum: first call {first:.2f} s (compile or cache); t = {t_rate:g} in "
          f"{core_wall * 1e3:.1f} ms (median of {reps}), {s.integrator_steps} heyoka steps, {s.steps} QR steps")
    print(f"   rate {core_rate:,.0f} time units/s ({core_wall / t_rate * 1e3:.3f} ms per time unit)")
    print(f"   method: {s.method}")

    # B: the reference, and the core over the same run for the agreement.
    ref, ref_wall, ref_steps = reference_spectrum(t_ref)
    ref_rate = t_ref / ref_wall
    same: Spectrum = spectrum(system, p, Y0, t_ref, interval=INTERVAL)
    diff = np.abs(same.exponents - ref)
    print(f"\nB. scipy DOP853 (rtol = atol = {SCIPY_TOL:g}), {system.dimension + 1} trajectories, delta = {DELTA:g}: "
          f"t = {t_ref:g} in {ref_wall:.2f} s, {ref_steps} steps")
    print(f"   rate {ref_rate:,.1f} time units/s ({ref_wall / t_ref * 1e3:.1f} ms per time unit)")
    print(f"   spectra at t = {t_ref:g}:")
    print(f"     core      {fmt(same.exponents, '+.9f')}")
    print(f"     reference {fmt(ref, '+.9f')}")
    print(f"     |diff|    {fmt(diff)}")

    # The core on a long run: convergence and structure.
    long = spectrum(system, p, Y0, t_long, interval=INTERVAL)
    print(f"\nC. core, t = {t_long:g} ({long.wall_time_s:.2f} s):")
    print(f"   exponents        {fmt(long.exponents, '+.6f')}")
    print(f"   moved last 20 %  {fmt(long.moved_last_20pct)}")
    print(f"   sum {long.sum:.3e}, quadrature of div f {long.divergence_average:.3e}, measure prediction "
          f"-[ln rho]/T {long.measure_average:.3e} (consistent: {long.measure_consistent})")
    print(f"   zeros expected {long.zero_count} (" + ", ".join(z.reason for z in long.expected_zero if z.counted)
          + f"); observed {fmt(long.zero_observed)}; symmetry residual "
          f"{long.symmetry_residual:.2e}")
    for w in long.warnings:
        print(f"   warning: {w}")

    ratio = core_rate / ref_rate
    print("\n==================== SUMMARY bench_lyapunov ====================")
    print(f"Chaplygin ball, linear field, full spectrum (6), QR every {INTERVAL:g}")
    print(f"rate   core {core_rate:,.0f} time units/s | scipy DOP853 + finite differences {ref_rate:,.1f} time units/s")
    print(f"speed ratio core/reference = {ratio:.0f}x   target >= {RATIO_TARGET:g}x: "
          f"{'PASS' if ratio >= RATIO_TARGET else 'MISS'}")
    print(f"agreement at t = {t_ref:g}: max |lambda_core - lambda_ref| = {diff.max():.2e} "
          f"(largest exponent {same.exponents[0]:.6f} vs {ref[0]:.6f})")
    print(f"t = {t_long:g}: lambda_1 = {long.exponents[0]:.5f}, moved over the last 20 %: "
          f"lambda_1 {long.moved_last_20pct[0]:.2e}, max over all {long.moved_last_20pct.max():.2e}")
    print("=================================================================")


if __name__ == "__main__":
    main()
