"""The search for integrals linear and quadratic in the velocities (nonholonomic.lagrangian.integral_search): the
energy is found in the ansatz (and equals E = (q_dot, dL/dq_dot) - L on the manifold); the known extra
integrals are found (the nonholonomic particle without potential: y_dot and z y_dot - (1 + y^2) x_dot; the
Suslov problem with the constraint along a principal axis: the body angular velocities omega_1, omega_2 and
the three components of the spatial angular velocity; a charge in a magnetic field: its three linear
integrals); the sleigh, the tilted Suslov problem and the rolling disk have only the energy there; every
integral listed is conserved along a heyoka integration to 1e-10, while a quantity that is not an integral
drifts."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from nonholonomic.lagrangian import derive, parse_system
from nonholonomic.lagrangian.integral_search import NOT_EXHAUSTIVE, integral_search
from nonholonomic.numerics.integration import integrate
from nonholonomic.systems.lagrangian import define
from tests.lagrangian_examples import PARTICLE, SLEIGH

#: The nonholonomic particle without potential.
FREE_PARTICLE = dict(PARTICLE, L="(x_dot**2 + y_dot**2 + z_dot**2)/2", parameters={})
#: A charge in the plane in a uniform magnetic field b (a gyroscopic term: linear in the velocities).
MAGNETIC = {"kind": "lagrangian", "coordinates": ["x", "y"],
            "L": "(x_dot**2 + y_dot**2)/2 + b/2*(x*y_dot - y*x_dot)", "parameters": {"b": 0.7}}
#: The Suslov problem in Euler angles (z-x-z), principal inertia I1, I2, I3, the constraint omega_3 = 0.
SUSLOV_L = ("I1/2*(phi_dot*sin(theta)*sin(psi) + theta_dot*cos(psi))**2 + I2/2*(phi_dot*sin(theta)*cos(psi) "
            "- theta_dot*sin(psi))**2 + I3/2*(phi_dot*cos(theta) + psi_dot)**2")
SUSLOV = {"kind": "lagrangian", "coordinates": ["phi", "theta", "psi"], "L": SUSLOV_L,
          "constraints": ["phi_dot*cos(theta) + psi_dot"], "parameters": {"I1": 1.0, "I2": 2.0, "I3": 3.0}}
#: The same with the constraint (a, omega) = 0, a = (0.6, 0, 0.8) not a principal axis.
SUSLOV_TILTED = dict(SUSLOV, constraints=[("ca*(phi_dot*cos(theta) + psi_dot) + sa*(phi_dot*sin(theta)*sin(psi) "
                                           "+ theta_dot*cos(psi))")],
                     parameters={"I1": 1.0, "I2": 2.0, "I3": 3.0, "ca": 0.8, "sa": 0.6})
#: The rolling disk: contact point (x, y), Euler angles (phi, theta, psi), theta the tilt.
DISK = {"kind": "lagrangian", "coordinates": ["x", "y", "phi", "theta", "psi"],
        "L": "m/2*(x_dot**2 + y_dot**2 + R**2*cos(theta)**2*theta_dot**2)"
             " + A/2*(theta_dot**2 + phi_dot**2*sin(theta)**2)"
             " + C/2*(psi_dot + phi_dot*cos(theta))**2 - m*g*R*sin(theta)",
        "constraints": ["x_dot + R*(phi_dot*cos(phi)*cos(theta) + psi_dot*cos(phi) - theta_dot*sin(phi)*sin(theta))",
                        "y_dot + R*(phi_dot*sin(phi)*cos(theta) + psi_dot*sin(phi) + theta_dot*sin(theta)*cos(phi))"],
        "parameters": {"m": 1.0, "R": 1.0, "A": 0.25, "C": 0.5, "g": 9.81}}


def manifold_state(data, search, q0, u0) -> np.ndarray:
    """(q, q_dot) with the independent velocities u0 and the others solved from A(q0) q_dot = 0."""
    pars = data.parameter_values
    A = np.array(sp.Matrix(data.A).xreplace(pars).xreplace(dict(zip(data.q, q0))), dtype=float).reshape(-1, len(q0))
    ind = [data.v.index(u) for u in search.velocities]
    dep = [j for j in range(len(q0)) if j not in ind]
    v = np.zeros(len(q0))
    v[ind] = u0
    if dep:
        v[dep] = np.linalg.solve(A[:, dep], -A[:, ind] @ np.asarray(u0, dtype=float))
    return np.concatenate([q0, v])


def numeric(data, expr):
    """``expr`` as a numpy function of the state (q, q_dot), parameters at their values."""
    return sp.lambdify([*data.q, *data.v], sp.sympify(expr).xreplace(data.parameter_values), "numpy")


def random_states(data, search, count: int, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [manifold_state(data, search, rng.uniform(0.3, 1.2, len(data.q)), rng.normal(size=len(search.velocities)))
            for _ in range(count)]


def span_rank(data, search, exprs) -> int:
    """The rank of the functions ``exprs`` on the manifold (values at 40 random states)."""
    functions = [numeric(data, e) for e in exprs]
    values = np.array([[float(f(*x)) for f in functions] for x in random_states(data, search, 40, 3)])
    s = np.linalg.svd(values, compute_uv=False)
    return int(np.sum(s > 1e-9 * s[0]))


def search_of(spec):
    data = parse_system(spec)
    search = integral_search(data)
    assert search.status == "done", search.reason
    assert all(i.proven for i in search.integrals)
    assert NOT_EXHAUSTIVE in search.reason
    return data, search


def of_degree(search, degree: int) -> list:
    return [i for i in search.integrals if i.degree == degree and i.name != "energy"]


@pytest.mark.parametrize("spec", [SLEIGH, PARTICLE, DISK], ids=["sleigh", "particle", "disk"])
def test_the_energy_is_found_in_the_ansatz_and_equals_e_on_the_manifold(spec):
    data, search = search_of(spec)
    energy = search.integrals[0]
    assert energy.name == "energy" and energy.degree == 2 and energy.proven
    assert "added" not in energy.formula  # found by the search, not added from L
    ours, theirs = numeric(data, energy.expression), numeric(data, derive(data).energy)
    for x in random_states(data, search, 10, 1):
        assert abs(ours(*x) - theirs(*x)) <= 1e-12 * max(1.0, abs(theirs(*x)))


def test_sleigh_has_no_linear_integral_in_the_ansatz():
    _, search = search_of(SLEIGH)
    assert [i.name for i in search.integrals] == ["energy"]
    assert "0 linear" in search.reason and "not in the ansatz" in search.reason
    assert "Delta = cos(theta)" in search.ansatz  # y_dot = tan(theta) x_dot: the ansatz has 1/cos(theta)^k


def test_particle_with_potential_separates_the_y_oscillator():
    """The constraint leaves y alone, ÿ = −k y: ẏ² + k y² is an integral, and so is E minus its half,
    ((1 + y²)ẋ² + k(x² + z²) + 2 g z)/2; the search finds that plane of quadratic integrals."""
    data, search = search_of(PARTICLE)
    assert of_degree(search, 1) == []
    x, y, z, x_dot, y_dot, _ = (*data.q, *data.v)
    k, g = data.parameters
    found = [search.integrals[0].expression] + [i.expression for i in of_degree(search, 2)]
    expected = [y_dot**2 + k * y**2, (1 + y**2) * x_dot**2 + k * (x**2 + z**2) + 2 * g * z]
    assert len(found) == 2
    assert span_rank(data, search, found) == span_rank(data, search, found + expected) == 2
    assert span_rank(data, search, found + [y_dot**2]) == 3  # not an integral


def test_free_particle_has_two_linear_integrals():
    """ÿ = 0 and (1 + y²)ẍ = −y ẋ ẏ: ẏ and z ẏ − (1 + y²) ẋ are integrals, (1 + y²) ẋ is not."""
    data, search = search_of(FREE_PARTICLE)
    _, y, z, x_dot, y_dot, _ = (*data.q, *data.v)
    linear = [i.expression for i in of_degree(search, 1)]
    expected = [y_dot, z * y_dot - (1 + y**2) * x_dot]
    assert len(linear) == 2
    assert span_rank(data, search, linear) == span_rank(data, search, linear + expected) == 2
    assert span_rank(data, search, linear + [(1 + y**2) * x_dot]) == 3


def test_suslov_has_the_body_and_the_spatial_angular_velocities():
    """ω₃ = 0 along a principal axis: I₁ω̇₁ = I₂ω̇₂ = 0, so ω₁, ω₂ and the spatial ω = R ω are constant."""
    data, search = search_of(SUSLOV)
    phi, theta, psi, phi_dot, theta_dot, _ = (*data.q, *data.v)
    psi_dot = -phi_dot * sp.cos(theta)  # the constraint
    s, c = sp.sin, sp.cos
    expected = [phi_dot * s(theta) * s(psi) + theta_dot * c(psi), phi_dot * s(theta) * c(psi) - theta_dot * s(psi),
                theta_dot * c(phi) + psi_dot * s(phi) * s(theta), theta_dot * s(phi) - psi_dot * c(phi) * s(theta),
                phi_dot + psi_dot * c(theta)]
    linear = [i.expression for i in of_degree(search, 1)]
    assert len(linear) == 5
    assert span_rank(data, search, linear) == span_rank(data, search, linear + expected) == 5
    assert of_degree(search, 2) == [] and search.omitted >= 1  # ω₁², ω₁ω₂, ...: products, not listed


@pytest.mark.parametrize("spec", [SUSLOV_TILTED, DISK], ids=["tilted-suslov", "disk"])
def test_only_the_energy_in_the_ansatz(spec):
    _, search = search_of(spec)
    assert [i.name for i in search.integrals] == ["energy"]
    assert "0 linear and 0 other quadratic" in search.reason


def test_gyroscopic_lagrangian_has_its_momenta():
    """ẍ = b ẏ, ÿ = −b ẋ: ẋ − b y, ẏ + b x and x ẏ − y ẋ + b (x² + y²)/2 (with a part free of velocities)."""
    data, search = search_of(MAGNETIC)
    assert "apart" not in search.ansatz  # L is not even in the velocities: one linear system
    x, y, x_dot, y_dot = (*data.q, *data.v)
    (b,) = data.parameters
    expected = [x_dot - b * y, y_dot + b * x, x * y_dot - y * x_dot + b * (x**2 + y**2) / 2]
    linear = [i.expression for i in of_degree(search, 1)]
    assert len(linear) == 3
    assert span_rank(data, search, linear) == span_rank(data, search, linear + expected) == 3


def test_an_integrable_constraint_gives_a_function_of_the_coordinates():
    spec = {"coordinates": ["x", "y", "z"], "L": "(x_dot**2 + y_dot**2 + z_dot**2)/2 - y**2/2",
            "constraints": ["z_dot - x_dot"]}
    data, search = search_of(spec)
    x, _, z = data.q
    functions = [i.expression for i in search.integrals if i.degree == 0]
    assert functions and span_rank(data, search, functions[:1] + [x - z]) == 1


CASES = [(SLEIGH, [0.2, -0.1, 0.3], [0.9, 0.7], None), (PARTICLE, [0.3, 0.5, -0.2], [0.8, -0.4], None),
         (FREE_PARTICLE, [0.3, 0.5, -0.2], [0.8, -0.4], "(1 + y**2)*x_dot"),
         (MAGNETIC, [0.3, -0.4], [0.5, 0.2], "x_dot"),
         (SUSLOV, [0.3, 0.9, 0.4], [0.7, -0.5], "phi_dot"),
         (DISK, [0.0, 0.0, 0.2, 1.1, 0.1], [0.8, 0.3, 2.0], "phi_dot")]


@pytest.mark.parametrize("spec, q0, u0, drifting", CASES,
                         ids=["sleigh", "particle", "free-particle", "magnetic", "suslov", "disk"])
def test_every_integral_is_conserved_along_the_motion(spec, q0, u0, drifting):
    data, search = search_of(spec)
    system = define(data)
    y0 = manifold_state(data, search, np.array(q0), np.array(u0))
    trajectory = integrate(system, np.array(data.values), y0, 10.0, 201)
    for integral in search.integrals:
        f = numeric(data, integral.expression)
        values = np.array([f(*state) for state in trajectory.states], dtype=float)
        assert np.max(np.abs(values - values[0])) <= 1e-10 * max(1.0, abs(values[0])), integral.formula
    if drifting:  # the check sees a quantity that is not conserved
        f = numeric(data, sp.sympify(drifting, locals={str(s): s for s in (*data.q, *data.v)}))
        values = np.array([f(*state) for state in trajectory.states], dtype=float)
        assert np.max(np.abs(values - values[0])) > 1e-3


def test_time_dependent_lagrangian_is_not_searched():
    data = parse_system({"coordinates": ["x"], "L": "x_dot**2/2 - x**2/2*(1 + eps*cos(t))", "parameters": {"eps": 0.1}})
    search = integral_search(data)
    assert search.status == "undecided" and "depends on t" in search.reason and search.integrals == ()


def test_a_proof_past_its_work_limit_is_not_tried_and_says_so(monkeypatch):
    """The proofs are bounded by their size (MAX_PROOF_TERMS), not by a clock: past it the integral is listed
    unproven with the measure named, and the search is partial."""
    from nonholonomic.lagrangian import integral_search as integrals

    monkeypatch.setattr(integrals, "MAX_PROOF_TERMS", 0)
    data = parse_system(dict(SLEIGH, parameters={"m": 1.1, "a": 0.3, "J": 0.2}))  # not searched before
    search = integral_search(data)
    assert search.status == "partial" and NOT_EXHAUSTIVE in search.reason
    assert [i.name for i in search.integrals] == ["energy"]
    assert all(i.proof.startswith("unproven: the proof not tried:") and "(MAX_PROOF_TERMS)" in i.proof
               and not i.proven for i in search.integrals)
