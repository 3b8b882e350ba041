"""The Lagrange–d'Alembert equations of a user's Lagrangian system (nonholonomic.lagrangian): Chaplygin's
sleigh and the nonholonomic particle against sympy.physics.mechanics.LagrangesMethod (an independent
derivation) and, for the sleigh, against its closed-form reduced system; the integrals along the motion;
and every refusal names its field."""

from __future__ import annotations

import os

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp
from sympy.physics.mechanics import LagrangesMethod, dynamicsymbols

from nonholonomic.lagrangian import DataError, derive, parse_system
from tests.lagrangian_examples import PARTICLE, SLEIGH

#: Relative agreement with LagrangesMethod at random states (both are exact rational functions evaluated in floats).
REFERENCE_RTOL = 1e-12
RK = {"method": "DOP853", "rtol": 1e-12, "atol": 1e-12}


def reference_accelerations(spec: dict, eqs) -> sp.Matrix:
    """(q̈, λ) of ``LagrangesMethod(L, q, nonhol_coneqs=...)`` in the symbols of ``eqs`` (the same L and
    constraints, rebuilt from dynamicsymbols). Its multipliers have the convention used here:
    d/dt ∂L/∂q̇ − ∂L/∂q = Aᵀλ."""
    t = dynamicsymbols._t
    qf = [dynamicsymbols(str(s)) for s in eqs.q]
    to_functions = {**{v: sp.diff(f, t) for v, f in zip(eqs.qdot, qf)}, **dict(zip(eqs.q, qf))}
    lm = LagrangesMethod(eqs.L.xreplace(to_functions), qf,
                         nonhol_coneqs=[c.xreplace(to_functions) for c in eqs.constraints])
    lm.form_lagranges_equations()
    n = len(qf)
    back = {**{sp.diff(f, t): v for v, f in zip(eqs.qdot, qf)}}
    qddot = lm.rhs()[n:, :]  # (q̈, λ)
    return qddot.xreplace(back).xreplace(dict(zip(qf, eqs.q)))


def random_states(eqs, count: int, seed: int) -> list[dict]:
    """States (q, q̇) with q̇ on the constraint A(q) q̇ = 0 (q̇ projected onto the kernel of A)."""
    rng = np.random.default_rng(seed)
    pars = dict(zip(eqs.parameters, eqs.values))
    A = sp.lambdify(eqs.q, eqs.A.xreplace(pars), "numpy")
    states = []
    for _ in range(count):
        q = rng.uniform(-2, 2, len(eqs.q))
        v = rng.normal(size=len(eqs.q))
        a = np.atleast_2d(np.asarray(A(*q), dtype=float))
        v -= a.T @ np.linalg.solve(a @ a.T, a @ v)
        states.append({**pars, **dict(zip(eqs.q, q)), **dict(zip(eqs.qdot, v))})
    return states


def check_against_lagranges_method(spec: dict) -> None:
    eqs = derive(parse_system(spec))
    reference = reference_accelerations(spec, eqs)
    args = [*eqs.q, *eqs.qdot, *eqs.parameters]
    ours = sp.lambdify(args, [*eqs.qddot, *eqs.multipliers], "numpy")
    theirs = sp.lambdify(args, list(reference), "numpy")
    for state in random_states(eqs, 20, seed=7):
        x = [state[s] for s in args]
        a, b = np.array(ours(*x), dtype=float), np.array(theirs(*x), dtype=float)
        assert np.allclose(a, b, rtol=REFERENCE_RTOL, atol=REFERENCE_RTOL * np.max(np.abs(b))), (a, b)


def test_sleigh_accelerations_agree_with_lagranges_method():
    check_against_lagranges_method(SLEIGH)


def test_particle_accelerations_agree_with_lagranges_method():
    check_against_lagranges_method(PARTICLE)


