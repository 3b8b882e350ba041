"""The rubber ball (eq. 2704-4 with E = γ): the Veselova system with I → J = I + D·1 (ERRATA 10)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import sympy as sp
from hypothesis import HealthCheck, given, settings, strategies as st
from scipy.integrate import solve_ivp

from nonholonomic import simulate
from nonholonomic.definition import InvariantMeasure, dot, symmetric_matrix_symbols, vector_symbols
from nonholonomic.evidence.measure import measure_evidence, pointwise_divergence_residual, symbolic_divergence_vanishes
from nonholonomic.initial_state import initial_state_problems
from nonholonomic.numerics.kernels import numeric, parameter_vector
from nonholonomic.systems import chaplygin_ball as cb, chaplygin_ball_veselova as bv, rubber_ball as rb, veselova

INERTIA = np.array([2.0, 3.0, 4.5])
D = 0.7
G0 = np.array([0.0, 0.6, 0.8])
W0 = np.array([0.5, -0.2, 0.15])  # (ω, γ) = 0
POTENTIALS = {"zero": {}, "linear": {"a": [0.3, -0.2, 0.5]}}


def run(potential: str, t_final: float, samples: int = 201, state=None, **kw):
    state = state or {"omega": W0, "gamma": G0}
    return simulate(rb.define(potential), {"inertia": INERTIA, "D": D, **POTENTIALS[potential]}, state, t_final,
                    samples, **kw)


def run_veselova_with_J(potential: str, t_final: float, samples: int = 201):
    return simulate(veselova.define(potential), {"inertia": INERTIA + D, **POTENTIALS[potential]},
                    {"omega": W0, "gamma": G0}, t_final, samples)


def reference_rhs(a=np.zeros(3)):
    """Eq. (2704-4) with E = γ in plain numpy, printed left-hand side I ω̇ + D γ×(ω̇×γ): solve
    [I + D(|γ|² − γ⊗γ), −γ; γᵀ, 0] (ω̇, μ) = (Iω×ω + γ×a, −(ω, γ×ω)) for (ω̇, μ)."""

    def f(t, y):
        w, g = y[:3], y[3:]
        A = np.zeros((4, 4))
        A[:3, :3] = np.diag(INERTIA) + D * (np.dot(g, g) * np.eye(3) - np.outer(g, g))
        A[:3, 3] = -g
        A[3, :3] = g
        rhs = np.append(np.cross(INERTIA * w, w) + np.cross(g, a), -np.dot(w, np.cross(g, w)))
        return np.concatenate([np.linalg.solve(A, rhs)[:3], np.cross(g, w)])

    return f


def veselova_with_J(expr: sp.Expr) -> sp.Expr:
    """A Veselova expression with I_k → I_k + D."""
    return expr.xreplace({veselova.I1: rb.I1 + rb.D, veselova.I2: rb.I2 + rb.D, veselova.I3: rb.I3 + rb.D})


# --- the definition ------------------------------------------------------------------------------

@pytest.mark.parametrize("potential", sorted(POTENTIALS))
def test_rhs_is_veselovas_with_I_replaced_by_J_on_all_of_R6(potential):
    # As rational functions (no |γ| = 1 used): the derived rubber-ball field is Veselova's with I → J.
    ours, theirs = rb.define(potential).rhs, veselova.define(potential).rhs
    for f, g in zip(ours, theirs):
        assert sp.expand(sp.numer(sp.together(f - veselova_with_J(g)))) == 0


def test_multiplier_is_derived_with_the_contact_inertia():
    # μ = −(n, I_Q⁻¹γ)/(γ, I_Q⁻¹γ), in the adjugate form the solver returns.
    n = rb.free_torque(sp.Integer(0))
    adj = cb.contact_inertia(rb.gamma).adjugate()
    expected = -dot(n, adj * rb.gamma) / dot(rb.gamma, adj * rb.gamma)
    assert sp.expand(sp.numer(sp.together(rb.constraint_multiplier(sp.Integer(0)) - expected))) == 0


def test_errata_10_contact_inertia_acts_on_the_acceleration():
    # I_Q ω̇ = J ω̇ − D(ω̇, γ)γ for every ω̇ (the printed "J ω − D(ω̇, γ)γ" is not), and Iω×ω = Jω×ω.
    w_dot = vector_symbols("wdot")
    IQ = cb.contact_inertia(rb.gamma)
    assert sp.expand(IQ * w_dot - (cb.J * w_dot - rb.D * dot(w_dot, rb.gamma) * rb.gamma)) == sp.zeros(3, 1)
    assert sp.expand(IQ * w_dot - (cb.J * rb.omega - rb.D * dot(w_dot, rb.gamma) * rb.gamma)) != sp.zeros(3, 1)
    assert sp.expand((rb.inertia * rb.omega).cross(rb.omega) - (cb.J * rb.omega).cross(rb.omega)) == sp.zeros(3, 1)
    # With (ω̇, γ) = 0 (the derived field, on all of R⁶) I_Q ω̇ = J ω̇.
    system = rb.define("linear")
    p = parameter_vector(system, {"inertia": INERTIA, "D": D, **POTENTIALS["linear"]})
    X = np.random.default_rng(2).normal(size=(20, 6))
    f = numeric(system).rhs(X, p)
    assert np.max(np.abs(np.einsum("ij,ij->i", f[:, :3], X[:, 3:]))) <= 1e-14


def test_generic_solver_is_the_same_for_E_equal_gamma():
    # The solver the ball with the Veselova constraint uses, with e = γ, is what defines this system.
    A, n = symmetric_matrix_symbols("A"), vector_symbols("n")
    w_dot, _ = bv.constrained_acceleration(A, n, rb.gamma)
    assert sp.expand(sp.numer(sp.together(dot(w_dot, rb.gamma)))) == 0


# --- trajectories: the Veselova system with I → J -------------------------------------------------

@pytest.mark.parametrize("potential,t_final", [("zero", 1000.0), ("linear", 100.0)])
def test_trajectory_and_reduced_time_equal_veselova_with_J(potential, t_final):
    # Measured: max |state difference| over 201 samples 6.0e-13 (U = 0, t = 1000) and 6.6e-14 (linear,
    # t = 100); the reduced times τ agree to 5.7e-13 and 1.8e-14. The linear field is chaotic: at
    # t = 1000 the two (equal) fields, compiled separately, part by 0.17, round-off amplified.
    ours, theirs = run(potential, t_final), run_veselova_with_J(potential, t_final)
    assert np.max(np.abs(ours.trajectory.states - theirs.trajectory.states)) <= 1e-10
    assert np.max(np.abs(ours.trajectory.tau - theirs.trajectory.tau)) <= 1e-10
    assert ours.trajectory.tau[-1] > 0.2 * t_final


def test_reduced_time_is_dt_over_rho_sqrt_det_J():
    result = run("linear", 10.0, samples=20001, checks=[])
    rho = numeric(result.system).density(result.trajectory.states, result.parameters)[:, 0]
    rate = 1 / (rho * np.sqrt(np.prod(INERTIA + D)))
    t = result.trajectory.t
    quadrature = np.concatenate([[0.0], np.cumsum((rate[1:] + rate[:-1]) / 2 * np.diff(t))])
    assert np.max(np.abs(result.trajectory.tau - quadrature)) <= 1e-8


@pytest.mark.parametrize("potential", sorted(POTENTIALS))
def test_every_integral_holds_to_1e_12_over_t_1000(potential):
    # Measured: every drift <= 5e-15.
    result = run(potential, 1000.0)
    expected = {"energy", "geometric", "constraint"} | ({"F"} if potential == "zero" else set())
    assert {i.name for i in result.integrals} == expected
    for item in result.integrals:
        assert item.max_rel_drift <= 1e-12, (item.name, item.max_rel_drift)
    assert all(c.passed for c in result.checks)


@pytest.mark.parametrize("potential", sorted(POTENTIALS))
def test_final_state_matches_independent_dop853(potential):
    # t = 100 (the linear case is chaotic at t = 1000, see above).
    f = reference_rhs(a=np.asarray(POTENTIALS[potential].get("a", np.zeros(3))))
    ref = solve_ivp(f, (0, 100.0), np.concatenate([W0, G0]), method="DOP853", rtol=1e-13, atol=1e-13)
    assert ref.success
    result = run(potential, 100.0, samples=2, checks=[])
    assert np.max(np.abs(result.trajectory.states[-1] - ref.y[:, -1])) <= 1e-9


# --- the measure ---------------------------------------------------------------------------------

@pytest.mark.parametrize("potential", sorted(POTENTIALS))
def test_density_is_proven_invariant(potential):
    proven, detail = symbolic_divergence_vanishes(rb.define(potential))
    assert proven is True, detail


def test_a_proof_past_max_proof_ops_is_undecided_naming_the_limit_and_the_pointwise_check_stays():
    """Decided by the bracket's size, not by seconds: not tried, in the same words on every call."""
    from nonholonomic.evidence.measure import divergence_bracket
    from nonholonomic.work_limits import WorkLimits, operations

    system = rb.define("zero")
    size = operations(divergence_bracket(system, system.measure.density))
    small = WorkLimits(max_proof_ops=size - 1)
    proven, detail = symbolic_divergence_vanishes(system, limits=small)
    assert proven is None
    assert detail == (f"div(rho f)/rho: the symbolic proof not tried: {size:,} operations > max {size - 1:,} "
                      "(max_proof_ops)")
    p = parameter_vector(system, {"inertia": INERTIA, "D": D})
    symbolic, pointwise = measure_evidence(system, p, run("zero", 5.0, samples=40, checks=[]).trajectory.states,
                                           limits=small)
    assert symbolic.passed is None and symbolic.detail.startswith(detail)
    assert pointwise.passed is True


