"""Branches of periodic orbits: the core's pseudo-arclength corrector against heyoka written by hand + scipy's
least_squares on the same orbits, measured in the same run; and a family of 200 points timed.

Chaplygin's ball in a linear field (I = (2, 3, 4.5), D = 0.7, a = (0.3, -0.2, a3)), the island's centre on H = 2,
(M, γ) = 0, section γ3 = 0, continued in a3 from 0.5 to 0.95 (through its period doubling at 0.8558).

A. **The core**: :func:`nonholonomic.analysis.periodic_orbit.branch.follow_branch` (no switching). Per point:
   the corrector (Gauss-Newton with the monodromy and heyoka's sensitivity to a3 from the one definition), the
   tangent, the multipliers and test functions, τ over the period; the location of the period doubling; the
   independent DOP853 check at every 10th point.
B. **The reference**: the ball's equations written by hand as heyoka expressions (ω by Sherman-Morrison), their
   variational equations by ``hy.var_ode_sys`` compiled once, and at each of the core's a3 values, starting from
   the previous value's orbit (natural-parameter continuation, what one writes by hand),
   ``scipy.optimize.least_squares(method="lm")`` on x(T) - x0 with γ3 = 0, H = 2, (M, γ) = 0, |γ| = 1, the
   Jacobian from the monodromy. Same tolerance (machine epsilon), same orbits: the closing states are compared.

Printed: time per point of each (median of 3 after a warm-up), integrations per point, the ratio reference /
core, the largest difference between the two sets of orbits; then the core on 200 points (a3 from 0.5 to 1.95
with max_step 0.01: the branch runs up to the homoclinic limit at |a| = 2), its time per point and its work.
"""

from __future__ import annotations

import statistics
import subprocess
import time

import heyoka as hy
import numpy as np
from scipy.optimize import least_squares

from nonholonomic.analysis.chaos_map.grid import Grid, complete
from nonholonomic.analysis.periodic_orbit import branch as branch_module, find_periodic_orbit
from nonholonomic.analysis.periodic_orbit.arclength import correct
from nonholonomic.analysis.periodic_orbit.branch import BranchOptions, follow_branch
from nonholonomic.numerics.kernels import parameter_vector
from nonholonomic.systems import get_system

INERTIA, D = np.array([2.0, 3.0, 4.5]), 0.7
EPS = float(np.finfo(float).eps)


def hand_written() -> hy.taylor_adaptive:
    """The ball's x, Φ (6 × 6) by heyoka's var_ode_sys on equations written here; a3 is par[0]."""
    M = hy.make_vars("M1", "M2", "M3")
    g = hy.make_vars("g1", "g2", "g3")
    a = [hy.expression(0.3), hy.expression(-0.2), hy.par[0]]
    A = [1.0 / (INERTIA[i] + D) for i in range(3)]
    Am = [A[i] * M[i] for i in range(3)]
    Ag = [A[i] * g[i] for i in range(3)]
    gAm = sum((g[i] * Am[i] for i in range(1, 3)), g[0] * Am[0])
    gAg = sum((g[i] * Ag[i] for i in range(1, 3)), g[0] * Ag[0])
    w = [Am[i] + D * Ag[i] * gAm / (1.0 - D * gAg) for i in range(3)]

    def cross(u, v):  # noqa: ANN001, ANN202
        return [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]

    dM = [x + y for x, y in zip(cross(M, w), cross(g, a))]
    dg = cross(g, w)
    sys = list(zip(M + g, dM + dg))
    vs = hy.var_ode_sys(sys, hy.var_args.vars, order=1)
    return hy.taylor_adaptive(vs, np.zeros(6 + 36), tol=EPS, compact_mode=True, pars=[0.5])


