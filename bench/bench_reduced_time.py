"""Benchmark: τ = ∫ N dt by quadrature along the dense output, where N is not analytic (issue 33).

Run from the repository root::

    .venv/bin/python bench/bench_reduced_time.py [--t-final 2000] [--repeat 5]

The Chaplygin skate on an inclined plane (N = √(1 − sin θ)·√(1 + sin θ) = |cos θ|, a kink at each of its 1,082
zeros over t = 2000), in one run, median of ``--repeat``:

- the service's :func:`nonholonomic.numerics.integration.integrate` (state by heyoka, τ by adaptive Gauss–Legendre
  cut at the kinks, its zeros located, the Romberg check);
- heyoka written by hand, with τ' = N as one more variable (``propagate_grid``): the cost of the old way, whose τ
  is wrong after the first zero;
- scipy's DOP853 at rtol = atol = 1e-12 with τ' = N beside the state (the accuracy a researcher gets from
  ``solve_ivp``), and DOP853 with the kinks as terminal events, restarted at each (the careful way by hand).

Each line prints the wall time, the ratio against the service, and |τ(T) − exact| (exact: the closed form).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import argparse
import os
import statistics
import time
from collections.abc import Callable

import numpy as np


def exact_tau(t: float) -> float:
    def primitive(u: float) -> float:
        k = np.floor((u + np.pi / 2) / np.pi)
        return float(2 * k + np.sin(u - k * np.pi))
    return (primitive(0.4 + 1.7 * t) - primitive(0.4)) / 1.7


def timed(fn: Callable[[], float], repeat: int) -> tuple[float, float]:
    times, value = [], 0.0
    for _ in range(repeat):
        tic = time.perf_counter()
        value = fn()
        times.append(time.perf_counter() - tic)
    return statistics.median(times), value


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--t-final", type=float, default=2000.0)
    parser.add_argument("--samples", type=int, default=2001)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()

    import heyoka as hy
    from scipy.integrate import solve_ivp

    from nonholonomic.lagrangian.parse import parse_system
    from nonholonomic.numerics.integration import integrate
    from nonholonomic.numerics.kernels import numeric
    from nonholonomic.systems.lagrangian import define
    from tests.unit.test_reduced_time import SKATE, SKATE_STATE

    data = parse_system(SKATE)
    system = define(data)
    p = np.array(data.values, dtype=float)
    y0 = np.array(SKATE_STATE)
    T, grid = args.t_final, np.linspace(0.0, args.t_final, args.samples)
    integrate(system, p, y0, 1.0, 2)  # compile outside the timing

    # heyoka by hand: the skate's Lagrange-d'Alembert equations, the blade's reaction lambda eliminated:
    # m x'' = m g s - lambda sin th, m y'' = lambda cos th, J th'' = 0, and -x' sin th + y' cos th = 0 differentiated
    # gives lambda / m = th' (x' cos th + y' sin th) + g s sin th; then tau' = N as the last variable
    x, y, th, xd, yd, thd, tau = hy.make_vars("x", "y", "theta", "x_dot", "y_dot", "theta_dot", "tau")
    values = {str(k): float(v) for k, v in zip(data.parameters, data.values)}
    g, s = values["g"], values["s"]
    reaction = thd * (xd * hy.cos(th) + yd * hy.sin(th)) + g * s * hy.sin(th)
    eqs = [(x, xd), (y, yd), (th, thd), (xd, g * s - reaction * hy.sin(th)), (yd, reaction * hy.cos(th)),
           (thd, 0.0 * thd), (tau, hy.sqrt(1.0 - hy.sin(th)) * hy.sqrt(1.0 + hy.sin(th)))]
    ta = hy.taylor_adaptive(eqs, [*y0, 0.0], tol=float(np.finfo(float).eps))

    def by_hand() -> float:
        ta.time, ta.state[:] = 0.0, [*y0, 0.0]
        out = ta.propagate_grid(grid)[-1]
        return float(out[-1, -1])

    kernels = numeric(system)

    def f(t: float, z: np.ndarray) -> np.ndarray:
        dx = kernels.rhs_single(z[:6], p)
        return np.append(dx, abs(np.cos(z[2])))

    def scipy_plain() -> float:
        sol = solve_ivp(f, (0.0, T), [*y0, 0.0], method="DOP853", rtol=1e-12, atol=1e-12)
        return float(sol.y[-1, -1])

    def kink(t: float, z: np.ndarray) -> float:
        return float(np.cos(z[2]))
    kink.terminal = True  # type: ignore[attr-defined]

    def scipy_events() -> float:
        t0, z = 0.0, np.array([*y0, 0.0])
        while t0 < T:
            sol = solve_ivp(f, (t0, T), z, method="DOP853", rtol=1e-12, atol=1e-12, events=kink)
            t0, z = float(sol.t[-1]), sol.y[:, -1].copy()
            if sol.status == 1:  # past the kink by a hair, so the event does not fire again at once
                t_next = t0 + 1e-9
                z = z + f(t0, z) * 1e-9
                t0 = t_next
        return float(z[-1])

    service_s, service_tau = timed(lambda: float(integrate(system, p, y0, T, args.samples).tau[-1]), args.repeat)
    exact = exact_tau(T)
    load = os.getloadavg()[0]
    print(f"skate, t = 0..{T:g}, {args.samples} samples; load average {load:.2f}")
    print(f"  service (quadrature, zeros, check)  {service_s * 1e3:9.1f} ms  ratio 1.00   |tau - exact| = "
          f"{abs(service_tau - exact):.2e}")
    for name, fn, repeat in (("heyoka by hand (tau in the state)", by_hand, args.repeat),
                             ("scipy DOP853 1e-12 (tau in the state)", scipy_plain, 1),
                             ("scipy DOP853 1e-12, restarted at kinks", scipy_events, 1)):
        seconds, value = timed(fn, repeat)
        print(f"  {name:<37} {seconds * 1e3:9.1f} ms  ratio {seconds / service_s:5.2f}   |tau - exact| = "
              f"{abs(value - exact):.2e}")


if __name__ == "__main__":
    main()