def test_density_is_the_balls_density_at_E_equal_gamma_over_sqrt_det_J():
    # (γ, adj(I_Q) γ) = det J (γ, J⁻¹γ) identically: eq. (2704-5) at E = γ is √det J · ρ.
    ball_density_sq = bv.measure_density(rb.gamma, rb.gamma) ** 2
    assert sp.expand(sp.numer(sp.together(ball_density_sq - cb.det_J * rb.measure_density() ** 2))) == 0


@pytest.mark.parametrize("name,wrong_density", [
    ("(gamma, I^-1 gamma)^(1/2)", veselova.measure_density(rb.gamma, sp.diag(1 / rb.I1, 1 / rb.I2, 1 / rb.I3))),
    ("(gamma, J gamma)^(1/2)", sp.sqrt(dot(rb.gamma, cb.J * rb.gamma))),
])
def test_a_wrong_density_fails_both_measure_checks(name, wrong_density):
    right = rb.define("zero")
    wrong = dataclasses.replace(right, measure=InvariantMeasure(wrong_density, name, "test"))
    p = parameter_vector(right, {"inertia": INERTIA, "D": D})
    states = run("zero", 5.0, samples=40, checks=[]).trajectory.states
    symbolic, pointwise = measure_evidence(wrong, p, states)
    assert symbolic.passed is False and pointwise.passed is False and pointwise.residual > 1e-3
    assert pointwise_divergence_residual(right, p, states) <= 1e-13


