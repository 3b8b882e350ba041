"""The invariant-measure search for a user's Lagrangian system (nonholonomic.lagrangian.measure_search): the
nonholonomic particle has √(1 + y²) dx dy dz dẋ dẏ, Chaplygin's sleigh has no measure ρ(q) (its
obstruction is a·m·sin θ/(J + m a²), so with a = 0 it has one), an unconstrained system has Liouville's
det M dq dq̇. Every ``found`` is re-checked here independently: div(ρ f) of the reduced flow simplified
to 0 and evaluated in floats at random states."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from nonholonomic.lagrangian import derive, parse_system
from nonholonomic.lagrangian.measure_search import POINTWISE_TOLERANCE, measure_verdict
from tests.lagrangian_examples import PARTICLE, SLEIGH

#: No constraints, a mass matrix depending on q: det M = x²y² + 2y² + 2.
FREE = {"kind": "lagrangian", "coordinates": ["x", "y"],
        "L": "((1 + y**2)*x_dot**2 + 2*x*x_dot*y_dot + (2 + x**2)*y_dot**2)/2 - k*y**2/2",
        "parameters": {"k": 0.5}}
POLAR = {"kind": "lagrangian", "coordinates": ["r", "phi"], "L": "(r_dot**2 + r**2*phi_dot**2)/2 - r**2/2"}


def reduced_field(data, verdict):
    """The reduced flow in (q, u), rebuilt from the derived equations and the verdict's dependent velocities."""
    eqs = derive(data)
    on = dict(verdict.dependent)
    u = verdict.velocities
    field = [vi.xreplace(on) for vi in eqs.qdot] + [eqs.qddot[eqs.qdot.index(uj)].xreplace(on) for uj in u]
    return field, (*eqs.q, *u)


def assert_invariant(spec, verdict, at_values: bool = False) -> None:
    """div(ρ f) = 0 symbolically (parameters symbolic, or their values exactly when ``at_values``) and,
    relative to its terms, ≤ POINTWISE_TOLERANCE at random states."""
    data = parse_system(spec)
    field, x = reduced_field(data, verdict)
    if at_values:
        field = [f.xreplace({s: sp.nsimplify(v, rational=True) for s, v in data.parameter_values.items()})
                 for f in field]
    terms = [sp.diff(verdict.density * f, xi) for f, xi in zip(field, x)]
    assert sp.simplify(sp.Add(*terms)) == 0
    pars = data.parameter_values
    numeric = sp.lambdify(x, [t.xreplace(pars) for t in terms], "numpy")
    rng = np.random.default_rng(7)
    for _ in range(20):
        values = np.array(numeric(*rng.uniform(-1.5, 1.5, len(x))), dtype=float)
        assert abs(values.sum()) <= POINTWISE_TOLERANCE * np.abs(values).sum()


def test_particle_has_the_measure_sqrt_1_plus_y2():
    verdict = measure_verdict(parse_system(PARTICLE))
    assert verdict.status == "found", verdict.reason
    y = sp.Symbol("y", real=True)
    assert sp.simplify(verdict.density / sp.sqrt(1 + y**2)).is_number
    assert [str(s) for s in verdict.velocities] == ["x_dot", "y_dot"]
    assert [str(s) for s, _ in verdict.dependent] == ["z_dot"]
    assert verdict.residual is not None and verdict.residual <= POINTWISE_TOLERANCE
    assert "vanishes identically" in verdict.reason
    assert_invariant(PARTICLE, verdict)


def test_sleigh_has_no_measure_and_the_reason_names_the_obstruction():
    verdict = measure_verdict(parse_system(SLEIGH))
    assert verdict.status == "none", verdict.reason
    assert verdict.density is None
    assert "not closed" in verdict.reason and "d g_theta/dx" in verdict.reason
    assert "a*m*sin(theta)/(J + a**2*m)" in verdict.reason  # vanishes only for a = 0


def test_sleigh_with_the_edge_at_the_centre_of_mass_has_a_measure():
    spec = dict(SLEIGH, parameters={"m": 1.3, "a": 0.0, "J": 0.25})
    verdict = measure_verdict(parse_system(spec))
    assert verdict.status == "found", verdict.reason
    assert "substituted exactly" in verdict.reason
    theta = sp.Symbol("theta", real=True)
    assert sp.simplify(verdict.density**2 * sp.cos(theta)**2).is_number  # 1/|cos θ|: u = (ẋ, θ̇), ẏ = tan θ ẋ
    assert_invariant(spec, verdict, at_values=True)


