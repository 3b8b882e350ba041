"""The Euler-angle local forms (eq. 2904-1, 2504-6..9, Theorem 2; eq. 001..007; eq. 2704-7, 2704-8).

Identities in θ, φ are decided exactly: sinθ, cosθ, sinφ, cosφ are replaced by the half-angle
rational functions of t = tan(θ/2), u = tan(φ/2), and the numerator over a common denominator is
expanded. Claims about the equations of motion are checked at exact rational phase points (sin and
cos from Pythagorean triples, rational parameters and velocities): the accelerations come from the
systems' vector fields (eq. 2504-1, 2604-1), so each residual is an exact number, 0 when the form
is right. The paper's printed misprints (ERRATA 2, 3, 7) are shown to fail.
"""

from __future__ import annotations

import ast

import numpy as np
import pytest
import sympy as sp

from nonholonomic import get_system, simulate
from nonholonomic.hamiltonization import local_forms as lf
from nonholonomic.systems import SYSTEMS, chaplygin_ball as ball, veselova as ves

R = sp.Rational
th, ph = lf.theta, lf.phi
_t, _u = sp.symbols("t u", real=True)
HALF_ANGLE = {sp.sin(th): 2 * _t / (1 + _t ** 2), sp.cos(th): (1 - _t ** 2) / (1 + _t ** 2),
              sp.sin(ph): 2 * _u / (1 + _u ** 2), sp.cos(ph): (1 - _u ** 2) / (1 + _u ** 2)}
#: (sinθ, cosθ, sinφ, cosφ) on the unit circle, exactly (Pythagorean triples), away from sinθ = 0.
POINTS = [(R(3, 5), R(4, 5), R(5, 13), R(-12, 13)), (R(8, 17), R(-15, 17), R(-7, 25), R(24, 25)),
          (R(12, 13), R(5, 13), R(20, 29), R(21, 29))]
INERTIA = {lf.I1: 2, lf.I2: 3, lf.I3: R(9, 2)}
VELOCITIES = {lf.thetadot: R(2, 7), lf.phidot: R(-3, 11)}
A_LINEAR = [R(3, 10), R(-1, 5), R(1, 2)]
K_QUADRATIC = [1, R(1, 5), 0, 2, R(1, 10), -1]  # K11, K12, K13, K22, K23, K33
TOLERANCE = 1e-12  # the trajectories' local-form residuals


def numerator(expr: sp.Expr) -> sp.Expr:
    """The expanded numerator of ``expr`` in t = tan(θ/2), u = tan(φ/2) (0 iff expr ≡ 0)."""
    e = sp.sympify(expr).xreplace(HALF_ANGLE)
    assert not {th, ph} & e.free_symbols, "expression not rational in sin, cos of theta, phi"
    return sp.expand(sp.numer(sp.together(e)))


def vanishes(expr: sp.Expr) -> bool:
    return numerator(expr) == 0


def at(expr: sp.Expr, point: tuple, values: dict) -> sp.Expr:
    """``expr`` at a rational point (sin, cos of θ, φ) with ``values`` for the other symbols."""
    st, ct, sph, cph = point
    e = sp.sympify(expr).xreplace({sp.sin(th): st, sp.cos(th): ct, sp.sin(ph): sph, sp.cos(ph): cph})
    e = e.xreplace(values)
    assert not {th, ph} & e.free_symbols
    return e


def potential(system) -> sp.Expr:
    """U(γ) of a system: its energy integral at zero velocity."""
    (energy,) = [i.expression for i in system.integrals if i.name == "energy"]
    velocity = ves.omega if system.kind == "veselova" else ball.M
    return energy.subs({v: 0 for v in velocity})