def reference_branch(ta: hy.taylor_adaptive, values: list[float], x0: np.ndarray, t0: float) -> tuple[list, int]:
    """Natural-parameter continuation by least_squares with the hand-written monodromy."""
    calls = [0]

    def energy_and_grad(x: np.ndarray, a3: float) -> tuple[float, np.ndarray]:
        m, g = x[:3], x[3:]
        iq = np.diag(INERTIA + D) - D * np.outer(g, g)
        w = np.linalg.solve(iq, m)
        e = 0.5 * m @ w + np.array([0.3, -0.2, a3]) @ g
        # dH/dM = ω; dH/dγ = a + D (ω·γ) ω (from I_Q = diag(I + D) - D γγᵀ)
        return e, np.concatenate([w, np.array([0.3, -0.2, a3]) + D * (w @ g) * w])

    def run(z: np.ndarray, a3: float) -> tuple[np.ndarray, np.ndarray]:
        calls[0] += 1
        ta.time = 0.0
        ta.pars[0] = a3
        ta.state[:6] = z[:6]
        ta.state[6:] = np.eye(6).reshape(-1)
        ta.propagate_until(float(z[6]))
        return ta.state[:6].copy(), ta.state[6:].reshape(6, 6).copy()

    orbits = []
    z = np.append(x0, t0)
    for a3 in values:
        cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

        def flow(v: np.ndarray, a3: float = a3,
                 cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = cache) -> tuple[np.ndarray, np.ndarray]:
            key = v.tobytes()
            if key not in cache:
                cache.clear()
                cache[key] = run(v, a3)
            return cache[key]

        def fun(v: np.ndarray, a3: float = a3) -> np.ndarray:
            x, phi = flow(v)
            e, _ = energy_and_grad(v[:6], a3)
            return np.concatenate([x - v[:6], [v[5], e - 2.0, v[:3] @ v[3:6], v[3:6] @ v[3:6] - 1.0]])

        def jac(v: np.ndarray, a3: float = a3) -> np.ndarray:
            x, phi = flow(v)
            _, de = energy_and_grad(v[:6], a3)
            m, g = x[:3], x[3:]
            w = np.linalg.solve(np.diag(INERTIA + D) - D * np.outer(g, g), m)
            f = np.concatenate([np.cross(m, w) + np.cross(g, [0.3, -0.2, a3]), np.cross(g, w)])
            out = np.zeros((10, 7))
            out[:6, :6], out[:6, 6] = phi - np.eye(6), f
            out[6, 5] = 1.0
            out[7, :6] = de
            out[8, :6] = np.concatenate([v[3:6], v[:3]])
            out[9, 3:6] = 2 * v[3:6]
            return out

        fit = least_squares(fun, z, jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
        z = fit.x
        orbits.append((a3, z.copy(), float(np.max(np.abs(fit.fun)))))
    return orbits, calls[0]


def centre() -> tuple:
    system = get_system("chaplygin_ball", "linear")
    p = parameter_vector(system, {"inertia": list(INERTIA), "D": D, "a": [0.3, -0.2, 0.5]})
    grid = Grid("gamma3", 0.0, ("gamma1", "M3"), {"energy": 2.0, "area": 0.0}, (1, 1))
    seed = complete(system, p, grid, ((-0.201, -0.199), (-0.001, 0.001))).states[0]
    orbit = find_periodic_orbit(system, p, seed, "gamma3", coordinates=("gamma1", "M3"), t_final=100.0)
    return system, p, orbit


def main() -> None:
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    print(f"load: {load}")
    system, p, orbit = centre()
    options = BranchOptions("potential.a[2]", 0.95, parameter_index=6, max_points=100, step=0.02, max_step=0.02,
                            switch=False)
    follow_branch(system, p, orbit, options, tolerance=EPS)  # warm-up: compiles the sensitivity integrator
    core_times, corrector_times, branch = [], [], None
    for _ in range(3):
        spent = [0.0]

        def timed(*args, spent=spent, **kwargs):  # noqa: ANN001, ANN002, ANN003, ANN202
            start = time.perf_counter()
            try:
                return correct(*args, **kwargs)
            finally:
                spent[0] += time.perf_counter() - start

        branch_module.correct = timed  # the walk's corrections (not the location's)
        start = time.perf_counter()
        branch = follow_branch(system, p, orbit, options, tolerance=EPS)
        core_times.append(time.perf_counter() - start)
        branch_module.correct = correct
        corrector_times.append(spent[0])
    assert branch is not None
    values = [q.value for q in branch.points[1:]]
    ta = hand_written()
    reference_branch(ta, values[:2], orbit.initial_state, orbit.period_t)  # warm-up
    ref_times, ref, calls = [], [], 0
    for _ in range(3):
        start = time.perf_counter()
        ref, calls = reference_branch(ta, values, orbit.initial_state, orbit.period_t)
        ref_times.append(time.perf_counter() - start)
    points = len(values)
    core, reference = statistics.median(core_times) / points, statistics.median(ref_times) / points
    corrector = statistics.median(corrector_times) / points
    diff = max(float(np.max(np.abs(z[:6] - q.initial_state))) for (_, z, _), q in zip(ref, branch.points[1:]))
    print(f"a3 from 0.5 to 0.95: {points} points after the start, the period doubling at "
          f"{branch.bifurcations[0].value:.10f} located ({branch.bifurcations[0].trials} trials)")
    print(f"  core, its corrector alone:              {1e3 * corrector:7.2f} ms/point")
    print(f"  core, the whole branch (every check):   {1e3 * core:7.2f} ms/point, "
          f"{branch.evaluations / points:.1f} integrations/point (location and tangents included)")
    print(f"  heyoka by hand + scipy least_squares:   {1e3 * reference:7.2f} ms/point, {calls / points:.1f} "
          f"integrations/point (natural parameter, at the core's values)")
    print(f"  ratio reference / core's corrector: {reference / corrector:.2f}; reference / the whole branch: "
          f"{reference / core:.2f}; the same orbits to {diff:.1e}; reference closing "
          f"{max(r for _, _, r in ref):.1e}")
    family = BranchOptions("potential.a[2]", 1.95, parameter_index=6, max_points=200, step=0.01, max_step=0.01,
                            switch=False)
    start = time.perf_counter()
    long = follow_branch(system, p, orbit, family, tolerance=EPS)
    took = time.perf_counter() - start
    print(f"a family of {len(long.points)} points (a3 0.5 -> {long.points[-1].value:.6f}, {long.status}): "
          f"{took:.2f} s, {1e3 * took / len(long.points):.1f} ms/point, {long.evaluations} integrations, "
          f"{long.taylor_steps} Taylor steps, bifurcations: "
          + ", ".join(f"{b.kind} {b.value:.6f}" for b in long.bifurcations))


if __name__ == "__main__":
    main()