def test_a_failing_derivation_is_a_derivation_error_and_one_past_the_safety_cap_a_failure_not_a_verdict(monkeypatch):
    """No clock decides a derivation: sympy's failure is a DerivationError naming it; a derivation still
    running at the safety cap raises SafetyCapExceeded (the job fails saying so) and goes on to its end."""
    import threading

    from nonholonomic import bounded
    from nonholonomic.lagrangian import DerivationError, equations

    def fails(data):
        raise RuntimeError("never mind")

    monkeypatch.setattr(equations, "_derive", fails)
    with pytest.raises(DerivationError, match="never mind"):
        derive(parse_system({"coordinates": ["x", "y"], "L": "(x_dot**2 + y_dot**2)/2 - x*y"}))
    release = threading.Event()

    def waits(data):
        release.wait(60)
        raise RuntimeError("released")

    monkeypatch.setattr(equations, "_derive", waits)
    cap = bounded.safety_cap_s()
    bounded.set_safety_cap(0.05)
    try:
        with pytest.raises(bounded.SafetyCapExceeded, match="safety cap of 0.05 s"):
            derive(parse_system({"coordinates": ["x", "y"], "L": "(x_dot**2 + y_dot**2)/2 - 2*x*y"}))
    finally:
        bounded.set_safety_cap(cap)
        release.set()


def test_the_elimination_path_is_chosen_by_the_work_not_the_clock(monkeypatch):
    """An entry of the exact elimination past MAX_FRACTION_TERMS sends the system to the plain elimination,
    with the measure named: the same path on every machine (Suslov's problem reaches 248 terms)."""
    from nonholonomic.lagrangian import equations, fractions
    from nonholonomic.systems.lagrangian_classics import CLASSICS

    data = parse_system(CLASSICS["suslov"]["job"]["system"])
    assert equations._derive(data)[3] is True
    monkeypatch.setattr(fractions, "MAX_FRACTION_TERMS", 100)
    _, lam, _, closed_form, why = equations._derive(data)
    assert not closed_form and lam == () and "terms > max 100 (MAX_FRACTION_TERMS)" in why
    monkeypatch.setattr(equations, "FRACTIONS_MAX_OPS", 10)
    assert "operations > max 10 (FRACTIONS_MAX_OPS)" in equations._derive(data)[4]


def numeric(eqs):
    """The field, constraints and energy as numpy functions of (q, q̇) at the parameters' values."""
    pars = dict(zip(eqs.parameters, eqs.values))
    state = [*eqs.q, *eqs.qdot]
    field = sp.lambdify(state, [e.xreplace(pars) for e in eqs.rhs], "numpy")
    constraints = sp.lambdify(state, [c.xreplace(pars) for c in eqs.constraints], "numpy")
    energy = sp.lambdify(state, eqs.energy.xreplace(pars), "numpy")
    return (lambda t, y: np.array(field(*y), dtype=float)), constraints, energy


def integrate_and_check_integrals(eqs, y0, t_final: float):
    field, constraints, energy = numeric(eqs)
    assert np.max(np.abs(constraints(*y0))) < 1e-15
    t_eval = np.linspace(0.0, t_final, 401)
    sol = solve_ivp(field, (0.0, t_final), y0, t_eval=t_eval, **RK)
    assert sol.success
    assert np.max(np.abs(np.array(constraints(*sol.y)))) <= 1e-10
    assert np.max(np.abs(energy(*sol.y) - energy(*y0))) <= 1e-10
    return sol