def accelerations(system, velocity_state: sp.Matrix, psidot_value, point, values) -> dict:
    """(θ̈, φ̈, ψ̈) at a rational point from the vector field: d/dt of the velocity state vector
    (ω for Veselova, M = I_Q ω for the ball) in Euler angles equals the system's right-hand side."""
    g = lf.euler_gamma()
    rates = [(th, lf.thetadot), (ph, lf.phidot), (lf.thetadot, lf.thetaddot), (lf.phidot, lf.phiddot),
             (lf.psidot, lf.psiddot)]
    local = sum((velocity_state.diff(x) * v for x, v in rates), sp.zeros(3, 1))
    state = ves.omega if system.kind == "veselova" else ball.M
    sub = {**dict(zip(state, velocity_state)), **dict(zip(ves.gamma if system.kind == "veselova" else ball.gamma, g))}
    field = sp.Matrix([sp.sympify(f).subs(sub, simultaneous=True) for f in system.rhs[:3]])
    values = {**values, lf.psidot: psidot_value}
    equations = [at(e, point, values) for e in local - field]
    (solution,) = sp.solve(equations, [lf.thetaddot, lf.phiddot, lf.psiddot], dict=True)
    return {**values, **solution}


def parameter_values(system) -> dict:
    names = [s.name for s in system.parameter_symbols]
    values = {s: INERTIA[s] for s in system.parameter_symbols if s in INERTIA}
    if "D" in names:
        values[ball.D] = R(7, 10)
    if "a1" in names:
        values.update(zip(system.parameter_symbols[names.index("a1"):names.index("a1") + 3], A_LINEAR))
    if "K11" in names:
        values.update(zip(system.parameter_symbols[names.index("K11"):names.index("K11") + 6], K_QUADRATIC))
    return values


# --- eq. (2904-1), (2504-6), (2504-8) ------------------------------------------------------------

def test_euler_angles_give_the_poisson_equation_and_the_constraint_2504_6():
    g, w = lf.euler_gamma(), lf.euler_omega()
    gdot = g.diff(th) * lf.thetadot + g.diff(ph) * lf.phidot
    assert all(vanishes(e) for e in gdot - g.cross(w))  # dγ/dt = γ × ω: the convention of eq. 2504-1
    assert not all(vanishes(e) for e in gdot - w.cross(g))  # (the opposite orientation is not it)
    assert vanishes(g.dot(g) - 1)
    assert vanishes(lf.veselova_constraint() - (lf.psidot + sp.cos(th) * lf.phidot))  # eq. 2504-6
    assert lf.euler_omega().diff(lf.thetadot) == lf.node_axis() and vanishes(lf.node_axis().dot(g))


def test_veselova_T_is_T0_on_the_constraint_2504_8():
    T0 = lf.veselova_free_kinetic_energy()
    assert vanishes(T0.subs(lf.psidot, lf.VESELOVA_PSIDOT) - lf.veselova_kinetic_energy())
    assert not vanishes(T0.subs(lf.psidot, 0) - lf.veselova_kinetic_energy())


def test_veselova_S_is_minus_sin_theta_dT0_dpsidot_and_the_printed_S_is_not():
    # ERRATA 2: S = sin²θ[θ̇(I₂−I₁) sinφ cosφ + φ̇ sinθ cosθ (I₁sin²φ + I₂cos²φ − I₃)] = −sinθ ∂T₀/∂ψ̇.
    dT0 = sp.diff(lf.veselova_free_kinetic_energy(), lf.psidot).subs(lf.psidot, lf.VESELOVA_PSIDOT)
    S = lf.veselova_gyroscopic_term()
    assert vanishes(S + sp.sin(th) * dT0)
    printed = lf.veselova_gyroscopic_term_printed()
    assert not vanishes(printed - S)
    assert not vanishes(printed - dT0)  # the printed "S = ∂T₀/∂ψ̇" is not it either
    # The θ̇ terms agree; the φ̇ coefficient is what the print gets wrong.
    assert vanishes(sp.diff(printed - S, lf.thetadot)) and not vanishes(sp.diff(printed - S, lf.phidot))


