"""The ball rolling on a surface of the user's own (eq. 2804-1..3, ERRATA 11-13): a sphere against a
closed form derived here, the torus (a quartic), a quadric against the kind ball_on_quadric, the
projection onto Φ = 0 and the refusals."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import sympy as sp

from nonholonomic import simulate
from nonholonomic.definition import InvariantMeasure
from nonholonomic.evidence.measure import pointwise_divergence_residual, symbolic_divergence_vanishes
from nonholonomic.expressions import ExpressionError
from nonholonomic.initial_state import initial_state_problems, project_initial_state
from nonholonomic.numerics.integration import integrate
from nonholonomic.numerics.kernels import numeric, parameter_vector, state_vector
from nonholonomic.systems import ball_on_quadric as bq, ball_on_surface as bs, get_system

D0, M, R = 0.036, 1.0, 0.3
BALL = {"D0": D0, "m": M, "R": R}
SPHERE = bs.surface("x1**2 + x2**2 + x3**2 - rho**2", ("rho",))
TORUS = bs.DEFAULT_SURFACE
TORUS_PARAMETERS = {"a0": 2.0, "r0": 1.0}


def rotate(v: np.ndarray, axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues: ``v`` turned by ``angle`` (one per row) about the unit ``axis``."""
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return v * c + np.cross(axis, v) * s + np.outer(1 - c[:, 0], axis) * (axis @ v)


