"""Study 1 revisited with the chaos indicators: the Jacobi problem's chaotic layer on the symmetric line,
the integrable ball's control at its true separatrix, and the sign of a = (ω, n) along orbits.

Run from the repository root (~1 min on 2 cores, the core only, no service)::

    .venv/bin/python bench/science_layer.py

1. **The layer.** States on the symmetric line ω2 = 0, a > 0, of study 1's section (x2 = 0, level
   H = 0.5, K = 2; ``science_geometry.jacobi_state``) at θ* + d, θ* = −0.33591693492 the separatrix found
   by study 1's bisection, d from −2e-3 to 2e-3 in steps of 1e-4; MEGNO ⟨Y⟩, FLI and the finite-time
   exponent at t = 2e4 (:mod:`nonholonomic.analysis.chaos_map.indicators`, one batch integration each).
2. **The ball's control.** Chaplygin's ball, U = 0, (H, c) = (2, 0), on the line γ = e2 (φ = π/2) of
   study 1's ball section, at M3* + d with M3* the separatrix: on γ = e2 the level set meets the
   separatrix of the unstable rotation about the middle axis, F = (M, M) = 2H (I2 + D) = 14.8, where
   ω = I_Q⁻¹M with I_Q = diag(I1 + D, I2, I3 + D) gives M3² = (F/(I1 + D) − 2H)/(1/(I1 + D) − 1/(I3 + D))
   = 8.32. Study 1 first used M3 = 2.88448893419, 4.8e-5 above it (its bisection of the time averages).
3. **a = (ω, n) along orbits** started on the line at θ0 (a > 0), t = 3000, 30001 samples: how often a
   changes sign.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for path in (ROOT, ROOT / "bench"):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))

import math  # noqa: E402
import os  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from science_config import BALL, BALL_LEVEL, JACOBI, JACOBI_LEVEL  # noqa: E402
from science_geometry import ball_state, jacobi_state  # noqa: E402

from nonholonomic import get_system  # noqa: E402
from nonholonomic.analysis import indicators  # noqa: E402
from nonholonomic.numerics.kernels import parameter_vector, state_vector  # noqa: E402
from nonholonomic.simulation import simulate  # noqa: E402

THETA_STAR = -0.33591693492
T_LAYER = 2e4
M3_SEPARATRIX = math.sqrt(8.32)
THRESHOLD = indicators.default_thresholds(T_LAYER)["megno"]


def scan(kind: str, parameters: dict, states: list[dict], labels: list[str], T: float) -> None:
    system = get_system(kind, "zero")
    p = parameter_vector(system, parameters)
    X = np.array([state_vector(system, s, p) for s in states])
    start = time.perf_counter()
    found = indicators.run_batch(system, np.repeat(p[None], len(X), 0), X, T)
    print(f"   ({len(X)} orbits in {time.perf_counter() - start:.1f} s)")
    for label, f in zip(labels, found):
        verdict = "chaotic" if f.megno > THRESHOLD else "regular"
        print(f"   {label}  <Y> {f.megno:8.2f}  FLI {f.fli:7.1f}  lambda {f.lyapunov:.2e}  {verdict}")


def main() -> int:
    load = os.getloadavg()
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; chaotic where <Y> > {THRESHOLD:g}")
    jacobi = {k: v for k, v in JACOBI.items() if k not in ("kind", "potential")}
    offsets = [round(k * 1e-4, 6) for k in range(-20, 21)]
    print(f"1. the Jacobi problem on the line omega2 = 0, a > 0, at theta* + d, t = {T_LAYER:g}")
    scan("ball_on_quadric", jacobi,
         [jacobi_state(THETA_STAR + d, 0.0, JACOBI_LEVEL["energy"], JACOBI_LEVEL["K"], JACOBI) for d in offsets],
         [f"d = {d:+.1e}" for d in offsets], T_LAYER)
    ball = {"inertia": BALL["inertia"], "D": BALL["D"]}
    deltas = [-1e-2, -3e-3, -1e-3, -3e-4, -1e-4, -1e-6, -1e-9, 1e-9, 1e-6, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2]
    print(f"2. the ball (U = 0) on gamma = e2 at M3* + d, M3* = sqrt(8.32) = {M3_SEPARATRIX!r}, t = {T_LAYER:g}")
    scan("chaplygin_ball", ball,
         [ball_state(math.pi / 2, M3_SEPARATRIX + d, BALL_LEVEL["energy"], BALL_LEVEL["area"], BALL) for d in deltas],
         [f"d = {d:+.0e}" for d in deltas], T_LAYER)
    print("3. a = (omega, n) along orbits from the line omega2 = 0, a > 0, t = 3000")
    system = get_system("ball_on_quadric", "zero")
    B = np.asarray(JACOBI["B"], dtype=float)
    for theta in np.round(np.arange(-1.0, -0.55, 0.05), 2):
        state = jacobi_state(float(theta), 0.0, JACOBI_LEVEL["energy"], JACOBI_LEVEL["K"], JACOBI)
        r = simulate(system, jacobi, state, 3000.0, 30001, checks=())
        x, w = r.state("x"), r.state("omega")
        n = x / B
        a = np.sum(w * n, axis=1) / np.linalg.norm(n, axis=1)
        changes = int(np.sum(np.diff(np.sign(a)) != 0))
        print(f"   theta0 = {theta:+.2f}: a in [{a.min():+.3f}, {a.max():+.3f}], {changes} sign changes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