@pytest.mark.parametrize("potential_kind", ["linear", "quadratic"])
def test_veselova_chaplygin_form_2504_7_reproduces_the_vector_flow(potential_kind):
    system = get_system("veselova", potential_kind)
    L = lf.veselova_kinetic_energy() - lf.on_euler_gamma(potential(system))
    values = {**parameter_values(system), **VELOCITIES}
    printed = []
    for point in POINTS:
        psd = at(lf.VESELOVA_PSIDOT, point, values)
        acc = accelerations(system, lf.euler_omega(), psd, point, values)
        # The flow keeps the constraint: ψ̈ = d/dt(−cosθ φ̇).
        assert at(sp.sin(th) * lf.thetadot * lf.phidot - sp.cos(th) * lf.phiddot, point, acc) == acc[lf.psiddot]
        residuals = [at(r, point, acc) for r in lf.generalized_chaplygin_residuals(L, lf.veselova_gyroscopic_term())]
        assert residuals == [0, 0], residuals
        wrong = [at(r, point, acc)
                 for r in lf.generalized_chaplygin_residuals(L, lf.veselova_gyroscopic_term_printed())]
        printed.append(max(abs(float(r)) for r in wrong))
    assert min(printed) > 1e-2, printed  # ERRATA 2's printed S: residuals of order 0.1


# --- Theorem 2: the reducing multiplier and the Lagrangian ---------------------------------------

def test_theorem_2_multiplier_makes_S_bar_vanish_and_the_printed_one_does_not():
    g = lf.euler_gamma()
    T, S = lf.veselova_kinetic_energy(), lf.veselova_gyroscopic_term()
    right = g.dot(ves.inertia_inv * g)  # N = (γ, I⁻¹γ)^(−1/2) (ERRATA 3)
    printed = g.dot(lf.inertia * g)  # N = (γ, Iγ)^(−1/2) as printed
    assert vanishes(lf.reduced_gyroscopic_term_over_multiplier(T, S, right))
    assert not vanishes(lf.reduced_gyroscopic_term_over_multiplier(T, S, printed))
    # The same with eq. (2704-8) literally (square roots and all), at rational points.
    values = {**INERTIA, lf.thetap: R(1, 3), lf.phip: R(-2, 5)}
    for point in POINTS:
        good = at(lf.reduced_gyroscopic_term(T, S, lf.veselova_reducing_multiplier()), point, values)
        bad = at(lf.reduced_gyroscopic_term(T, S, lf.veselova_reducing_multiplier_printed()), point, values)
        assert sp.expand(good) == 0
        assert abs(float(bad)) > 1e-2, float(bad)


def test_theorem_2_euler_lagrange_equations_hold_in_the_new_time():
    """Eq. (2504-9): (1/N) d/dt ∂L̄/∂q′ − ∂L̄/∂q = 0 along the Veselova flow (linear potential)."""
    system = get_system("veselova", "linear")
    U = lf.on_euler_gamma(potential(system))
    values = {**parameter_values(system), **VELOCITIES}
    worst = {}
    for name, n in (("errata", lf.veselova_reducing_multiplier()),
                    ("printed", lf.veselova_reducing_multiplier_printed())):
        Lbar = lf.time_substituted_lagrangian(lf.veselova_kinetic_energy(), n) - U
        back = {lf.thetap: lf.thetadot / n, lf.phip: lf.phidot / n}  # q′ = q̇ / N
        worst[name] = 0.0
        for point in POINTS[:2]:
            acc = accelerations(system, lf.euler_omega(), at(lf.VESELOVA_PSIDOT, point, values), point, values)
            for qi, qpi in zip(lf.Q, lf.QPRIME):
                momentum = sp.diff(Lbar, qpi).subs(back, simultaneous=True)
                residual = lf.time_derivative(momentum) / n - sp.diff(Lbar, qi).subs(back, simultaneous=True)
                value = sp.expand(at(residual, point, acc))
                if name == "errata":
                    assert value == 0, value
                worst[name] = max(worst[name], abs(float(value)))
    assert worst["printed"] > 1e-2, worst


