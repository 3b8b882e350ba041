"""Periodic orbits: the core's search (Newton on the closing equations with the monodromy) against scipy's
root finder on the return map by finite differences, measured in the same run.

Chaplygin's ball in a linear field (I = (2, 3, 4.5), D = 0.7, a = (0.3, -0.2, 0.5)), level H = 2,
(M, γ) = 0, section γ3 = 0 (increasing) in the chart (γ1, M3), three seeds:

* the island's centre (period 1, elliptic) from (γ1, M3) = (-0.2, 0);
* a hyperbolic period-1 orbit (multipliers 10.53, 0.095) from (-0.8666, 2.5715), where Newton wanders;
* a prime period-2 orbit (elliptic) from (-0.8666, -4.2962).

A. **The core**: :func:`nonholonomic.analysis.periodic_orbit.find_periodic_orbit` (its checks included:
   the crossings, the independent DOP853 integration, the multipliers).
B. **The reference**: ``scipy.optimize.root(method="hybr")`` (MINPACK's Powell hybrid method, its own
   finite-difference Jacobian) on F(z) = P^k(z) - z in the chart, z → the state by the grid's completion
   (:func:`nonholonomic.analysis.chaos_map.grid.complete`), P by heyoka's events
   (:func:`~nonholonomic.analysis.poincare.section`); then the same closing error max|x(T) - x0|
   measured by the core's integrator.

Printed: the core's time with its checks (median of 3 after a warm-up) and its search alone
(``search_time_s``: Newton's part), the reference's time, the ratio reference / core's search, and both
closing errors. Targets: the search at least as fast as the reference (ratio ≥ 1) and closing to ≤ 1e-12.
The checks (mostly the independent DOP853 integration, a Python right-hand side) are reported, not raced.
"""

from __future__ import annotations

import statistics
import subprocess
import time

import numpy as np
from scipy.optimize import root

from nonholonomic.analysis.chaos_map.grid import Grid, complete
from nonholonomic.analysis.periodic_orbit import find_periodic_orbit
from nonholonomic.analysis.poincare import section
from nonholonomic.numerics.integration import integrate
from nonholonomic.numerics.kernels import parameter_vector
from nonholonomic.systems import get_system

LEVEL = {"energy": 2.0, "area": 0.0}
SEEDS = {"centre (period 1, elliptic)": ((-0.2, 0.0), 1),
         "hyperbolic (period 1)": ((-0.86660837, 2.57149011), 1),
         "prime period 2 (elliptic)": ((-0.86660837, -4.29619123), 2)}


def state_at(system, p, z) -> np.ndarray:
    grid = Grid("gamma3", 0.0, ("gamma1", "M3"), LEVEL, (1, 1))
    cells = complete(system, p, grid, ((z[0] - 1e-3, z[0] + 1e-3), (z[1] - 1e-3, z[1] + 1e-3)))
    return cells.states[0]


def reference(system, p, z0, k: int) -> tuple[np.ndarray, float]:
    """scipy's hybr on the chart's return map; the closing state and its period."""
    times: list[float] = []

    def residual(z: np.ndarray) -> np.ndarray:
        x = state_at(system, p, z)
        if not np.all(np.isfinite(x)):
            return np.array([1e3, 1e3])
        sec = section(system, p, x, 200.0, "gamma3", max_points=k + 2, coordinates=("gamma1", "M3"))
        keep = sec.t > 1e-9
        if keep.sum() < k:
            return np.array([1e3, 1e3])
        times.append(float(sec.t[keep][k - 1]))
        return sec.coordinates[keep][k - 1] - z

    fit = root(residual, np.asarray(z0, dtype=float), method="hybr", options={"xtol": 1e-14})
    residual(fit.x)
    return state_at(system, p, fit.x), times[-1]


def closing(system, p, x, t) -> float:
    end = integrate(system, p, x, t, 2).states[-1]
    return float(np.max(np.abs(end - x)) / max(1.0, np.max(np.abs(x))))


def timed(fn, repeats: int = 3) -> tuple[float, object]:
    fn()  # warm-up: compiles, fills caches
    runs, out = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        runs.append(time.perf_counter() - start)
    return statistics.median(runs), out


def main() -> None:
    system = get_system("chaplygin_ball", "linear")
    p = parameter_vector(system, {"inertia": [2.0, 3.0, 4.5], "D": 0.7, "a": [0.3, -0.2, 0.5]})
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    print(f"periodic orbits of the ball in a linear field; load: {load}")
    rows = []
    for name, (z0, k) in SEEDS.items():
        seed = state_at(system, p, z0)
        t_core, orbit = timed(lambda seed=seed, k=k: find_periodic_orbit(
            system, p, seed, "gamma3", period=k, t_final=200.0, coordinates=("gamma1", "M3")))
        t_ref, (x_ref, T_ref) = timed(lambda z0=z0, k=k: reference(system, p, z0, k))
        err_core = closing(system, p, orbit.initial_state, orbit.period_t)
        err_ref = closing(system, p, x_ref, T_ref)
        same = np.max(np.abs(x_ref - orbit.initial_state))
        search = orbit.search_time_s
        rows.append((name, search, t_ref, err_core, err_ref))
        print(f"{name:28s} core {t_core * 1e3:7.1f} ms with its checks, the search {search * 1e3:6.1f} ms "
              f"({orbit.status}, {orbit.method}, {orbit.evaluations} integrations), T = {orbit.period_t:.10f}, "
              f"closing {err_core:.1e}")
        print(f"{'':28s} scipy hybr {t_ref * 1e3:7.1f} ms, T = {T_ref:.10f}, closing {err_ref:.1e}; "
              f"same orbit to {same:.1e}; ratio reference / core's search {t_ref / search:.2f}, "
              f"/ core with checks {t_ref / t_core:.2f}")
    print("SUMMARY")
    for name, search, t_ref, err_core, err_ref in rows:
        ok = t_ref / search >= 1.0 and err_core <= 1e-12
        print(f"  {name:28s} ratio reference / search {t_ref / search:5.2f}  closing core {err_core:.1e} vs "
              f"reference {err_ref:.1e}  {'OK' if ok else 'MISS'}")


if __name__ == "__main__":
    main()