def test_sleigh_follows_the_reduced_system():
    """Closed form (contact point (x, y), mass centre a ahead of it along the blade (cos θ, sin θ), J the
    inertia about the mass centre): v' = a ω², ω' = −m a v ω / (J + m a²), v = cos θ ẋ + sin θ ẏ, ω = θ̇.
    The derivation gives exactly this sign (θ̈ = −a m θ̇ (ẋ cos θ + ẏ sin θ)/(J + a² m)): with a > 0 the
    mass centre is ahead of the blade and the rotation dies out (the asymptotic straight motion)."""
    eqs = derive(parse_system(SLEIGH))
    m, a, J = (SLEIGH["parameters"][k] for k in ("m", "a", "J"))
    y0 = np.array([0.2, -0.1, 0.0, 0.9, 0.0, 0.7])  # -sin 0 * 0.9 + cos 0 * 0 = 0: on the constraint
    sol = integrate_and_check_integrals(eqs, y0, 20.0)
    th, xd, yd, thd = sol.y[2], sol.y[3], sol.y[4], sol.y[5]
    v_full, w_full = np.cos(th) * xd + np.sin(th) * yd, thd

    def reduced(t, s):
        v, w = s
        return [a * w**2, -m * a * v * w / (J + m * a**2)]

    red = solve_ivp(reduced, (0.0, 20.0), [0.9, 0.7], t_eval=sol.t, **RK)
    assert np.max(np.abs(v_full - red.y[0])) <= 1e-9
    assert np.max(np.abs(w_full - red.y[1])) <= 1e-9
    assert abs(v_full[-1] - red.y[0][-1]) <= 1e-9 and abs(w_full[-1] - red.y[1][-1]) <= 1e-9
    # the opposite sign of a would make ω grow: the comparison above is not blind to it
    flipped = solve_ivp(lambda t, s: [-a * s[1]**2, m * a * s[0] * s[1] / (J + m * a**2)], (0.0, 1.0),
                        [0.9, 0.7], **RK)
    assert abs(flipped.y[1][-1] - w_full[np.searchsorted(sol.t, 1.0)]) > 1e-2
    field, _, _ = numeric(eqs)
    late = solve_ivp(field, (0.0, 200.0), y0, **RK)
    assert abs(late.y[5][-1]) < 1e-2 * abs(y0[5])


def test_particle_keeps_its_constraint_and_energy():
    eqs = derive(parse_system(PARTICLE))
    y0 = np.array([0.3, 0.5, -0.2, 0.8, -0.4, 0.5 * 0.8])  # z_dot = y x_dot
    integrate_and_check_integrals(eqs, y0, 20.0)


def test_sleigh_equations_are_short_and_energy_is_the_kinetic_energy():
    eqs = derive(parse_system(SLEIGH))
    m, a, J, theta = (sp.Symbol(s, real=True) for s in ("m", "a", "J", "theta"))
    x_dot, y_dot, theta_dot = eqs.qdot
    expected = -a * m * theta_dot * (x_dot * sp.cos(theta) + y_dot * sp.sin(theta)) / (J + a**2 * m)
    assert sp.cancel(eqs.qddot[2] - expected) == 0
    assert all(sp.count_ops(e) < 40 for e in eqs.qddot)
    assert eqs.energy.equals(eqs.L)  # no potential: E = T
    assert not eqs.time_dependent


def test_unconstrained_and_time_dependent_lagrangians():
    eqs = derive(parse_system({"coordinates": ["x"], "L": "x_dot**2/2 - x**2/2*(1 + eps*cos(t))",
                               "parameters": {"eps": 0.1}}))
    x, eps, t = eqs.q[0], eqs.parameters[0], eqs.t
    assert sp.simplify(eqs.qddot[0] + x * (1 + eps * sp.cos(t))) == 0
    assert eqs.energy is None and eqs.multipliers == () and eqs.time_dependent


def test_a_pivot_that_vanishes_by_an_identity_is_not_used():
    """M = [[cosh²x − sinh²x − 1, 1], [1, 0]] = [[0, 1], [1, 0]]: ``cancel`` does not see the zero, the
    numeric zero test does, and LU pivots on the other row; q̈ = −M⁻¹ ∂U/∂q = (−y, −x)."""
    eqs = derive(parse_system({"coordinates": ["x", "y"],
                               "L": "(cosh(x)**2 - sinh(x)**2 - 1)*x_dot**2/2 + x_dot*y_dot - x**2/2 - y**2/2"}))
    x, y = eqs.q
    assert [sp.simplify(e) for e in eqs.qddot] == [-y, -x]