def sphere_closed_form(t: np.ndarray, rho: float, x0: np.ndarray, w0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ball on the sphere |x| = ρ with U = 0, solved by hand.

    n = x/ρ, so dn/dt = (R/ρ) ω × n, and (D₀ + D) dω/dt = D (ω, n) dn/dt (eq. 2804-1). Then
    d/dt (ω, n) = (ω, dn/dt) = 0: c = (ω, n) is constant, and ω − k n = W is constant with
    k = D c/(D₀ + D). So dn/dt = (R/ρ) W × n: n turns uniformly about W at the rate (R/ρ)|W|, and
    ω = W + k n, x = ρ n.
    """
    D = M * R**2
    n0 = x0 / rho
    k = D * (w0 @ n0) / (D0 + D)
    W = w0 - k * n0
    n = rotate(n0, W / np.linalg.norm(W), R / rho * np.linalg.norm(W) * t)
    return rho * n, W + k * n


def test_the_sphere_follows_the_closed_form():
    rho = 2.0
    x0 = rho * np.array([0.48, 0.6, 0.64])
    w0 = np.array([1.2, -0.8, 2.0])
    system = get_system(bs.KIND, "zero", SPHERE)
    result = simulate(system, {**BALL, "rho": rho}, {"x": x0, "omega": w0}, 200.0, 401)
    t = result.trajectory.t
    x, w = sphere_closed_form(t, rho, x0, w0)
    # A turn takes 2π ρ/(R |W|) ≈ 19 s: ten turns, to the integrator's accuracy.
    assert np.max(np.abs(result.state("x") - x)) < 1e-10
    assert np.max(np.abs(result.state("omega") - w)) < 1e-10
    assert all(i.passed for i in result.integrals) and all(c.passed for c in result.checks)
    # The closed form is not the trivial motion: (ω, n) ≠ 0 and n sweeps a cone.
    assert abs(w0 @ x0 / rho) > 0.5 and np.ptp(x[:, 0]) > 1.0


def test_the_torus_conserves_phi_and_the_energy_and_the_measure_is_proven():
    system = get_system(bs.KIND, "linear", TORUS)
    parameters = {**BALL, **TORUS_PARAMETERS, "a": [0.0, 0.0, 9.81]}  # gravity along x3
    result = simulate(system, parameters, bs.EXAMPLE["initial_state"], 100.0, 201)
    drift = {i.name: i.max_rel_drift for i in result.integrals}
    assert drift["surface"] < 1e-12 and drift["energy"] < 1e-12, drift
    x = result.state("x")
    assert np.ptp(x[:, 2]) > 0.1 and np.ptp(np.hypot(x[:, 0], x[:, 1])) > 0.1  # it rolls over the tube
    checks = {c.method: c for c in result.checks if c.name == "invariant_measure"}
    assert checks["symbolic"].passed is True
    assert checks["pointwise"].passed and checks["pointwise"].residual < 1e-12
    # The checks can fail: density 1 or |∇Φ|² is not invariant, the printed torque +R breaks the energy.
    p = parameter_vector(system, parameters)
    states = np.hstack([result.state("x"), result.state("omega")])[::10]
    g = bs.gradient_norm(TORUS.Phi)
    for wrong in (sp.Integer(1), g**2):
        other = dataclasses.replace(system, measure=InvariantMeasure(wrong, "wrong", "-"))
        assert pointwise_divergence_residual(other, p, states) > 1e-3
    U = (system.parameters[-1].symbols[2]) * bs.x[2]
    printed = dataclasses.replace(system, rhs=bs.equations_of_motion(TORUS.Phi, U, torque=+R))
    wrong = integrate(printed, p, state_vector(system, bs.EXAMPLE["initial_state"], p), 20.0, 101)
    energy = numeric(system).integrals(wrong.states, p)[:, 1]
    assert np.ptp(energy) > 1e-3 * abs(energy[0])


@pytest.mark.parametrize("potential", ["zero", "harmonic"])
def test_a_quadric_written_as_phi_rolls_as_the_kind_ball_on_quadric(potential):
    B = np.array([[2.0, 0.3, -0.2], [0.3, 1.5, 0.4], [-0.2, 0.4, 1.0]])
    A = np.linalg.inv(B)
    names = ("A11", "A12", "A13", "A22", "A23", "A33")
    quadric = bs.surface("A11*x1**2 + A22*x2**2 + A33*x3**2 + 2*(A12*x1*x2 + A13*x1*x3 + A23*x2*x3) - 1",
                         tuple(sorted(names)))
    entries = dict(zip(names, (A[0, 0], A[0, 1], A[0, 2], A[1, 1], A[1, 2], A[2, 2])))
    extra = {"k": 0.5} if potential == "harmonic" else {}
    direction = np.array([0.5, 0.6, 0.7])
    x0 = direction / np.sqrt(direction @ A @ direction)
    state = {"x": x0, "omega": [1.2, -0.8, 2.0]}
    mine = simulate(get_system(bs.KIND, potential, quadric), {**BALL, **entries, **extra}, state, 100.0, 201)
    theirs = simulate(bq.define(potential), {**BALL, "B": B, **extra}, state, 100.0, 201)
    for name in ("x", "omega"):
        assert np.max(np.abs(mine.state(name) - theirs.state(name))) < 1e-9
    # Along this kind's trajectory, the quadric's Joachimsthal-like K (eq. 2804-4) is conserved too.
    K = {i.name: i for i in theirs.integrals}["K"]
    p = parameter_vector(bq.define(potential), {**BALL, "B": B, **extra})
    k_index = [i.name for i in bq.define(potential).integrals].index("K")
    states = np.hstack([mine.state("x"), mine.state("omega")])
    values = numeric(bq.define(potential)).integrals(states, p)[:, k_index]
    assert np.ptp(values) < 1e-11 * max(1.0, abs(K.initial))


def test_an_initial_x_off_the_surface_is_refused_or_projected_by_newton():
    system = get_system(bs.KIND, "zero", TORUS)
    parameters = {**BALL, **TORUS_PARAMETERS}
    off = {"x": [3.1, 0.2, 0.3], "omega": [0.5, 2.0, 0.3]}
    problems = initial_state_problems(system, parameters, off)
    assert [p.field for p in problems] == ["initial_state.x"] and "project_initial_state" in problems[0].reason
    assert initial_state_problems(system, parameters, off, project=True) == []
    p = parameter_vector(system, parameters)
    y, reports = project_initial_state(system, p, state_vector(system, off, p))
    x = y[:3]
    assert abs((x[0] ** 2 + x[1] ** 2 + x[2] ** 2 + 3) ** 2 - 16 * (x[0] ** 2 + x[1] ** 2)) < 1e-11
    assert np.linalg.norm(x - off["x"][:3]) < 0.2 and y[3:].tolist() == off["omega"]
    assert reports[0].field == "initial_state.x" and abs(reports[0].value_before) > 1 and reports[0].value_after == \
        pytest.approx(0, abs=1e-11)
    result = simulate(system, parameters, off, 10.0, 11, project=True)
    assert result.projections and all(i.passed for i in result.integrals)


@pytest.mark.parametrize(("text", "parameters", "reason"), [
    ("x1^2 + x2**2 - 1", (), "use \\*\\* for powers"),
    ("abs(x1) + x2**2 - 1", (), "abs\\(\\) is not smooth"),
    ("q - 1", ("q",), "does not depend on x1, x2, x3"),
    ("x1**2 - x1", ("x1",), "is a component of x"),
    ("x1**q - 1", ("q",), "rational number"),
    ("__import__('os')", (), "not allowed"),
])
def test_surfaces_that_are_not_smooth_expressions_of_x_are_refused(text, parameters, reason):
    with pytest.raises(ExpressionError, match=reason):
        bs.surface(text, parameters)


def test_the_torus_measure_proof_and_the_field_are_those_of_the_quadric_form():
    # The surface enters only through n = ∇Φ/|∇Φ|: for Φ = (x, A x) − 1 written by hand, the field is
    # that of ball_on_quadric with the same A, symbol for symbol.
    A = bq.A
    Phi = (bs.x.T * A * bs.x)[0] - 1
    mine = bs.equations_of_motion(Phi, sp.Integer(0))
    theirs = bq.equations_of_motion(sp.Integer(0))
    assert all(sp.simplify(a - b) == 0 for a, b in zip(mine[:3], theirs[:3]))
    point = {s: v for s, v in zip([*bs.x, *bs.omega, *A.free_symbols, bq.D0, bq.m, bq.R],
                                  [0.3, -0.2, 0.5, 1.0, 0.4, -0.7, *np.linspace(0.5, 1.5, len(A.free_symbols)),
                                   0.036, 1.0, 0.3])}
    assert all(abs(float((a - b).subs(point))) < 1e-12 for a, b in zip(mine, theirs))
    assert symbolic_divergence_vanishes(get_system(bs.KIND, "zero", SPHERE))[0] is True
