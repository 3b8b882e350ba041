"""Benchmark: systems written by the user against the built-in kinds they generalise (issue 12, items 2-3).

Run from the repository root::

    .venv/bin/python bench/bench_user_systems.py [--runs 9]

1. ``ball_on_surface`` with the quadric written as Φ(x) against the kind ``ball_on_quadric`` (the
   reference, same run): the same heyoka integration to t = 1000 (machine-epsilon tolerance), median of
   ``--runs``; the ratio surface / quadric and the largest difference of the samples. Also the torus of
   the catalog example: its time and its first definition and compile.
2. ``generalized_chaplygin`` with Veselova's Euler-angle form (Theorem 1's worked example) against the
   kind ``veselova`` (the reference, same run), to t = 200: the ratio and the largest difference of γ; the
   seconds of the first definition (sympy, Theorem 1 included) and of the integrator's compile.
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

from nonholonomic.hamiltonization.local_forms import euler_angles_and_rates, veselova_generalized_chaplygin  # noqa: E402
from nonholonomic.numerics.integration import MACHINE_EPSILON, heyoka_template, integrate  # noqa: E402
from nonholonomic.numerics.kernels import parameter_vector, state_vector  # noqa: E402
from nonholonomic.systems import (
    ball_on_surface as bs,  # noqa: E402
    generalized_chaplygin as gc,  # noqa: E402
    get_system,  # noqa: E402
)

BALL = {"D0": 0.036, "m": 1.0, "R": 0.3}
B = np.array([[2.0, 0.3, -0.2], [0.3, 1.5, 0.4], [-0.2, 0.4, 1.0]])
INERTIA = {"I1": 2.0, "I2": 3.0, "I3": 4.5}


def timed(system, values: dict, state: dict, t_final: float, samples: int,
          runs: int) -> tuple[float, np.ndarray, float]:
    """(median seconds, states, seconds of the first call: compile or disk cache)."""
    p = parameter_vector(system, values)
    y0 = state_vector(system, state, p)
    start = time.perf_counter()
    integrate(system, p, y0, t_final, samples)
    first = time.perf_counter() - start
    times, states = [], None
    for _ in range(runs):
        start = time.perf_counter()
        states = integrate(system, p, y0, t_final, samples).states
        times.append(time.perf_counter() - start)
    return statistics.median(times), states, first


def surfaces(runs: int) -> None:
    A = np.linalg.inv(B)
    names = ("A11", "A12", "A13", "A22", "A23", "A33")
    quadric = bs.surface("A11*x1**2 + A22*x2**2 + A33*x3**2 + 2*(A12*x1*x2 + A13*x1*x3 + A23*x2*x3) - 1",
                         tuple(sorted(names)))
    entries = dict(zip(names, (A[0, 0], A[0, 1], A[0, 2], A[1, 1], A[1, 2], A[2, 2])))
    d = np.array([0.5, 0.6, 0.7])
    state = {"x": d / np.sqrt(d @ A @ d), "omega": [1.2, -0.8, 2.0]}
    t_ref, s_ref, _ = timed(get_system("ball_on_quadric", "zero"), {**BALL, "B": B}, state, 1000.0, 1001, runs)
    t_mine, s_mine, _ = timed(get_system(bs.KIND, "zero", quadric), {**BALL, **entries}, state, 1000.0, 1001, runs)
    ratio = t_mine / t_ref
    print(f"ball_on_surface (quadric as Phi) vs ball_on_quadric, t = 1000: {t_mine * 1e3:.2f} ms vs "
          f"{t_ref * 1e3:.2f} ms, ratio {ratio:.2f}; max |sample difference| {np.max(np.abs(s_mine - s_ref)):.2e}")
    torus = get_system(bs.KIND, "linear", bs.DEFAULT_SURFACE)
    values = {**BALL, "a0": 2.0, "r0": 1.0, "a": [0.0, 0.0, 9.81]}
    t_torus, _, _ = timed(torus, values, bs.EXAMPLE["initial_state"], 1000.0, 1001, runs)
    print(f"torus with gravity (catalog example), t = 1000: {t_torus * 1e3:.2f} ms (another orbit: "
          f"{t_torus / t_ref:.2f} x the quadric's time)")
    size = f"s{time.time_ns() % 10**9}"  # a name never seen: the definition is not in the caches
    start = time.perf_counter()
    quartic = get_system(bs.KIND, "zero", bs.surface(f"x1**4 + x2**4 + x3**4 - {size}**4", (size,)))
    defined = time.perf_counter() - start
    start = time.perf_counter()
    heyoka_template(quartic, MACHINE_EPSILON)
    compiled = time.perf_counter() - start
    print(f"a new surface (a quartic): definition {defined:.2f} s, integrator compile {compiled:.2f} s")


def euler_angles(runs: int) -> None:
    gamma0 = np.array([0.48, 0.6, 0.64])
    omega0 = np.cross(gamma0, [0.3, -0.5, 0.2])
    t_ref, s_ref, _ = timed(get_system("veselova", "zero"), {"inertia": list(INERTIA.values())},
                            {"omega": omega0, "gamma": gamma0}, 200.0, 401, runs)
    ex = veselova_generalized_chaplygin()
    start = time.perf_counter()
    data = gc.chaplygin_data(ex["L"], ("theta", "phi"), ("thetadot", "phidot"), ex["a1"], ex["a2"],
                             ex["b"], None, ("I1", "I2", "I3"))
    system = gc.define(data)
    defined = time.perf_counter() - start
    start = time.perf_counter()
    heyoka_template(system, MACHINE_EPSILON)
    compiled = time.perf_counter() - start
    th, ph, thd, phd, _, _ = euler_angles_and_rates(omega0[None, :], gamma0[None, :])
    t_mine, s_mine, _ = timed(system, INERTIA, {"q": [th[0], ph[0]], "q_dot": [thd[0], phd[0]]}, 200.0, 401, runs)
    q = s_mine[:, :2]
    gamma = np.stack([np.sin(q[:, 0]) * np.sin(q[:, 1]), np.sin(q[:, 0]) * np.cos(q[:, 1]), np.cos(q[:, 0])], axis=1)
    print(f"generalized_chaplygin (Veselova in Euler angles, t and tau) vs veselova, t = 200: {t_mine * 1e3:.2f} ms "
          f"vs {t_ref * 1e3:.2f} ms, ratio {t_mine / t_ref:.2f}; max |gamma difference| "
          f"{np.max(np.abs(gamma - s_ref[:, 3:])):.2e}; first definition (Theorem 1 included) {defined:.2f} s, "
          f"integrator compile {compiled:.2f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=9)
    args = parser.parse_args()
    surfaces(args.runs)
    euler_angles(args.runs)


if __name__ == "__main__":
    main()