def test_theorem_2_lagrangian_equals_its_vector_form():
    system = get_system("veselova", "quadratic")
    U = potential(system)
    local, vector = lf.veselova_reduced_lagrangian(U), lf.veselova_reduced_lagrangian_vector(U)
    assert vanishes(local - vector)
    # With the printed N the local Lagrangian is not the theorem's vector form.
    printed = lf.time_substituted_lagrangian(lf.veselova_kinetic_energy(), lf.veselova_reducing_multiplier_printed())
    assert not vanishes(printed - lf.on_euler_gamma(U) - vector)


# --- Chaplygin's ball: eq. (001)–(007) ------------------------------------------------------------

def test_ball_kinetic_energy_cyclic_integral_and_routh_function():
    g, w = lf.euler_gamma(), lf.euler_omega()
    IQ = ball.contact_inertia(g)
    T = lf.ball_kinetic_energy()
    assert vanishes((w.T * IQ * w)[0] / 2 - T)  # ½(M, ω), M = I_Q ω (eq. 2604-1, 2604-2)
    assert vanishes(sp.diff(T, lf.psidot) - lf.ball_cyclic_momentum())  # eq. (004)
    assert vanishes(g.dot(IQ * w) - lf.ball_cyclic_momentum())  # c = (M, γ)
    assert vanishes(lf.ball_cyclic_momentum().subs(lf.psidot, lf.ball_psidot()) - lf.c)
    routh = (T - lf.psidot * lf.ball_cyclic_momentum()).subs(lf.psidot, lf.ball_psidot())
    assert vanishes(routh - lf.ball_routh_function())
    # The Routh energy Σ q̇ ∂ℛ/∂q̇ − ℛ is the kinetic energy.
    Rf = lf.ball_routh_function()
    energy = sum(v * sp.diff(Rf, v) for v in lf.QDOT) - Rf
    assert vanishes(energy - T.subs(lf.psidot, lf.ball_psidot()))


def test_ball_routh_form_003_reproduces_the_vector_flow():
    system = get_system("chaplygin_ball", "linear")
    Rf = lf.ball_routh_function() - lf.on_euler_gamma(potential(system), ball.gamma)
    values = {**parameter_values(system), **VELOCITIES}
    IQ = ball.contact_inertia(lf.euler_gamma())
    wrong_sign = []
    for point in POINTS:
        acc = accelerations(system, IQ * lf.euler_omega(), R(5, 3), point, values)
        acc[lf.c] = at(lf.ball_cyclic_momentum(), point, acc)
        # eq. (003) with its own sign: d/dt ∂ℛ/∂θ̇ − ∂ℛ/∂θ = −φ̇ S₀₀₃ is (2704-7) with S = −S₀₀₃.
        residuals = [at(r, point, acc) for r in lf.generalized_chaplygin_residuals(Rf, lf.ball_gyroscopic_term())]
        assert residuals == [0, 0], residuals
        assert lf.ball_gyroscopic_term() == -lf.ball_gyroscopic_term_routh()
        wrong = [at(r, point, acc) for r in lf.generalized_chaplygin_residuals(Rf, lf.ball_gyroscopic_term_routh())]
        wrong_sign.append(max(abs(float(r)) for r in wrong))
    assert min(wrong_sign) > 1e-2, wrong_sign


