"""The systems, levels, sections and thresholds of bench/science.py, and its run sizes (``Config``,
``FULL``, ``QUICK``): the request fragments and constants shared by the other parts. Part of
bench/science.py (run that file; this module only holds data).
"""

from __future__ import annotations

from dataclasses import dataclass

# --------------------------------------------------------------------------------------------------
# The systems, levels and analysis blocks (request fragments)
# --------------------------------------------------------------------------------------------------

#: The catalog's Jacobi problem: a solid ball (D0 = 2/5 m R^2) on the ellipsoid with semi-axes 1, √2, √3.
JACOBI = {"kind": "ball_on_quadric", "D0": 0.036, "m": 1.0, "R": 0.3, "B": [1.0, 2.0, 3.0],
          "potential": {"kind": "zero"}}
#: The same ball on an ellipsoid of revolution (b1 = b2): integrable (Routh), the same-system control.
JACOBI_ROUND = {**JACOBI, "B": [1.0, 1.0, 3.0]}
#: The quadric in a linear field: no K, chaotic (tests/unit/test_lyapunov.py).
JACOBI_LINEAR = {**JACOBI, "potential": {"kind": "linear", "a": [0.1, -0.2, 0.3]}}
BALL = {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7, "potential": {"kind": "zero"}}
BALL_LINEAR = {**BALL, "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}}

JACOBI_LEVEL = {"energy": 0.5, "K": 2.0}
ROUND_LEVEL = {"energy": 0.5, "K": 3.0}
BALL_LEVEL = {"energy": 2.0, "area": 0.0}
#: Study 2's level of the ball (U = 0): H = 0.5, c = 0.
TORUS_ENERGY, TORUS_AREA = 0.5, 0.0

#: x2 = 0 (the plane of the longest and the shortest axis), x2 increasing: crossed by every orbit
#: seen (x3 = 0 misses orbits that circle one pole). Chart: θ = atan2(x3/√b3, x1/√b1) and ω2, one
#: sheet per sign of a = (ω, n) (a changes sign on orbits from θ0 ≈ −1.0 … −0.75: bench/science_layer.py).
JACOBI_SECTION = {"surface": "x2", "value": 0.0, "direction": "increasing", "coordinates": ["x3", "omega2"],
                  "max_points": 100000}
#: γ3 = 0 increasing. Chart: φ = atan2(γ2, γ1) and M3 (the increasing branch is single-valued in them).
BALL_SECTION = {"surface": "gamma3", "value": 0.0, "direction": "increasing", "coordinates": ["gamma1", "M3"],
                "max_points": 100000}
LYAPUNOV = {"count": 1, "interval": 5.0}

GROWTH_CHAOTIC = 3.0
ORDER_REGULAR = 0.65
MIN_POINTS = 30


@dataclass(frozen=True)
class Config:
    members: int            # sampled members per main ensemble
    t_final: float          # main ensembles
    controls: int           # members of the small control ensembles (quadric in a field, round quadric)
    line_points: int        # separatrix probe: states on the symmetric line
    t_line: float           # ... their sections, and each bisection step
    separatrices: int       # ... how many separatrices per system are probed
    offsets: tuple[float, ...]  # ... distances of the probe orbits from the separatrix (both sides)
    t_probe: float          # ... their sections and exponents
    bisection_tol: float    # ... width of the final bracket (in the line parameter)
    resonances: tuple[tuple[int, int], ...]
    orbits: tuple[float, ...]   # study 2: φ of the orbits' starting points on each torus
    scan_points: int
    scan_returns: int


FULL = Config(members=64, t_final=1e4, controls=8, line_points=64, t_line=3000.0, separatrices=1,
              offsets=(1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 1e-6, 1e-9), t_probe=2e4, bisection_tol=1e-11,
              resonances=((1, 3), (1, 4)),
              orbits=(0.0, 0.7, 1.5, 2.5, -1.0), scan_points=24, scan_returns=200)
QUICK = Config(members=8, t_final=2e3, controls=4, line_points=32, t_line=1500.0, separatrices=1,
               offsets=(1e-4,), t_probe=5e3, bisection_tol=1e-9, resonances=((1, 3),),
               orbits=(0.0, 1.5, -1.0), scan_points=12, scan_returns=60)