def with_(**changes) -> dict:
    return {**SLEIGH, **changes}


REFUSALS = [
    (with_(constraints=["x_dot**2 - y_dot"]), "constraints[0]", "linear"),
    (with_(constraints=["x_dot*theta_dot"]), "constraints[0]", "linear"),
    (with_(constraints=["sin(x_dot)"]), "constraints[0]", "linear"),
    (with_(constraints=["x_dot - 1"]), "constraints[0]", "homogeneous"),
    (with_(constraints=["x_dot - y_dot", "y_dot + k*theta_dot"]), "constraints[1]", "k"),
    (with_(L="m/2*x_dot**2 + q0*y_dot**2"), "L", "q0"),
    ({"coordinates": ["x", "y"], "L": "x_dot**2/2"}, "L", "y_dot"),
    ({"coordinates": ["x", "y"], "L": "(x_dot + y_dot)**2/2"}, "L", "singular"),
    (with_(parameters={"m": 0.0, "a": 0.4, "J": 0.0}), "L", "singular"),
    ({"coordinates": ["x", "y"], "L": "x_dot**3 + y_dot**2"}, "L", "degree 3"),
    ({"coordinates": ["x", "y"], "L": "sqrt(1 + x_dot**2) + y_dot**2"}, "L", "polynomial"),
    (with_(constraints=["x_dot - y_dot", "2*x_dot - 2*y_dot"]), "constraints[1]", "depends"),
    (with_(constraints=["cos(theta)*x_dot", "sin(theta)*cos(theta)*x_dot"]), "constraints[1]", "depends"),
    (with_(constraints=["x_dot", "y_dot", "theta_dot"]), "constraints", "at most 2"),
    ({"coordinates": ["x", "y", "z"], "L": "(x_dot**2 - y_dot**2 + z_dot**2)/2", "constraints": ["x_dot + y_dot"]},
     "constraints", "A M^-1 A^T"),
    (with_(coordinates=["x", "x", "theta"]), "coordinates", "twice"),
    (with_(parameters={"m": 1.3, "a": 0.4, "J": 0.25, "x": 1.0}), "parameters", "twice"),
    (with_(coordinates=["t", "y", "theta"]), "coordinates", "reserved"),
    (with_(coordinates=["x", "y", "sin"]), "coordinates", "sin"),
    (with_(parameters={"m": 1.3, "a": 0.4, "J": 0.25, "x_dot": 1.0}), "parameters", "_dot"),
    (with_(parameters={"m": 1.3, "a": 0.4, "J": 0.25, "k": 1.0}), "parameters.k", "not used"),
    (with_(parameters={"m": float("nan"), "a": 0.4, "J": 0.25}), "parameters.m", "finite"),
    (with_(L="x_dot^2"), "L", "**"),
    (with_(kind="veselova"), "kind", "lagrangian"),
]


@pytest.mark.parametrize(("spec", "field", "word"), REFUSALS, ids=[f"{f}-{w}" for _, f, w in REFUSALS])
def test_refusals_name_the_field(spec, field, word):
    with pytest.raises(DataError) as info:
        parse_system(spec)
    assert info.value.field == field, str(info.value)
    assert word in info.value.reason, str(info.value)


@pytest.mark.parametrize("field", ["L", "constraints[0]"])
def test_expressions_are_never_evaluated(field, monkeypatch):
    def forbidden(*args, **kwargs):
        raise AssertionError("os.system was called")

    monkeypatch.setattr(os, "system", forbidden)
    attack = "__import__('os').system('echo pwned')"
    spec = with_(L=attack) if field == "L" else with_(constraints=[attack])
    with pytest.raises(DataError) as info:
        parse_system(spec)
    assert info.value.field == field
    with pytest.raises(DataError) as info:
        parse_system(with_(constraints=["x_dot", "(lambda: 1)()"]))
    assert info.value.field == "constraints[1]"