def test_ball_S_bar_depends_on_q_only_and_is_eq_007_up_to_its_sign():
    g = lf.euler_gamma()
    Delta = ball.contact_inertia_determinant(g)  # N = ρ_μ = Δ^(−1/2)
    Rf, S = lf.ball_routh_function(), lf.ball_gyroscopic_term()
    over_n = lf.reduced_gyroscopic_term_over_multiplier(Rf, S, Delta)
    assert all(vanishes(sp.diff(over_n, v)) for v in lf.QDOT)  # Theorem 1, statement 1
    B = over_n.subs({v: 0 for v in lf.QDOT})
    n = lf.ball_reducing_multiplier()
    S_bar_007 = lf.ball_S_bar_printed(n) / n  # N³/N = N² = 1/Δ: rational
    assert vanishes(B + S_bar_007)  # S̄ = −S̄₀₀₇ (eq. 007 writes −φ′ S̄ on the θ equation)
    assert not vanishes(B - S_bar_007)
    # Eq. (2704-8) literally, and ERRATA 6: S̄ = N·B(q), B = S at zero momenta P = ∂ℛ/∂q̇, not B.
    values = {**INERTIA, ball.D: R(7, 10), lf.c: R(2, 3), lf.thetap: R(1, 3), lf.phip: R(-2, 5)}
    for point in POINTS[:2]:
        S_bar = sp.expand(at(lf.reduced_gyroscopic_term(Rf, S, n), point, values))
        assert sp.expand(S_bar + at(lf.ball_S_bar_printed(n), point, values)) == 0
        velocities = sp.solve([at(sp.diff(Rf, v), point, values) for v in lf.QDOT], lf.QDOT, dict=True)[0]
        B_momenta = at(S, point, {**values, **velocities})
        N_value = at(n, point, values)
        assert sp.expand(S_bar - N_value * B_momenta) == 0
        assert abs(float(S_bar - B_momenta)) > 1e-3 * abs(float(S_bar))


def test_ball_hamiltonian_of_errata_7_is_half_L_adj_IQ_L_and_the_printed_one_is_not():
    IQ = ball.contact_inertia(lf.euler_gamma())
    L = lf.ball_L_from_momenta()
    half_adj = (L.T * IQ.adjugate() * L)[0] / 2
    assert vanishes(lf.ball_hamiltonian() - half_adj)  # identically in N
    assert not vanishes(lf.ball_hamiltonian_printed() - half_adj)
    # The misprinted coefficients: p_θ², p_φ², p_θ p_φ, c p_φ (a factor cosθ) and c² (a factor ½);
    # the c p_θ term is printed right.
    difference = sp.expand(lf.ball_hamiltonian() - lf.ball_hamiltonian_printed())
    for monomial in (lf.p_theta ** 2, lf.p_phi ** 2, lf.p_theta * lf.p_phi, lf.c * lf.p_phi):
        assert not vanishes(difference.coeff(monomial)), monomial
    assert not vanishes(difference.subs({lf.p_theta: 0, lf.p_phi: 0}))
    assert vanishes(difference.coeff(lf.c * lf.p_theta))


def test_ball_momenta_give_L_equal_rho_M_and_H_equal_the_energy():
    g = lf.euler_gamma()
    IQ = ball.contact_inertia(g)
    Rf = lf.ball_routh_function()
    P = [sp.diff(Rf, v) for v in lf.QDOT]  # p = N P (theorem after eq. 007)
    M = IQ * lf.euler_omega(psd=lf.ball_psidot())
    L = lf.ball_L_from_momenta().subs({lf.p_theta: lf.N * P[0], lf.p_phi: lf.N * P[1]}, simultaneous=True)
    assert all(vanishes(sp.expand(e / lf.N)) for e in L - lf.N * M)  # L(p) = ρ_μ M, for any N
    assert vanishes(g.dot(lf.ball_L_from_momenta()) - lf.N * lf.c)  # (L, γ) = ρ_μ c
    # Legendre transform of ℛ̄ at rational points: H(θ, φ, p) = ½(M, ω) with N = ρ_μ; the printed H is not.
    n = lf.ball_reducing_multiplier()
    values = {**INERTIA, ball.D: R(7, 10), **VELOCITIES, lf.psidot: R(5, 3)}
    for point in POINTS:
        values[lf.c] = at(lf.ball_cyclic_momentum(), point, values)
        p_values = {lf.p_theta: at(n * P[0], point, values), lf.p_phi: at(n * P[1], point, values)}
        energy = at(lf.ball_kinetic_energy(), point, values)
        H = at(lf.ball_hamiltonian(n), point, {**values, **p_values})
        assert sp.expand(H - energy) == 0
        printed = at(lf.ball_hamiltonian_printed(n), point, {**values, **p_values})
        assert abs(float(printed - energy)) > 1e-2 * float(energy)


