"""A Lagrangian system reduced to a generalized Chaplygin system (eq. 2704-7) and Theorem 1 applied
(nonholonomic.lagrangian.chaplygin): the reduced field against the Lagrange–d'Alembert equations, the
reducing multiplier against the measure search, the two integrations against each other, the Hamiltonian
form along a trajectory, Chaplygin's sleigh (a Chaplygin system without a measure unless a = 0), and
the refusals."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import sympy as sp

from nonholonomic.hamiltonization.forms import flow_residual
from nonholonomic.lagrangian import derive, parse_system
from nonholonomic.lagrangian.chaplygin import chaplygin_reduction
from nonholonomic.lagrangian.measure_search import measure_verdict
from nonholonomic.numerics.integration import integrate
from nonholonomic.systems import generalized_chaplygin as gc, lagrangian as lagrangian_kind
from tests.lagrangian_examples import PARTICLE, SLEIGH

#: The nonholonomic particle in a harmonic field in x, y only (z cyclic).
CYCLIC_PARTICLE = {"kind": "lagrangian", "coordinates": ["x", "y", "z"],
                   "L": "(x_dot**2 + y_dot**2 + z_dot**2)/2 - k*(x**2 + y**2)/2",
                   "constraints": ["z_dot - y*x_dot"], "parameters": {"k": 0.8}}
#: A term linear in the velocities (c x z_dot) and a mass matrix depending on y: b != 0 in S.
GYROSCOPIC = {"kind": "lagrangian", "coordinates": ["x", "y", "z"],
              "L": "(x_dot**2 + (1 + y**2)*y_dot**2 + z_dot**2)/2 + c*x*z_dot + x_dot*y_dot/3 - y**2/2",
              "constraints": ["z_dot - sin(y)*x_dot - x*y_dot"], "parameters": {"c": 0.7}}
#: Two cyclic coordinates (z, w): two terms in S with opposite κ.
TWO_CYCLIC = {"kind": "lagrangian", "coordinates": ["x", "y", "z", "w"],
              "L": "(x_dot**2 + y_dot**2 + z_dot**2 + 2*w_dot**2)/2 - x**2/2",
              "constraints": ["z_dot - y*x_dot", "w_dot - x*y_dot"]}
SYMBOLS = {name: sp.Symbol(name, real=True) for name in ("x", "y", "theta", "k", "m", "a", "J")}


def restricted_difference(spec, at_values: bool = False):
    """(reduction, reduced q̈ − Lagrange–d'Alembert q̈ restricted to the manifold, shape components)."""
    data = parse_system(spec)
    red = chaplygin_reduction(data, at_values=at_values)
    assert red.reduced, red.reason
    eqs = derive(data)
    on = dict(red.dependent)
    acc = gc.accelerations(red.data)
    return red, [acc[j] - eqs.qddot[i].xreplace(on) for j, i in enumerate(red.shape)], data


def assert_zero_pointwise(exprs, data, red, tolerance=1e-12, seed=3):
    """Each expression (a function of the shape state and the parameters) ≤ tolerance × (1 + size of q̈)
    at 20 random states."""
    shape = [data.q[i] for i in red.shape] + [data.v[i] for i in red.shape]
    pars = data.parameter_values
    fn = sp.lambdify(shape, [e.xreplace(pars) for e in exprs], "numpy")
    scale = sp.lambdify(shape, [a.xreplace(pars) for a in gc.accelerations(red.data)], "numpy")
    rng = np.random.default_rng(seed)
    for _ in range(20):
        x = rng.uniform(0.1, 1.2, 4) * rng.choice([-1, 1], 4)
        assert np.max(np.abs(fn(*x))) <= tolerance * (1 + np.max(np.abs(scale(*x))))


# --- the particle ----------------------------------------------------------------------------------

def test_particle_reduces_with_a1_equal_y_and_its_field_is_lagrange_dalembert():
    red, diff, data = restricted_difference(CYCLIC_PARTICLE)
    x, y, k = SYMBOLS["x"], SYMBOLS["y"], SYMBOLS["k"]
    assert [str(data.q[i]) for i in red.shape] == ["x", "y"]
    assert [(str(s), sp.sstr(e)) for s, e in red.dependent] == [("z_dot", "x_dot*y")]
    # S = (∂L/∂ż)|* κ, κ = ∂β₁/∂y − ∂β₂/∂x = 1, ∂L/∂ż = ż = y ẋ: a₁ = y, a₂ = b = 0
    assert (red.data.a1, red.data.a2, red.data.b) == (y, 0, 0)
    assert sp.simplify(red.data.U - k * (x**2 + y**2) / 2) == 0
    assert red.values == (0.8,)
    assert all(sp.simplify(d) == 0 for d in diff)
    assert_zero_pointwise(diff, data, red)
    # the control: the opposite sign of S (the brief's "−Σ_α ...") is the wrong field
    flipped = gc.accelerations(dataclasses.replace(red.data, a1=-red.data.a1))
    eqs = derive(data)
    on = dict(red.dependent)
    assert sp.simplify(flipped[0] - eqs.qddot[0].xreplace(on)) != 0


@pytest.mark.parametrize("spec", [GYROSCOPIC, TWO_CYCLIC], ids=["linear_terms", "two_cyclic"])
def test_linear_terms_and_two_cyclic_coordinates_give_lagrange_dalembert(spec):
    red, diff, data = restricted_difference(spec)
    if spec is GYROSCOPIC:  # b = c x κ, κ = ∂β_z1/∂y − ∂β_z2/∂x = cos y − 1
        x, y = SYMBOLS["x"], SYMBOLS["y"]
        assert sp.simplify(red.data.b - sp.Symbol("c", real=True) * x * (sp.cos(y) - 1)) == 0
    else:  # κ_z = 1, κ_w = −1: S = ż − 2ẇ = y ẋ − 2 x ẏ
        assert (red.data.a1, red.data.a2) == (SYMBOLS["y"], -2 * SYMBOLS["x"])
    assert_zero_pointwise(diff, data, red)


def test_particle_theorem_1_multiplier_and_the_measure_search_agree():
    """Theorem 1: N = ρ = 1/√(1 + y²) (ρ dP dq); in (q, q̇), dP = det G* dq̇ gives ρ det G* = √(1 + y²),
    which is measure_verdict's density ρ(q, s) dq ds du (u = q̇ the shape velocities): the same up to a
    constant factor."""
    data = parse_system(CYCLIC_PARTICLE)
    red = chaplygin_reduction(data)
    system = gc.define(red.data)
    y = SYMBOLS["y"]
    N = system.reduced_time.density
    assert sp.simplify(N * sp.sqrt(1 + y**2)).is_number
    detG = sp.hessian(red.data.L - red.data.U, red.data.v).det()
    verdict = measure_verdict(data)
    assert verdict.status == "found", verdict.reason
    assert [str(u) for u in verdict.velocities] == ["x_dot", "y_dot"]
    assert sp.simplify(verdict.density / (N * detG)).is_number
    assert sp.simplify(system.measure.density - N * detG) == 0
    assert system.hamiltonian_form is not None and system.hamiltonian_form.proof[0] is True


def test_particle_reduced_and_full_integrations_agree_and_the_form_is_hamiltonian():
    data = parse_system(CYCLIC_PARTICLE)
    red = chaplygin_reduction(data)
    reduced = gc.define(red.data)
    full = lagrangian_kind.define(data)
    y0 = np.array([0.3, 0.5, -0.2, 0.8, -0.4, 0.5 * 0.8])  # z_dot = y x_dot
    p = np.array(red.values)
    one = integrate(full, np.array(data.values), y0, 20.0, 41)
    two = integrate(reduced, p, red.reduced_state(y0), 20.0, 41)
    assert np.max(np.abs(red.reduced_state(one.states) - two.states)) <= 1e-9
    assert np.max(np.abs(red.reduced_state(one.states[-1]) - two.states[-1])) <= 1e-9
    assert np.ptp(red.reduced_state(one.states)[:, 0]) > 0.5  # it moves
    # τ = ∫ N dt, N = 1/√(1 + y²) (trapezoid on the samples, step 0.5)
    N = 1 / np.sqrt(1 + two.states[:, 1] ** 2)
    tau = np.concatenate([[0.0], np.cumsum((N[1:] + N[:-1]) / 2 * np.diff(two.t))])
    assert abs(two.tau[-1] - tau[-1]) <= 0.02 * tau[-1]
    form = reduced.hamiltonian_form
    assert flow_residual(form, reduced, two.states, p) <= 1e-10
    assert flow_residual(form, reduced, two.states, p, time="t") > 1e-3  # in t it is not Hamiltonian


# --- Chaplygin's sleigh ----------------------------------------------------------------------------

def test_sleigh_is_chaplygin_in_x_theta_and_theorem_1_finds_no_measure():
    """y cyclic (L = L(θ, velocities), ẏ = tan θ ẋ): shape (x, θ), L* = m ẋ²/(2 cos²θ) + (J + m a²) θ̇²/2,
    S = m sec²θ (tan θ ẋ + a cos θ θ̇). A₁ = tan θ, A₂ = m a/((J + m a²) cos θ): dA₁/dx + dA₂/dθ =
    m a sin θ/((J + m a²) cos²θ) ≠ 0, so no ρ(q) (as measure_verdict's obstruction a m sin θ/(J + m a²))."""
    red, diff, data = restricted_difference(SLEIGH)
    m, a, J, theta = (SYMBOLS[s] for s in ("m", "a", "J", "theta"))
    assert [str(data.q[i]) for i in red.shape] == ["x", "theta"]
    assert sp.simplify(red.dependent[0][1] - sp.tan(theta) * data.v[0]) == 0
    x_dot, theta_dot = red.data.v
    L_star = m * x_dot**2 / (2 * sp.cos(theta) ** 2) + (J + m * a**2) * theta_dot**2 / 2
    assert sp.simplify(red.data.L - L_star) == 0 and red.data.U == 0
    assert sp.simplify(red.data.a1 - m * sp.sin(theta) / sp.cos(theta) ** 3) == 0
    assert sp.simplify(red.data.a2 - m * a / sp.cos(theta)) == 0 and red.data.b == 0
    assert all(sp.simplify(d) == 0 for d in diff)
    assert_zero_pointwise(diff, data, red)
    system = gc.define(red.data)
    assert system.hamiltonian_form is None and system.reduced_time is None
    assert "integrability condition" in system.measure.formula and "fails" in system.measure.formula
    assert measure_verdict(data).status == "none"
    # the reduced sleigh in t rolls as the full one (θ̇ dies out: the rotation stops)
    full = lagrangian_kind.define(data)
    y0 = np.array([0.2, -0.1, 0.3, 0.9, 0.9 * np.tan(0.3), 0.7])
    one = integrate(full, np.array(data.values), y0, 20.0, 21)
    two = integrate(system, np.array(red.values), red.reduced_state(y0), 20.0, 21)
    assert np.max(np.abs(red.reduced_state(one.states) - two.states)) <= 1e-9
    assert two.tau is None


def test_sleigh_with_the_edge_at_the_centre_of_mass_has_n_cos_theta():
    """a = 0 at the values: A₂ = 0, ∂ ln ρ/∂θ = −tan θ, N = cos θ; ρ det G* = cos θ · m J / cos²θ ∝
    1/cos θ = measure_verdict's density. With a symbolic, Theorem 1 decides for generic a (no measure)."""
    spec = dict(SLEIGH, parameters={"m": 1.3, "a": 0.0, "J": 0.25})
    red, diff, data = restricted_difference(spec, at_values=True)
    assert red.data.parameters == () and red.values == ()
    assert all(sp.simplify(d.xreplace({SYMBOLS["a"]: 0})) == 0 for d in diff)
    theta = SYMBOLS["theta"]
    system = gc.define(red.data)
    N = system.reduced_time.density  # √(1 − sin θ) √(1 + sin θ) = cos θ on |θ| < π/2
    ratio = sp.lambdify(theta, N / sp.cos(theta), "numpy")(np.linspace(-1.5, 1.5, 31))
    assert np.ptp(ratio) <= 1e-13 * abs(ratio[0]) and abs(ratio[0]) > 0
    detG = sp.hessian(red.data.L - red.data.U, red.data.v).det()
    verdict = measure_verdict(data)
    assert verdict.status == "found", verdict.reason
    ratio = sp.lambdify(theta, verdict.density / (N * detG), "numpy")(np.linspace(-1.5, 1.5, 31))
    assert np.ptp(ratio) <= 1e-12 * abs(ratio[0]) and abs(ratio[0]) > 0  # 1/(m J) = 40/13
    assert abs(ratio[0] - 1 / (1.3 * 0.25)) <= 1e-12
    generic = gc.define(chaplygin_reduction(data).data)
    assert generic.reduced_time is None


# --- refusals --------------------------------------------------------------------------------------

@pytest.mark.parametrize("spec, words", [
    ({"kind": "lagrangian", "coordinates": ["x", "y", "z", "w"],
      "L": "(x_dot**2 + y_dot**2 + z_dot**2 + w_dot**2)/2", "constraints": ["z_dot - y*x_dot"]},
     ["3 independent velocities"]),
    ({"kind": "lagrangian", "coordinates": ["x", "y"], "L": "(x_dot**2 + y_dot**2)/2",
      "constraints": ["y_dot - x*x_dot"]}, ["1 independent velocity"]),
    (PARTICLE, ["L depends on the dependent coordinate z", "L depends on the dependent coordinate x",
                "cannot be solved for y_dot"]),
    (dict(CYCLIC_PARTICLE, constraints=["z_dot - z*x_dot"]),
     ["the constraint coefficients depend on z", "L depends on the dependent coordinate x"]),
    (dict(CYCLIC_PARTICLE, L="(x_dot**2 + y_dot**2 + z_dot**2)/2 - k*t*x**2"), ["depends on the time t"]),
], ids=["three", "one", "potential_in_z", "coefficients_in_z", "time"])
def test_refusals_say_why(spec, words):
    red = chaplygin_reduction(parse_system(spec))
    assert not red.reduced and red.data is None
    for word in words:
        assert word in red.reason, red.reason