# --- the initial state ---------------------------------------------------------------------------

def test_off_constraint_states_are_refused_or_projected():
    off = {"omega": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.9]}
    problems = initial_state_problems(rb.define(), {"inertia": INERTIA, "D": D}, off)
    assert {p.field for p in problems} == {"initial_state.gamma", "initial_state.omega"}
    result = run("zero", 10.0, state=off, project=True)
    assert [r.field for r in result.projections] == ["initial_state.gamma", "initial_state.omega"]
    g, w = result.state("gamma")[0], result.state("omega")[0]
    assert abs(np.linalg.norm(g) - 1) <= 1e-15 and abs(np.dot(w, g)) <= 1e-16
    assert all(i.max_rel_drift <= 1e-13 for i in result.integrals)


def test_example_is_admissible():
    example = rb.EXAMPLE
    assert initial_state_problems(rb.define(), {"inertia": example["system"]["inertia"], "D": example["system"]["D"]},
                                  example["initial_state"]) == []


# --- properties ----------------------------------------------------------------------------------

moment = st.floats(0.2, 5.0)
component = st.one_of(st.just(0.0), st.floats(1e-6, 1.0), st.floats(-1.0, -1e-6))
vector = st.tuples(component, component, component)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(inertia=st.tuples(moment, moment, moment), d=st.one_of(st.just(0.0), st.floats(1e-6, 3.0)), w=vector,
       g=vector.filter(lambda v: np.linalg.norm(v) > 0.1), a=vector, potential=st.sampled_from(sorted(POTENTIALS)))
def test_property_integrals_and_measure_hold(inertia, d, w, g, a, potential):
    gamma = np.asarray(g) / np.linalg.norm(g)
    omega = np.asarray(w) - np.dot(w, gamma) * gamma
    system = rb.define(potential)
    pars = {"inertia": inertia, "D": d, **({"a": a} if potential == "linear" else {})}
    result = simulate(system, pars, {"omega": omega, "gamma": gamma}, 100.0, 101, checks=["integrals"])
    for item in result.integrals:
        assert item.max_rel_drift <= 1e-12, (item.name, item.max_rel_drift)
    assert pointwise_divergence_residual(system, result.parameters, result.trajectory.states) <= 1e-12
