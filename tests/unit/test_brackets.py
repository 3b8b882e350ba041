"""Machine-checked Poisson structures: e(3), Chaplygin's ball bracket (eq. 2604-6), the generalized
Chaplygin bracket (eq. 2704-9) and user brackets (Jacobi identity, Casimirs, rank)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import sympy as sp

from nonholonomic.evidence.brackets import (
    casimir_checks,
    casimir_pointwise,
    jacobi_pointwise,
    jacobi_symbolic,
    rank_at,
    structure_evidence,
    verify_user_bracket,
)
from nonholonomic.hamiltonization.poisson import (
    PoissonStructure,
    chaplygin_ball_bracket,
    e3,
    generalized_chaplygin_bracket,
)
from nonholonomic.systems import chaplygin_ball as ball

BALL_PARAMETERS = [np.array([2.0, 3.0, 4.5, 0.7]), np.array([1.0, 1.3, 7.0, 5.0]), np.array([3.0, 2.0, 1.0, 1e-3])]
RNG = np.random.default_rng(20240604)
POINTS = RNG.uniform(-2.0, 2.0, (200, 6))
#: The same points with γ (resp. Γ) of unit length: there det I_Q > 0 for every J, D, so the
#: Casimir sqrt(det I_Q) (L, γ) is real (off |γ| = 1 it is NaN where D (γ, J⁻¹γ) > 1).
UNIT_POINTS = np.hstack([POINTS[:, :3], POINTS[:, 3:] / np.linalg.norm(POINTS[:, 3:], axis=1, keepdims=True)])


def ball_variant(coefficient: sp.Expr, factors) -> PoissonStructure:
    """Eq. (2604-6) with ``D → coefficient·D`` in the L-block and ``J_i J_j → factors_i factors_j``."""
    ps = chaplygin_ball_bracket()
    L, g = sp.Matrix(ps.variables[:3]), ball.gamma
    rho2 = 1 / ball.contact_inertia_determinant(g)
    P = ps.matrix.copy()
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        P[i, j] = L[k] - coefficient * ball.D * L.dot(g) * rho2 * factors[i] * factors[j] * g[k]
        P[j, i] = -P[i, j]
    return dataclasses.replace(ps, name=f"{ps.name}_variant", matrix=P)


J_FACTORS = [ball.I1 + ball.D, ball.I2 + ball.D, ball.I3 + ball.D]
I_FACTORS = [ball.I1, ball.I2, ball.I3]


def structures():
    return [(e3(), None), (chaplygin_ball_bracket(), BALL_PARAMETERS)]


# ------------------------------------------------------------------------------------------
# e(3) and the ball
# ------------------------------------------------------------------------------------------

def test_printed_ball_bracket_is_the_variant_builder_at_coefficient_one():
    # The test helper rebuilds eq. (2604-6) exactly, so its variants differ only where intended.
    assert ball_variant(1, J_FACTORS).matrix == chaplygin_ball_bracket().matrix


@pytest.mark.parametrize("ps", [e3(), chaplygin_ball_bracket()], ids=["e3", "ball"])
def test_jacobi_holds_symbolically_for_all_parameters(ps):
    # ERRATA "verified as printed": eq. (2604-6) is a Poisson bracket on R^6 (off the pole det I_Q = 0)
    # for any J, D — the parameters stay symbols in the proof.
    proven, detail = jacobi_symbolic(ps)  # measured: e3 ~0.02 s, ball ~0.5 s
    print(f"{ps.name}: Jacobi proof: {detail}")
    assert proven is True, detail
    assert detail == "all 20 Jacobiators J_ijk (i<j<k) reduce to 0, parameters symbolic"  # no time in it


@pytest.mark.parametrize("ps, parameter_sets", structures(), ids=["e3", "ball"])
def test_jacobi_holds_pointwise_to_1e_12(ps, parameter_sets):
    residuals = [jacobi_pointwise(ps, POINTS, p) for p in (parameter_sets or [None])]
    print(ps.name, "pointwise Jacobi residuals", residuals)
    assert max(residuals) <= 1e-12  # measured: 0 (e3), ~2e-16 (ball)


@pytest.mark.parametrize("ps, parameter_sets", structures(), ids=["e3", "ball"])
def test_claimed_casimirs_hold(ps, parameter_sets):
    # e(3): Γ², (M, Γ); ball: γ², (L, γ)/ρ_μ = (M, γ) (the text after eq. 2604-6).
    checks = casimir_checks(ps)
    assert [c[0] for c in checks] == [name for name, _ in ps.casimirs] and len(checks) == 2
    assert all(verdict is True for _, verdict, _ in checks), checks
    for _, C in ps.casimirs:
        for p in parameter_sets or [None]:
            assert casimir_pointwise(ps, C, UNIT_POINTS, p) <= 1e-12  # measured: <= 3e-15 (ball, D = 5)


@pytest.mark.parametrize("ps, wrong, parameters", [
    (e3(), "M^2", None),
    (chaplygin_ball_bracket(), "L^2", BALL_PARAMETERS[0]),
    (chaplygin_ball_bracket(), "(L, gamma)", BALL_PARAMETERS[0]),  # without the 1/ρ_μ
], ids=["e3-M2", "ball-L2", "ball-Lgamma"])
def test_wrong_casimir_candidates_fail(ps, wrong, parameters):
    v = sp.Matrix(ps.variables[:3])
    g = sp.Matrix(ps.variables[3:])
    C = {"M^2": v.dot(v), "L^2": v.dot(v), "(L, gamma)": v.dot(g)}[wrong]
    wrong_ps = dataclasses.replace(ps, casimirs=((wrong, C),))
    [(name, verdict, detail)] = casimir_checks(wrong_ps)
    assert name == wrong and verdict is False, detail
    residual = casimir_pointwise(wrong_ps, C, UNIT_POINTS, parameters)
    print(wrong, "pointwise residual", residual)
    assert residual > 1e-3  # measured: 1.0 (M², L²), 0.086 ((L, γ))


@pytest.mark.parametrize("ps, parameters", [(e3(), None), (chaplygin_ball_bracket(), BALL_PARAMETERS[0])],
                         ids=["e3", "ball"])
def test_rank_is_4_at_generic_points(ps, parameters):
    ranks = {rank_at(ps, x, parameters) for x in POINTS[:50]}
    assert ranks == {4}


def test_rank_drops_on_the_degenerate_set_of_e3():
    # At Γ = 0 only the so(3) block is left: rank 2 for M ≠ 0, rank 0 at the origin.
    assert rank_at(e3(), np.array([0.3, -1.0, 0.5, 0, 0, 0])) == 2
    assert rank_at(e3(), np.zeros(6)) == 0


def test_ball_bracket_with_I_i_I_j_instead_of_J_i_J_j_fails_jacobi_both_ways():
    broken = ball_variant(1, I_FACTORS)
    proven, detail = jacobi_symbolic(broken)
    assert proven is False, detail
    residuals = [jacobi_pointwise(broken, POINTS, p) for p in BALL_PARAMETERS[:2]]
    print("I_i I_j variant: pointwise Jacobi residuals", residuals, detail)
    assert min(residuals) > 1e-4  # measured: 2.5e-3 and 2.5e-2, against ~1.1e-16 for the printed bracket


def test_ball_bracket_with_doubled_D_term_is_still_poisson_but_loses_the_casimir():
    # Finding: Jacobi alone does not pin the coefficient of the D-term — ε_ijk(L_k − c D (L,γ) ρ_μ² J_i J_j γ_k)
    # is a Poisson bracket for c = 2 too. The Casimir (L, γ)/ρ_μ (i.e. the constant of areas) does pin it.
    doubled = ball_variant(2, J_FACTORS)
    proven, detail = jacobi_symbolic(doubled)
    assert proven is True, detail
    assert jacobi_pointwise(doubled, POINTS, BALL_PARAMETERS[0]) <= 1e-12
    checks = dict((name, verdict) for name, verdict, _ in casimir_checks(doubled))
    assert checks == {"gamma^2": True, "(L, gamma)/rho_mu = (M, gamma)": False}
    _, area = doubled.casimirs[1]
    assert casimir_pointwise(doubled, area, UNIT_POINTS, BALL_PARAMETERS[0]) > 1e-3


def test_structure_evidence_for_the_ball():
    ps = chaplygin_ball_bracket()
    items = structure_evidence(ps, UNIT_POINTS[:50], BALL_PARAMETERS[0])
    assert [(i.name, i.method) for i in items] == [
        ("jacobi_identity", "symbolic"), ("jacobi_identity", "pointwise"),
        ("casimir", "symbolic"), ("casimir", "symbolic"), ("rank_on_leaf", "numeric")]
    assert all(i.passed is True for i in items), items
    assert all(i.formula == ps.formula and i.equation == "2604-6" for i in items)
    assert items[1].tolerance == 1e-10 and items[1].residual <= 1e-12
    assert all(i.residual <= 1e-12 for i in items[2:4])
    assert "rank 4 at 50 points" in items[4].detail


def test_structure_evidence_reports_a_broken_bracket():
    broken = ball_variant(1, I_FACTORS)
    items = structure_evidence(broken, POINTS[:50], BALL_PARAMETERS[0])
    by = {(i.name, i.method): i for i in items if i.name == "jacobi_identity"}
    assert by[("jacobi_identity", "symbolic")].passed is False
    assert by[("jacobi_identity", "pointwise")].passed is False
    assert by[("jacobi_identity", "pointwise")].residual > 1e-4


# ------------------------------------------------------------------------------------------
# Generalized Chaplygin bracket (eq. 2704-9)
# ------------------------------------------------------------------------------------------

theta, phi, p_theta, p_phi = sp.symbols("theta phi p_theta p_phi", real=True)
c_area = sp.Symbol("c", real=True)


def ball_S_bar() -> sp.Expr:
    """S̄ of eq. (007) in Euler angles, N = ρ_μ at γ = (sinθ sinφ, sinθ cosφ, cosθ) (eq. 2904-1).

    Used here only as a non-trivial S̄(q) (with a square root and trigonometric functions).
    """
    g = sp.Matrix([sp.sin(theta) * sp.sin(phi), sp.sin(theta) * sp.cos(phi), sp.cos(theta)])
    N = 1 / sp.sqrt(ball.contact_inertia_determinant(g))
    return (c_area * (ball.I3 + ball.D) * ball.D * N**3 * sp.sin(theta)
            * (ball.I1 * sp.cos(phi)**2 + ball.I2 * sp.sin(phi)**2 + ball.D))


def test_generalized_chaplygin_bracket_with_q_dependent_S_bar_is_poisson_of_rank_4():
    ps = generalized_chaplygin_bracket(ball_S_bar(), (theta, phi), (p_theta, p_phi),
                                       parameters=(ball.I1, ball.I2, ball.I3, ball.D, c_area))
    proven, detail = jacobi_symbolic(ps)
    assert proven is True, detail
    X = RNG.uniform(-2.0, 2.0, (100, 4))
    p = np.array([2.0, 3.0, 4.5, 0.7, 0.9])
    assert jacobi_pointwise(ps, X, p) <= 1e-12
    assert {rank_at(ps, x, p) for x in X[:30]} == {4}


def test_generalized_chaplygin_bracket_with_p_dependent_S_bar_fails():
    # 2 DOF: J(q_i, p_1, p_2) = ∂S̄/∂p_i, so S̄ must depend on q only (Theorem 1, statement 1).
    ps = generalized_chaplygin_bracket(sp.sin(p_theta) * theta, (theta, phi), (p_theta, p_phi))
    proven, detail = jacobi_symbolic(ps)
    assert proven is False, detail  # decided by a 50-digit evaluation: the numerator is not polynomial
    X = RNG.uniform(-2.0, 2.0, (50, 4))
    assert jacobi_pointwise(ps, X) == pytest.approx(1.0)  # a single non-zero term: nothing cancels


# ------------------------------------------------------------------------------------------
# User brackets
# ------------------------------------------------------------------------------------------

x, y, z = sp.symbols("x y z")


def user_matrix(entries: list[list[str]]) -> sp.Matrix:
    return sp.Matrix([[sp.sympify(e, locals={"x": x, "y": y, "z": z}) for e in row] for row in entries])


SO3 = [["0", "z", "-y"], ["-z", "0", "x"], ["y", "-x", "0"]]  # {x,y}=z, {y,z}=x, {z,x}=y


def test_user_so3_bracket_passes_with_its_casimir():
    out = verify_user_bracket([x, y, z], user_matrix(SO3),
                              {"x^2+y^2+z^2": sp.sympify("x**2+y**2+z**2"), "x^2+y^2": x**2 + y**2})
    json.dumps(out)
    assert out["dimension"] == 3
    assert out["antisymmetric"]["passed"] is True and out["antisymmetric"]["offending"] == []
    assert out["jacobi"]["method"] == "symbolic" and out["jacobi"]["passed"] is True
    assert out["jacobi"]["residual"] <= 1e-12
    good, wrong = out["casimirs"]
    assert good["name"] == "x^2+y^2+z^2" and good["passed"] is True and good["residual"] <= 1e-12
    assert wrong["passed"] is False and wrong["residual"] > 1e-3
    assert out["rank"]["generic"] == 2 and set(out["rank"]["values"]) == {2} and len(out["rank"]["values"]) == 20


def test_user_non_antisymmetric_matrix_is_reported():
    entries = [row[:] for row in SO3]
    entries[1][0] = "z"  # {y, x} = z as well as {x, y} = z
    out = verify_user_bracket([x, y, z], user_matrix(entries))
    json.dumps(out)
    anti = out["antisymmetric"]
    assert anti["passed"] is False and anti["residual"] == pytest.approx(1.0)
    assert [o["entry"] for o in anti["offending"]] == [[0, 1]]
    assert anti["offending"][0]["sum"] == "2*z" and anti["offending"][0]["bracket"] == "{x, y} + {y, x}"


def test_user_bracket_failing_jacobi_is_reported_with_its_residual():
    # {x,y}=z, {y,z}=x, {z,x}=x y: J = {y, x y} = −y z ≠ 0.
    out = verify_user_bracket([x, y, z], user_matrix([["0", "z", "-x*y"], ["-z", "0", "x"], ["x*y", "-x", "0"]]))
    json.dumps(out)
    assert out["antisymmetric"]["passed"] is True
    jac = out["jacobi"]
    print("failing user bracket:", jac)
    assert jac["method"] == "symbolic" and jac["passed"] is False
    assert jac["residual"] > 0.1  # measured: O(1)
    assert "(x, y, z)" in jac["detail"]


def test_user_bracket_with_parameters_and_the_pointwise_fallback_past_max_proof_ops():
    # The ball bracket as a user bracket with numbers for I, D: with max_proof_ops = 1 no proof is tried
    # and the verdict comes from the pointwise residual, the detail naming the limit (not a clock).
    from nonholonomic.work_limits import WorkLimits

    ps = chaplygin_ball_bracket()
    values = dict(zip(ps.parameters, [2.0, 3.0, 4.5, 0.7]))
    small = WorkLimits(max_proof_ops=1)
    out = verify_user_bracket(ps.variables, ps.matrix, dict(ps.casimirs[:1]), parameters=values, limits=small)
    json.dumps(out)
    assert out["jacobi"]["method"] == "pointwise" and out["jacobi"]["passed"] is True
    assert out["jacobi"]["residual"] <= 1e-12
    assert "operations > max 1 (max_proof_ops)" in out["jacobi"]["detail"]
    assert out["casimirs"][0]["passed"] is True  # gamma^2: each {C, x_i} is 0 as built, no proof needed
    assert out["rank"]["generic"] == 4
    # the same call, the same answer (no clock in it)
    assert verify_user_bracket(ps.variables, ps.matrix, dict(ps.casimirs[:1]), parameters=values, limits=small) == out
    # With the default limits the same bracket (same numbers, now exact decimals) is proved symbolically.
    out = verify_user_bracket(ps.variables, ps.matrix, parameters=values)
    assert out["jacobi"]["method"] == "symbolic" and out["jacobi"]["passed"] is True


def test_jacobi_past_max_proof_ops_is_undecided_with_the_limit_named():
    from nonholonomic.work_limits import WorkLimits

    proven, detail = jacobi_symbolic(chaplygin_ball_bracket(), WorkLimits(max_proof_ops=1))
    assert proven is None and detail.startswith("undecided Jacobiators (L1, L2, L3): not tried: ")
    assert detail.endswith("operations > max 1 (max_proof_ops)")
    assert jacobi_symbolic(chaplygin_ball_bracket())[0] is True  # another limit, another (cached) proof


def test_user_bracket_input_errors():
    with pytest.raises(ValueError, match="square"):
        verify_user_bracket([x, y, z], sp.Matrix([[0, z, -y], [-z, 0, x]]))
    with pytest.raises(ValueError, match="3 x 3 but there are 2 variables"):
        verify_user_bracket([x, y], user_matrix(SO3))
    with pytest.raises(ValueError, match="free symbols.*: a"):
        verify_user_bracket([x, y, z], user_matrix(SO3) * sp.Symbol("a"))
    with pytest.raises(ValueError, match="free symbols.*: b"):
        verify_user_bracket([x, y, z], user_matrix(SO3), {"C": sp.Symbol("b") * x})
    with pytest.raises(ValueError, match="undefined functions"):
        verify_user_bracket([x, y, z], user_matrix(SO3) * sp.Function("f")(x))
    # A given parameter (an exact decimal in the proof) makes the same bracket acceptable.
    out = verify_user_bracket([x, y, z], user_matrix(SO3) * sp.Symbol("a"), parameters={sp.Symbol("a"): 0.1})
    assert out["jacobi"]["passed"] is True and out["rank"]["generic"] == 2