@pytest.mark.parametrize("spec, det_m", [(FREE, "x**2*y**2 + 2*y**2 + 2"), (POLAR, "r**2")])
def test_unconstrained_system_has_liouville_measure_det_m(spec, det_m):
    verdict = measure_verdict(parse_system(spec))
    assert verdict.status == "found", verdict.reason
    assert verdict.dependent == ()
    symbols = {str(s): s for s in verdict.density.free_symbols}
    expected = sp.sympify(det_m, locals=symbols)
    assert sp.simplify(verdict.density / expected).is_number
    assert_invariant(spec, verdict)


def test_a_system_past_the_exact_eliminations_limit_is_undecided_with_the_measure_named(monkeypatch):
    """Past the exact elimination's size (FRACTIONS_MAX_OPS), never a clock, the sampled ansatz runs instead: the
    reason names the limit, and the sleigh, which has no measure, gets none from the ansatz either."""
    from nonholonomic.lagrangian import equations

    monkeypatch.setattr(equations, "FRACTIONS_MAX_OPS", 5)
    spec = dict(SLEIGH, parameters={"m": 1.7, "a": 0.3, "J": 0.35})  # not derived before in this process
    verdict = measure_verdict(parse_system(spec))
    assert verdict.status == "undecided" and "an ansatz was fitted on sampled states" in verdict.reason
    assert "no density rho = P^r G^s" in verdict.reason
    assert "operations > max 5 (FRACTIONS_MAX_OPS)" in verdict.reason


def test_a_found_measure_is_claimed_and_checked_along_the_trajectory_and_a_wrong_one_fails():
    """The particle's definition claims ρ|det A_D| = √(1 + y²) on z_dot = y x_dot; the job's measure check proves
    div(ρ f) = 0 there and finds it ~0 at the samples; with ρ = 1 both fail (div f = −y ẏ/(1 + y²) ≠ 0)."""
    from dataclasses import replace

    from nonholonomic.definition import InvariantMeasure
    from nonholonomic.evidence.measure import measure_evidence
    from nonholonomic.simulation import simulate
    from nonholonomic.systems.lagrangian import define

    system = define(parse_system(PARTICLE))
    assert system.measure.density == sp.sqrt(sp.Symbol("y", real=True) ** 2 + 1)
    assert system.structure["measure"]["verdict"] == "found"
    state = {"q": [0.3, -0.2, 0.1], "q_dot": [0.5, 0.4, -0.2 * 0.5]}
    result = simulate(system, PARTICLE["parameters"], state, 10.0, 101, checks=["measure"])
    symbolic, pointwise = result.checks
    assert symbolic.passed is True and "z_dot = x_dot*y" in symbolic.detail
    assert pointwise.passed is True and pointwise.residual <= 1e-12
    wrong = replace(system, measure=InvariantMeasure(sp.Integer(1), "rho = 1", "test",
                                                     on_manifold=system.measure.on_manifold))
    symbolic, pointwise = measure_evidence(wrong, result.parameters, result.trajectory.states)
    assert symbolic.passed is False and pointwise.passed is False and pointwise.residual > 1e-3


@pytest.mark.parametrize("name", ["nonholonomic_particle", "rolling_disk"])
def test_the_spectrum_sum_is_what_the_measure_on_the_manifold_predicts(name):
    """On the constraint manifold div f of the full flow in (q, q̇) is −d/dt ln(ρ |det A_D|) (the reduced flow's
    −d/dt ln ρ, and the Jacobian det A_D of q̇ ↦ (u, A q̇)): the sum of the full spectrum, (1/T) ∫ div f dt,
    equals −[ln(ρ |det A_D|)]/T to round-off; a wrong density (ρ without the proof) would not."""
    from nonholonomic.analysis.options import SpectrumOptions
    from nonholonomic.simulation import simulate
    from nonholonomic.systems.lagrangian import define
    from nonholonomic.systems.lagrangian_classics import CLASSICS

    job = CLASSICS[name]["job"]
    system = define(parse_system(job["system"]))
    result = simulate(system, job["system"]["parameters"], job["initial_state"], 50.0, 11, checks=[],
                      lyapunov=SpectrumOptions())
    spectrum = result.lyapunov
    assert spectrum.sum_expected == 0.0 and spectrum.measure_average is not None
    assert abs(spectrum.sum - spectrum.measure_average) <= 1e-10 * max(1.0, abs(spectrum.sum))
    assert abs(spectrum.sum) > 1e-6  # finite T: the prediction is not trivially 0 = 0
    assert not any("contradicts" in w for w in spectrum.warnings)
