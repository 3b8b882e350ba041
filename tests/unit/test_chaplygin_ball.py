"""Chaplygin's ball (eq. 2604-1..5): the definition, the integrator and the evidence."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import sympy as sp

from nonholonomic import get_system, simulate
from nonholonomic.definition import InvariantMeasure
from nonholonomic.evidence.integrals import integral_evidence
from nonholonomic.evidence.measure import measure_evidence, pointwise_divergence_residual, symbolic_divergence_vanishes
from nonholonomic.numerics.integration import MACHINE_EPSILON, StepRecorder, integrate
from nonholonomic.numerics.kernels import numeric, parameter_vector
from nonholonomic.systems import chaplygin_ball as ball
from tests.reference import ball_reference

INERTIA = np.array([2.0, 3.0, 4.5])
D = 0.7
M0 = np.array([0.5, -0.2, 0.1])
G0 = np.array([0.0, 0.6, 0.8])
POTENTIALS = {"zero": {}, "linear": {"a": [0.3, -0.2, 0.5]}, "brun": {"k": 0.4}}


def run(potential: str, t_final: float, samples: int = 201, **kw):
    params = {"inertia": INERTIA, "D": D, **POTENTIALS[potential]}
    return simulate(get_system("chaplygin_ball", potential), params, {"M": M0, "gamma": G0}, t_final, samples, **kw)


# --- the symbolic definition -------------------------------------------------------------------

def test_sherman_morrison_inverse_and_determinant_lemma_hold_for_any_gamma():
    IQ = ball.contact_inertia()
    assert sp.simplify(ball.contact_inertia_inverse() * IQ - sp.eye(3)) == sp.zeros(3, 3)
    assert sp.cancel(IQ.det() - ball.contact_inertia_determinant()) == 0


def test_contact_inertia_is_the_angular_momentum_about_the_contact_point_on_the_unit_sphere():
    # M = I ω + D γ × (ω × γ) (eq. 2604-1) equals I_Q ω = (J − D γ⊗γ) ω when |γ| = 1.
    rng = np.random.default_rng(1)
    for _ in range(5):
        g = rng.normal(size=3)
        g /= np.linalg.norm(g)
        w = rng.normal(size=3)
        M = INERTIA * w + D * np.cross(g, np.cross(w, g))
        IQ = np.diag(INERTIA + D) - D * np.outer(g, g)
        assert np.allclose(M, IQ @ w, rtol=0, atol=1e-14)


# --- integrals and accuracy ----------------------------------------------------------------------

@pytest.mark.parametrize("potential", sorted(POTENTIALS))
def test_every_integral_holds_to_1e_12_over_t_1000(potential):
    result = run(potential, 1000.0)
    names = {i.name for i in result.integrals}
    assert names == ({"energy", "geometric", "area", "F"} if potential == "zero" else {"energy", "geometric", "area"})
    for item in result.integrals:
        assert item.max_rel_drift <= 1e-12, (item.name, item.max_rel_drift)
        assert item.passed
        assert item.evaluated_at == 201 + result.trajectory.step_states.shape[0]
    assert result.trajectory.tolerance == MACHINE_EPSILON


@pytest.mark.parametrize("potential,t_final", [("zero", 1000.0), ("brun", 1000.0), ("linear", 100.0)])
def test_final_state_matches_independent_dop853(potential, t_final):
    # The linear field is chaotic: two 1e-13 integrations part by O(1) before t = 1000, so it is
    # compared at t = 100, where both agree to ~1e-11.
    result = run(potential, t_final, samples=2)
    pars = POTENTIALS[potential]
    ref = ball_reference(INERTIA, D, np.concatenate([M0, G0]), t_final, a=pars.get("a"), k=pars.get("k", 0.0))
    assert np.max(np.abs(result.trajectory.states[-1] - ref)) <= 1e-9


def test_scipy_engine_agrees_with_heyoka():
    a = run("zero", 50.0, samples=11)
    b = run("zero", 50.0, samples=11, engine="scipy", tolerance=1e-13)
    assert b.trajectory.engine == "scipy"
    assert np.max(np.abs(a.trajectory.states - b.trajectory.states)) <= 1e-10
    assert np.max(np.abs(a.trajectory.tau - b.trajectory.tau)) <= 1e-10


def test_reduced_time_is_the_integral_of_rho_mu():
    result = run("linear", 10.0, samples=20001)
    rho = numeric(result.system).density(result.trajectory.states, result.parameters)[:, 0]
    t = result.trajectory.t
    quadrature = np.concatenate([[0.0], np.cumsum((rho[1:] + rho[:-1]) / 2 * np.diff(t))])
    assert np.max(np.abs(result.trajectory.tau - quadrature)) <= 1e-7
    assert result.trajectory.tau[0] == 0.0


def test_omega_input_is_converted_with_the_contact_inertia():
    w = np.array([0.3, -0.1, 0.2])
    IQ = np.diag(INERTIA + D) - D * np.outer(G0, G0)
    result = simulate(get_system("chaplygin_ball"), {"inertia": INERTIA, "D": D}, {"omega": w, "gamma": G0}, 1.0, 2)
    assert np.allclose(result.state("M")[0], IQ @ w, atol=1e-15)
    assert np.allclose(result.state("omega")[0], w, atol=1e-14)


def test_samples_are_at_the_requested_times():
    result = run("zero", 7.5, samples=4)
    assert result.trajectory.t.tolist() == [0.0, 2.5, 5.0, 7.5]
    assert np.allclose(result.trajectory.states[0], np.concatenate([M0, G0]), rtol=0, atol=0)


def test_step_recorder_thins_evenly_when_full():
    rec = StepRecorder(capacity=8)
    for i in range(100):
        rec.add(float(i), np.array([i]))
    assert len(rec.t) < 8 and rec.stride == 16
    assert np.all(np.diff(rec.t) == rec.stride)


# --- the evidence must be able to fail -----------------------------------------------------------

@pytest.mark.parametrize("potential", sorted(POTENTIALS))
def test_chaplygin_density_is_proven_invariant(potential):
    proven, detail = symbolic_divergence_vanishes(get_system("chaplygin_ball", potential))
    assert proven is True, detail


@pytest.mark.parametrize("wrong_density", [sp.Integer(1), sp.sqrt(ball.contact_inertia_determinant())])
def test_a_wrong_density_fails_both_measure_checks(wrong_density):
    right = get_system("chaplygin_ball", "linear")
    wrong = dataclasses.replace(right, measure=InvariantMeasure(wrong_density, "wrong", "test"))
    p = parameter_vector(right, {"inertia": INERTIA, "D": D, "a": [0.3, -0.2, 0.5]})
    states = run("linear", 5.0, samples=50).trajectory.states
    symbolic, pointwise = measure_evidence(wrong, p, states)
    assert symbolic.passed is False
    assert pointwise.passed is False and pointwise.residual > 1e-3
    assert pointwise_divergence_residual(right, p, states) <= 1e-13


def test_a_wrong_right_hand_side_breaks_the_energy_integral():
    # Flip the sign of the potential's torque γ × ∂U/∂γ in dM/dt.
    right = get_system("chaplygin_ball", "linear")
    a = sp.Matrix(sp.symbols("a1:4", real=True))
    torque = ball.gamma.cross(a)
    wrong_rhs = tuple(right.rhs[i] - 2 * torque[i] for i in range(3)) + right.rhs[3:]
    wrong = dataclasses.replace(right, rhs=wrong_rhs)
    p = parameter_vector(right, {"inertia": INERTIA, "D": D, "a": [0.3, -0.2, 0.5]})
    traj = integrate(wrong, p, np.concatenate([M0, G0]), 20.0, 101)
    energy = {i.name: i for i in integral_evidence(wrong, p, traj)}["energy"]
    assert not energy.passed and energy.max_rel_drift > 1e-3
    traj_right = integrate(right, p, np.concatenate([M0, G0]), 20.0, 101)
    assert {i.name: i for i in integral_evidence(right, p, traj_right)}["energy"].passed


def test_measure_evidence_names_formula_equation_and_method():
    result = run("zero", 10.0)
    methods = {c.method: c for c in result.checks}
    assert set(methods) == {"symbolic", "pointwise"}
    for check in result.checks:
        assert check.equation == "2604-3" and "det(I_Q)^(-1/2)" in check.formula and check.passed
    assert methods["pointwise"].residual <= 1e-13
