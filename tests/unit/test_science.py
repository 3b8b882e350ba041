"""A short variant of bench/science.py on the core functions: each test fails if the physics is wrong.

* [b008] (paper, Comment after eq. 2604-4): on a resonant torus of Chaplygin's ball (U = 0) every
  orbit closes with the same period in τ (dτ = ρ_μ dt, eq. 2604-5, where the flow is Hamiltonian and
  linear on the tori) while the periods in t differ; on a non-resonant torus the q-return times differ
  in both.
* The section measure (nearest-neighbour index order) and the exponent's growth power separate the
  integrable ball from the ball in a linear field.
* The nonholonomic Jacobi problem (U = 0) on the triaxial ellipsoid: a random orbit is regular, an
  orbit started 1e-4 from a separatrix is chaotic (the thin chaotic layer), while next to a
  separatrix of the integrable ball nothing is chaotic.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

from nonholonomic.analysis import lyapunov, poincare, sampling
from nonholonomic.numerics.kernels import parameter_vector
from nonholonomic.systems import get_system

_PATH = Path(__file__).resolve().parents[2] / "bench" / "science.py"
_spec = importlib.util.spec_from_file_location("bench_science", _PATH)
science = importlib.util.module_from_spec(_spec)
sys.modules["bench_science"] = science
_spec.loader.exec_module(science)

BALL = science.BALL
H, C = science.TORUS_ENERGY, science.TORUS_AREA


def _params(spec: dict, potential: str) -> tuple:
    system = get_system(spec["kind"], potential)
    values = {k: v for k, v in spec.items() if k not in ("kind", "potential")}
    values.update({k: v for k, v in spec["potential"].items() if k != "kind"})
    return system, parameter_vector(system, values)


def _vector(state: dict, names: tuple[str, str]) -> np.ndarray:
    return np.concatenate([state[names[0]], state[names[1]]])


def _returns(system, p, y0: np.ndarray, q: int, t_final: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """t, τ and φ of the first q + 1 crossings of γ3 = 0 (increasing), the start (on the section) included."""
    s = poincare.section(system, p, y0, t_final, "gamma3", max_points=q + 1)
    t, tau, phi = s.t, s.tau, np.arctan2(s.points["gamma"][:, 1], s.points["gamma"][:, 0])
    if t[0] > 1e-9:
        t, tau = np.concatenate([[0.0], t]), np.concatenate([[0.0], tau])
        phi = np.concatenate([[math.atan2(y0[4], y0[3])], phi])
    return t, tau, phi


def test_tau_periods_agree_on_a_resonant_torus_and_t_periods_do_not() -> None:
    system, p = _params(BALL, "zero")
    q = 3

    def closing(M3: float) -> float:
        y0 = _vector(science.ball_state(0.0, M3, H, C, BALL), ("M", "gamma"))
        _, _, phi = _returns(system, p, y0, q, 60.0)
        return float(science.wrap(phi[q] - phi[0] - 2 * math.pi))

    M3 = brentq(closing, 1.40, 1.56, xtol=1e-15, rtol=1e-15)   # ν = 1/3 (bench: M3 ≈ 1.47997)
    assert abs(closing(M3)) < 1e-13
    start = science.ball_state(0.0, M3, H, C, BALL)
    F = float(np.dot(start["M"], start["M"]))

    def periods(F: float, M3_guess: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        T_t, T_tau, gaps = [], [], []
        for phi0 in (0.0, 1.5, -1.0):
            state = science.ball_on_torus(phi0, H, C, F, M3_guess, BALL)
            y0 = _vector(state, ("M", "gamma"))
            t, tau, phi = _returns(system, p, y0, q, 60.0)
            T_t.append(t[q] - t[0])
            T_tau.append(tau[q] - tau[0])
            gaps.append(abs(science.wrap(phi[q] - phi[0])))
        return np.array(T_t), np.array(T_tau), np.array(gaps)

    T_t, T_tau, gaps = periods(F, M3 + 0.1)
    assert np.all(gaps < 1e-12)                                  # every orbit on the torus closes after q returns
    assert np.ptp(T_tau) / np.mean(T_tau) < 1e-12                # equal periods in τ (bench: 4e-16)
    assert np.ptp(T_t) / np.mean(T_t) > 1e-6                     # different periods in t (bench: 3e-5)
    # A non-resonant torus: the orbits do not close and their q-return times differ in τ too.
    M3c = M3 - 0.2
    control = science.ball_state(0.0, M3c, H, C, BALL)
    Tc_t, Tc_tau, gaps_c = periods(float(np.dot(control["M"], control["M"])), M3c + 0.1)
    assert np.all(gaps_c[1:] > 1e-2)
    assert np.ptp(Tc_tau) / np.mean(Tc_tau) > 1e-3


def _section_rows(system, p, states: np.ndarray, t_final: float, surface: str, names: tuple[str, str]) -> list:
    sections = poincare.section_batch(system, p, states, t_final, surface, max_points=100_000)
    mats = [np.hstack([s.points[names[0]], s.points[names[1]]]) for s in sections]
    scale = np.std(np.concatenate(mats), axis=0)
    return [(science.neighbour_order(P, scale), science.roughness(P, scale)) for P in mats]


def test_section_measures_separate_the_integrable_ball_from_the_linear_field() -> None:
    rows = {}
    for potential, spec in (("zero", BALL), ("linear", science.BALL_LINEAR)):
        system, p = _params(spec, potential)
        states = sampling.on_level(system, p, {"energy": 0.5, "area": 0.0}, 4, 5)   # H = 0.5: all chaotic
        rows[potential] = _section_rows(system, p, states, 3000.0, "gamma3", ("M", "gamma"))
    assert all(order > 0.7 and rough < 0.1 for order, rough in rows["zero"]), rows["zero"]
    assert all(order < science.ORDER_REGULAR and rough > 0.4 for order, rough in rows["linear"]), rows["linear"]


def _growth(system, p, y0: np.ndarray, t_final: float) -> float:
    s = lyapunov.spectrum(system, p, y0, t_final, count=1, interval=5.0)
    return science.exponent_measures(s.convergence_t, s.convergence[:, 0], t_final)["growth"]


@pytest.mark.parametrize("theta, chaotic", [(0.4, False), (-0.336175219169 - 1e-4, True)])
def test_jacobi_problem_regular_orbit_and_chaotic_separatrix_layer(theta: float, chaotic: bool) -> None:
    system, p = _params(science.JACOBI, "zero")
    level = science.JACOBI_LEVEL
    state = science.jacobi_state(theta, 0.0, level["energy"], level["K"], science.JACOBI)
    y0 = _vector(state, ("x", "omega"))
    growth = _growth(system, p, y0, 4000.0)
    s = poincare.section(system, p, y0, 20_000.0, "x2", max_points=100_000)   # ~700 points (cheap)
    order = science.neighbour_order(np.hstack([s.points["x"], s.points["omega"]]))
    if chaotic:   # |v| grows exponentially (growth ~ 11 at t = 4000) and the points leave any curve
        assert growth > science.GROWTH_CHAOTIC and order < science.ORDER_REGULAR, (growth, order)
    else:         # |v| grows linearly and the points lie on a curve
        assert growth < 1.5 and order > 0.7, (growth, order)


def test_ball_separatrix_probe_is_regular() -> None:
    system, p = _params(BALL, "zero")
    # The separatrix on the line φ = π/2 of (H, c) = (2, 0) found by bench/science.py's bisection.
    M3 = -2.884441057592631 - 1e-4
    state = science.ball_state(math.pi / 2, M3, 2.0, 0.0, BALL)
    growth = _growth(system, p, _vector(state, ("M", "gamma")), 4000.0)
    assert growth < 1.5, growth