@pytest.mark.parametrize("name", ["rolling_disk", "chaplygin_sleigh"])  # (suslov_tilted: 33 s, the same paths)
def test_the_rational_function_elimination_equals_the_expression_tree_fallback(name, monkeypatch):
    """The exact fraction-field path (sin, cos as generators with sin² + cos² = 1) and the LU on expression trees
    give the same q̈ at random states to 1e-12 (and the fast path is the one used)."""
    from nonholonomic.lagrangian import equations
    from nonholonomic.systems.lagrangian_classics import CLASSICS

    data = parse_system(CLASSICS[name]["job"]["system"])
    fast = equations._derive_in_fractions(data)
    assert fast is not None
    monkeypatch.setattr(equations, "_derive_in_fractions", lambda data: None)
    slow = equations._derive(data)
    rng = np.random.default_rng(7)
    symbols = (*data.q, *data.v)
    for _ in range(4):
        point = {s: float(x) for s, x in zip(symbols, rng.uniform(0.2, 0.8, len(symbols)))}
        point.update(data.parameter_values)
        for a, b in zip(fast[0], slow[0]):
            x, y = float(a.xreplace(point)), float(b.xreplace(point))
            assert abs(x - y) <= 1e-12 * max(1.0, abs(y))


@pytest.mark.parametrize("name", ["suslov_tilted", "rolling_disk", "chaplygin_sleigh"])
def test_the_projected_elimination_without_cancellation_equals_the_exact_one_on_the_manifold(name, monkeypatch):
    """The path for systems too large for the exact elimination (Bᵀ M B u̇ = −Bᵀ(h + M c), no cancellation) gives
    the exact path's q̈ at random states on the constraint manifold to 1e-10, and keeps A q̇ constant off it."""
    from nonholonomic.lagrangian import equations
    from nonholonomic.systems.lagrangian_classics import CLASSICS

    data = parse_system(CLASSICS[name]["job"]["system"])
    exact = equations._derive_in_fractions(data)[0]
    monkeypatch.setattr(equations, "FRACTIONS_MAX_OPS", 0)
    qddot, lam, _, closed_form, _ = equations._derive(data)
    assert not closed_form and lam == ()
    args = (*data.q, *data.v)
    values = dict(data.parameter_values)
    rng = np.random.default_rng(5)
    for _ in range(4):
        point = dict(zip(args, rng.uniform(0.2, 0.8, len(args))))
        point.update(values)
        A = np.array([[float(data.A[a, j].xreplace(point)) for j in range(len(data.q))]
                      for a in range(data.A.shape[0])])
        # d/dt (A q̇) = Ȧ q̇ + A q̈ = 0 at any q̇ (off the manifold too)
        adot = [float(sum(sp.diff(f, qj) * vj for qj, vj in zip(data.q, data.v)).xreplace(point))
                for f in data.constraints]
        plain = np.array([float(e.xreplace(point)) for e in qddot])
        assert np.max(np.abs(A @ plain + np.array(adot))) < 1e-10
        # on the manifold: the dependent velocities solved from the constraints
        dep = list(equations.dependent_columns(data))
        ind = [j for j in range(len(data.q)) if j not in dep]
        v = np.array([point[s] for s in data.v])
        v[dep] = np.linalg.solve(A[:, dep], -A[:, ind] @ v[ind])
        point.update(zip(data.v, v))
        a = np.array([float(e.xreplace(point)) for e in qddot])
        b = np.array([float(e.xreplace(point)) for e in exact])
        assert np.max(np.abs(a - b)) <= 1e-10 * max(1.0, np.max(np.abs(b)))