# --- Theorem 1 worked examples --------------------------------------------------------------------

ALLOWED_FUNCTIONS = {"sin", "cos", "tan", "sqrt", "exp", "log"}
ALLOWED_NODES = (ast.Expression, ast.BinOp, ast.UnaryOp, ast.Call, ast.Name, ast.Constant, ast.Load,
                 ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Pow, ast.USub, ast.UAdd)


def parse(text: str, names: set[str]) -> sp.Expr:
    """Parse a Theorem 1 string with only + - * / ** and the allowed functions and names."""
    tree = ast.parse(text, mode="eval")
    for node in ast.walk(tree):
        assert isinstance(node, ALLOWED_NODES), ast.dump(node)
        if isinstance(node, ast.Call):
            assert isinstance(node.func, ast.Name) and node.func.id in ALLOWED_FUNCTIONS and not node.keywords
        elif isinstance(node, ast.Name):
            assert node.id in names | ALLOWED_FUNCTIONS, node.id
        elif isinstance(node, ast.Constant):
            assert isinstance(node.value, int)
    symbols = {s.name: s for s in (th, ph, lf.thetadot, lf.phidot, lf.I1, lf.I2, lf.I3, ball.D, lf.c)}
    return sp.sympify(text, locals={**symbols, **{f: getattr(sp, f) for f in ALLOWED_FUNCTIONS}})


@pytest.mark.parametrize("kind", ["veselova", "chaplygin_ball"])
def test_theorem_1_examples_are_safe_strings_of_the_tested_forms(kind):
    spec = lf.veselova_generalized_chaplygin() if kind == "veselova" else lf.chaplygin_ball_generalized_chaplygin()
    assert set(spec) == {"L", "a1", "a2", "b", "coordinates", "velocities"}
    assert spec["coordinates"] == "theta,phi" and spec["velocities"] == "thetadot,phidot"
    names = ({"theta", "phi", "thetadot", "phidot", "I1", "I2", "I3"}
             | ({"D", "c"} if kind == "chaplygin_ball" else set()))
    L, a1, a2, b = (parse(spec[k], names) for k in ("L", "a1", "a2", "b"))
    S = a1 * lf.thetadot + a2 * lf.phidot + b
    g = lf.euler_gamma()
    if kind == "veselova":
        assert vanishes(L - lf.veselova_kinetic_energy()) and vanishes(S - lf.veselova_gyroscopic_term())
        assert b == 0  # an ordinary Chaplygin system
        assert vanishes(lf.reduced_gyroscopic_term_over_multiplier(L, S, g.dot(ves.inertia_inv * g)))
    else:
        assert vanishes(L - lf.ball_routh_function()) and vanishes(S - lf.ball_gyroscopic_term())
        assert not vanishes(b)  # b ≠ 0: a generalized Chaplygin system
        over_n = lf.reduced_gyroscopic_term_over_multiplier(L, S, ball.contact_inertia_determinant(g))
        assert all(vanishes(sp.diff(over_n, v)) for v in lf.QDOT)
    for got, want in zip((a1, a2, b), lf.gyroscopic_coefficients(S)):
        assert vanishes(got - want)


# --- local_form_evidence on trajectories -----------------------------------------------------------

G0 = np.array([0.0, 0.6, 0.8])
W0 = np.array([0.5, -0.2, 0.1]) - np.dot([0.5, -0.2, 0.1], G0) * G0


@pytest.fixture(scope="module")
def trajectories():
    linear = {"a": [0.3, -0.2, 0.5]}
    v = simulate(get_system("veselova", "linear"), {"inertia": [2.0, 3.0, 4.5], **linear},
                 {"omega": W0, "gamma": G0}, 200.0, 201)
    b = simulate(get_system("chaplygin_ball", "linear"), {"inertia": [2.0, 3.0, 4.5], "D": 0.7, **linear},
                 {"M": [0.5, -0.2, 0.1], "gamma": G0}, 200.0, 201)
    return {"veselova": v, "chaplygin_ball": b}


@pytest.mark.parametrize("kind,names", [("veselova", ["euler_kinetic_energy", "euler_reduced_lagrangian"]),
                                        ("chaplygin_ball", ["euler_hamiltonian", "euler_momenta"])])
def test_local_forms_match_the_vector_forms_along_trajectories(trajectories, kind, names):
    result = trajectories[kind]
    items = lf.local_form_evidence(result.system, result.parameters, result.trajectory.states)
    assert [i.name for i in items] == names
    for item in items:
        assert item.method == "pointwise" and item.tolerance == 1e-10
        assert item.passed is True and item.residual <= TOLERANCE, (item.name, item.residual)
        assert "max over 201 states, 0 skipped" in item.detail
    # The potential is nonzero along the way (the Lagrangian check sees U).
    U = np.einsum("j,ij->i", [0.3, -0.2, 0.5], result.trajectory.states[:, 3:])
    assert np.ptp(U) > 0.1


def test_printed_hamiltonian_fails_along_the_ball_trajectory(trajectories):
    result = trajectories["chaplygin_ball"]
    states, p = result.trajectory.states, result.parameters
    omega = result.state("omega")
    thetas, phis, thd, phd, _, _ = lf.euler_angles_and_rates(omega, states[:, 3:])
    c_val = np.einsum("ij,ij->i", states[:, :3], states[:, 3:])
    args = (th, ph, lf.thetadot, lf.phidot, lf.c, lf.p_theta, lf.p_phi) + result.system.parameter_symbols
    n = lf.ball_reducing_multiplier()
    f = sp.lambdify(args, [*lf.ball_momenta(), lf.ball_hamiltonian(n), lf.ball_hamiltonian_printed(n)], "numpy")
    pt, pp, _, _ = f(thetas, phis, thd, phd, c_val, 0, 0, *p)
    _, _, H, printed = f(thetas, phis, thd, phd, c_val, pt, pp, *p)
    energy = np.einsum("ij,ij->i", states[:, :3], omega) / 2
    assert np.max(np.abs(H - energy) / energy) <= TOLERANCE
    assert np.max(np.abs(printed - energy) / energy) > 0.1


def test_states_at_the_poles_are_skipped_and_counted():
    system = get_system("veselova", "zero")
    p = np.array([2.0, 3.0, 4.5])
    near = np.array([np.sin(0.03) * np.sin(1.0), np.sin(0.03) * np.cos(1.0), np.cos(0.03)])
    w = np.array([0.3, -0.4, 0.2])
    rows = [np.concatenate([w - w @ g * g, g])
            for g in (np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0]), near, G0)]
    items = lf.local_form_evidence(system, p, np.array(rows))
    for item in items:
        assert item.passed is True and item.residual <= 1e-10
        assert "max over 2 states, 2 skipped" in item.detail
    only_poles = lf.local_form_evidence(system, p, np.array(rows[:2]))
    assert all(i.passed is None and i.residual is None and "all 2 states" in i.detail for i in only_poles)


def test_a_state_off_the_veselova_constraint_fails_the_kinetic_energy_check():
    system = get_system("veselova", "zero")
    state = np.concatenate([W0 + 0.3 * G0, G0])  # (ω, γ) = 0.3
    (kinetic, _) = lf.local_form_evidence(system, np.array([2.0, 3.0, 4.5]), state[None, :])
    assert kinetic.passed is False and kinetic.residual > 0.01


def test_other_kinds_have_no_local_forms():
    for kind in SYSTEMS:
        if kind not in ("veselova", "chaplygin_ball"):
            system = get_system(kind)
            assert lf.local_form_evidence(system, np.ones(len(system.parameter_symbols)),
                                          np.zeros((1, system.dimension))) == []
