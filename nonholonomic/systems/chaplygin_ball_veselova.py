"""Chaplygin's ball with the Veselova constraint (ω, E) = 0, E a space-fixed unit vector.

Paper, section "Realization of constraints. Chaplygin's ball with the Veselova constraint",
eq. (2704-2)–(2704-6). The spherical support realization leads to eq. (2704-4)::

    I dω/dt + D γ × (dω/dt × γ) = Iω × ω + μ E + M_Q,    dγ/dt = γ × ω,    dE/dt = E × ω,
    M_Q = γ × ∂U/∂γ + E × ∂U/∂E,

the equations of Chaplygin's ball (eq. 2604-1) with the extra constraint (ω, E) = 0 (eq. 2704-2).

The left-hand side is written as ``I_Q dω/dt`` with ``I_Q = J − D γ⊗γ``, ``J = I + D·1`` (the
ball's contact inertia, :func:`nonholonomic.systems.chaplygin_ball.contact_inertia`). The two forms
agree only on |γ| = 1 (``I x + D γ×(x×γ) = (I + D|γ|²) x − D (γ, x) γ``). Both were checked: with
either form (and ρ, the energy and K built from the same form) the density is invariant on all of
R⁹ and the integrals hold as listed below, so neither is singled out; ``J − D γ⊗γ`` is used
because it is the ball's I_Q (same symbols, Sherman–Morrison, det I_Q = det J (1 − D (γ, J⁻¹γ)))
and because with it the case E = γ is exactly the Veselova system with I → J on all of R⁶
(:mod:`nonholonomic.systems.rubber_ball`).

The multiplier is derived, not copied: sympy solves ``I_Q dω/dt = n + μ E`` (n = Iω×ω + M_Q)
together with ``d/dt (ω, E) = (dω/dt, E) + (ω, E × ω) = 0`` for (dω/dt, μ), for a generic symmetric
matrix in place of I_Q (:func:`constrained_acceleration`). The result is

    μ = −(Iω × ω + M_Q, I_Q⁻¹E) / (E, I_Q⁻¹E),
    dω/dt = (I_Q (E × n)) × E / (E, adj(I_Q) E),

so the numerator needs I_Q⁻¹E; the printed multiplier after eq. (2704-4) has I⁻¹E there
(ERRATA 9), and with it (ω, E) leaves zero (the tests integrate both). "J = I + D" means I + D·1.

Integrals (text after eq. 2704-5): the energy H = ½(I_Q ω, ω) + U(γ, E), the geometric integrals
γ² = 1, E² = 1, (γ, E) = const, and the constraint (ω, E) itself; for U = 0 (eq. 2704-6)

    F1 = (K, E × γ),    F2 = (K, E × (E × γ)),    K = I_Q ω − (I_Q ω, E) E,

since dK/dt = K × ω on E² = 1 (K is space-fixed). F1 and F2 are independent only where
E × γ ≠ 0; at E = ±γ both vanish identically (that case is the rubber ball). Invariant measure
(eq. 2704-5)

    ρ_ω = ((E, I_Q⁻¹E) det I_Q)^(1/2) = (E, adj(I_Q) E)^(1/2)

for d³ω d³γ d³E (E is a state variable here; the paper writes d³ω d³γ). The paper gives no time
substitution for this system (reduced time: none).

Where each claim holds off the constraint surfaces (all checked in the tests): (ω, E), γ², E²,
(γ, E), F1, F2 and the measure hold on all of R⁹ (dK/dt − K × ω = μ (1 − E²) E is parallel to E,
hence orthogonal to E × γ and E × (E × γ)); dH/dt = μ (ω, E), so the energy needs (ω, E) = 0.
"""

from __future__ import annotations

import sys
from functools import cache, lru_cache

import sympy as sp

from nonholonomic.definition import (
    FirstIntegral,
    InvariantMeasure,
    MechanicalSystem,
    Parameter,
    Projection,
    StateConstraint,
    StateVector,
    cross,
    dot,
    gradient,
    vector_symbols,
)
from nonholonomic.kinds import Sampling, SystemKind, root_words
from nonholonomic.memo import remembered
from nonholonomic.potentials import ZERO, Potential, catalog_of, linear, resolve
from nonholonomic.systems.chaplygin_ball import (
    I1,
    I2,
    I3,
    D,
    contact_inertia,
    contact_inertia_inverse,
    inertia,
)

KIND = "chaplygin_ball_veselova"
TITLE = "Chaplygin's ball with the Veselova constraint (omega, E) = 0, E a space-fixed unit vector"

omega = vector_symbols("omega")
gamma = vector_symbols("gamma")
E = vector_symbols("E")

PARAMETERS = (
    Parameter("inertia", (I1, I2, I3), "principal moments of inertia I1, I2, I3 about the centre", "kg m^2",
              minimum=0.0, strict=True),
    Parameter("D", (D,), "D = m R^2 for the ball (D = (R/R1)^2 D1 for the spherical support, eq. 2704-4)",
              "kg m^2", minimum=0.0),
)

POTENTIALS = catalog_of(ZERO, linear("gamma", also_on="E"))
#: The state vectors a potential of this kind may depend on (an expression potential uses their components).
POTENTIAL_VARIABLES = ("gamma", "E")

#: A job request for this kind (the catalog shows it; tests and benchmarks run it).
EXAMPLE = {
    "system": {"kind": KIND, "inertia": [2.0, 3.0, 4.5], "D": 0.7, "potential": {"kind": "zero"}},
    "initial_state": {"omega": [0.4, -0.2, -0.3], "gamma": [0.0, 0.6, 0.8], "E": [0.6, 0.0, 0.8]},
    "t_final": 1000.0, "samples": 201,
}

STATE = (
    StateVector("omega", tuple(omega), "angular velocity, body frame", "rad/s"),
    StateVector("gamma", tuple(gamma), "unit normal to the plane (axis through the balls' centres), body frame",
                "1"),
    StateVector("E", tuple(E), "unit vector of the space-fixed axis of the Veselova constraint, body frame", "1"),
)


@cache
def _generic_solution() -> tuple[sp.Matrix, sp.Matrix, sp.Matrix, tuple[sp.Expr, ...], sp.Expr]:
    """Solve ``A ω' = n + μ e``, ``(ω', e) + (ω, e × ω) = 0`` for (ω', μ) with A, n, e generic."""
    entries = {(i, j): sp.Dummy(f"A{i + 1}{j + 1}", real=True) for i in range(3) for j in range(i, 3)}
    A = sp.Matrix(3, 3, lambda i, j: entries[(min(i, j), max(i, j))])
    n = sp.Matrix([sp.Dummy(f"n{i}", real=True) for i in range(1, 4)])
    e = sp.Matrix([sp.Dummy(f"e{i}", real=True) for i in range(1, 4)])
    w = sp.Matrix([sp.Dummy(f"w{i}", real=True) for i in range(1, 4)])
    w_dot = sp.Matrix([sp.Dummy(f"wdot{i}", real=True) for i in range(1, 4)])
    mu = sp.Dummy("mu", real=True)
    # d/dt (ω, e) = (dω/dt, e) + (ω, de/dt) with de/dt = e × ω (a space-fixed vector in body axes)
    equations = list(A * w_dot - n - mu * e) + [sp.expand(dot(w_dot, e) + dot(w, cross(e, w)))]
    (solution,) = sp.solve(equations, list(w_dot) + [mu], dict=True)
    return A, n, e, tuple(sp.factor(solution[x]) for x in w_dot), sp.factor(solution[mu])


def constrained_acceleration(A: sp.Matrix, n: sp.Matrix, e: sp.Matrix) -> tuple[sp.Matrix, sp.Expr]:
    """``(dω/dt, μ)`` from ``A dω/dt = n + μ e`` and ``d/dt (ω, e) = 0`` with ``de/dt = e × ω``.

    Solved by sympy once for a generic symmetric ``A`` and generic vectors, then substituted, so
    the result is ``μ = −(n, adj(A) e) / (e, adj(A) e)`` and
    ``dω/dt = (A (e × n)) × e / (e, adj(A) e)``, rational with one denominator.
    """
    A_g, n_g, e_g, w_dot, mu = _generic_solution()
    values = {A_g[i, j]: A[i, j] for i in range(3) for j in range(i, 3)}
    values.update(zip(n_g, n))
    values.update(zip(e_g, e))
    return sp.Matrix([x.xreplace(values) for x in w_dot]), mu.xreplace(values)


def potential_torque(U: sp.Expr) -> sp.Matrix:
    """``M_Q = γ × ∂U/∂γ + E × ∂U/∂E`` (text after eq. 2704-5)."""
    return cross(gamma, gradient(U, gamma)) + cross(E, gradient(U, E))


def free_torque(U: sp.Expr) -> sp.Matrix:
    """``n = Iω × ω + M_Q``: the right-hand side of eq. (2704-4) without μE."""
    return cross(inertia * omega, omega) + potential_torque(U)


def constraint_multiplier(U: sp.Expr) -> sp.Expr:
    """μ derived from ``d/dt (ω, E) = 0``: ``−(Iω×ω + M_Q, adj(I_Q) E) / (E, adj(I_Q) E)``."""
    return constrained_acceleration(contact_inertia(gamma), free_torque(U), E)[1]


def equations_of_motion(U: sp.Expr, mu: sp.Expr) -> tuple[sp.Expr, ...]:
    """``(dω/dt, dγ/dt, dE/dt)`` of eq. (2704-4) for a given multiplier expression μ
    (``dω/dt = I_Q⁻¹ (Iω×ω + μE + M_Q)``, I_Q⁻¹ by Sherman–Morrison); used to build variants."""
    omega_dot = contact_inertia_inverse(gamma) * (free_torque(U) + mu * E)
    return tuple(omega_dot) + tuple(cross(gamma, omega)) + tuple(cross(E, omega))


def measure_density(g: sp.Matrix = gamma, e: sp.Matrix = E) -> sp.Expr:
    """``ρ_ω = ((E, I_Q⁻¹E) det I_Q)^(1/2) = (E, adj(I_Q) E)^(1/2)`` (eq. 2704-5), polynomial under the root."""
    return sp.sqrt(dot(e, contact_inertia(g).adjugate() * e))


def space_fixed_vector() -> sp.Matrix:
    """``K = I_Q ω − (I_Q ω, E) E`` (eq. 2704-6); for U = 0, dK/dt = K × ω + μ (1 − E²) E."""
    IQw = contact_inertia(gamma) * omega
    return IQw - dot(IQw, E) * E


@lru_cache(maxsize=64)  # as the kernels and integrators compiled from it
@remembered("definition")  # derived once per machine and version (nonholonomic.memo)
def define(potential: str | Potential = "zero") -> MechanicalSystem:
    """Chaplygin's ball with the Veselova constraint and the potential ``potential`` (a key of
    :data:`POTENTIALS`).

    Returns
    -------
    MechanicalSystem
        The right-hand side of eq. (2704-4) with μ derived from d/dt (ω, E) = 0, the integrals
        (text after eq. 2704-5; F1, F2 of eq. 2704-6 for U = 0), the measure of eq. (2704-5) and no
        reduced time.
    """
    pot = resolve(POTENTIALS, potential)
    variables = {"gamma": gamma, "E": E, "I": inertia}
    U = pot.build(variables)
    omega_dot, _ = constrained_acceleration(contact_inertia(gamma), free_torque(U), E)
    rhs = tuple(omega_dot) + tuple(cross(gamma, omega)) + tuple(cross(E, omega))

    IQw = contact_inertia(gamma) * omega
    kinetic = dot(IQw, omega) / 2
    norm_w, norm_g, norm_E = (sp.sqrt(dot(v, v)) for v in (omega, gamma, E))
    integrals = [
        FirstIntegral("energy", kinetic + U, kinetic + pot.scale(variables),
                      "H = (I_Q omega, omega)/2 + U(gamma, E), I_Q = J - D gamma⊗gamma", "after 2704-5"),
        FirstIntegral("geometric", dot(gamma, gamma), dot(gamma, gamma), "(gamma, gamma)", "after 2704-5"),
        FirstIntegral("E_squared", dot(E, E), dot(E, E), "(E, E)", "after 2704-5"),
        FirstIntegral("gamma_E", dot(gamma, E), norm_g * norm_E, "(gamma, E)", "after 2704-5"),
        FirstIntegral("constraint", dot(omega, E), norm_w * norm_E, "(omega, E) = 0", "2704-2"),
    ]
    if pot.kind == "zero":
        K = space_fixed_vector()
        Exg = cross(E, gamma)
        size = sp.sqrt(dot(IQw, IQw)) * norm_g
        integrals += [
            FirstIntegral("F1", dot(K, Exg), size * norm_E, "F1 = (K, E x gamma), K = I_Q omega - (I_Q omega, E) E",
                          "2704-6"),
            FirstIntegral("F2", dot(K, cross(E, Exg)), size * norm_E**2,
                          "F2 = (K, E x (E x gamma)), K = I_Q omega - (I_Q omega, E) E", "2704-6"),
        ]

    return MechanicalSystem(
        kind=KIND,
        potential=pot.kind,
        title=TITLE,
        equation="2704-4",
        parameters=PARAMETERS + pot.parameters,
        state=STATE,
        rhs=rhs,
        integrals=tuple(integrals),
        measure=InvariantMeasure(measure_density(),
                                 "rho_omega = ((E, I_Q^-1 E) det I_Q)^(1/2) = (E, adj(I_Q) E)^(1/2) "
                                 "for d^3omega d^3gamma d^3E", "2704-5"),
        reduced_time=None,
        potential_formula=pot.formula,
        constraints=(
            StateConstraint("gamma", norm_g, 1.0, "|gamma| = 1", "after 2704-5",
                            projection=Projection("gamma", tuple(gamma / norm_g), "gamma -> gamma / |gamma|")),
            StateConstraint("E", norm_E, 1.0, "|E| = 1", "after 2704-5",
                            projection=Projection("E", tuple(E / norm_E), "E -> E / |E|")),
            StateConstraint("omega", dot(omega, E), 0.0, "(omega, E) = 0", "2704-2", scale=norm_w * norm_E,
                            projection=Projection("omega", tuple(omega - dot(omega, E) / dot(E, E) * E),
                                                  "omega -> omega - (omega, E) E / (E, E)")),
        ),
        notes=(
            "mu = -(I omega x omega + M_Q, I_Q^-1 E) / (E, I_Q^-1 E): derived from d/dt (omega, E) = 0; the printed "
            "multiplier after eq. 2704-4 has I^-1 E in the numerator (ERRATA 9), which lets (omega, E) drift",
            "I dw/dt + D gamma x (dw/dt x gamma) is written I_Q dw/dt with I_Q = J - D gamma⊗gamma, J = I + D·1 "
            "(equal on |gamma| = 1)",
            "F1 and F2 (U = 0) are independent only where E x gamma != 0; for E = gamma they vanish identically "
            "(see kind rubber_ball)",
            "the energy needs (omega, E) = 0 (dH/dt = mu (omega, E)); (omega, E), gamma^2, E^2, (gamma, E), F1, F2 "
            "and the measure hold on all of R^9",
        ),
    )


#: The kind's record (nonholonomic.kinds): sampling on a level of H and (gamma, E).
SYSTEM_KIND = SystemKind(
    sys.modules[__name__],
    sampling=Sampling(
        "chaplygin_ball_veselova", "omega", ("energy", "gamma_E"), "text after eq. 2704-5",
        describe=lambda names: "gamma uniform on the sphere; E uniform on the sphere, or E = (gamma, E) gamma + "
                               "sqrt(1 - (gamma, E)^2) v with v uniform among unit vectors ⊥ gamma if (gamma, E) is "
                               "fixed; omega = t u with u uniform among unit vectors ⊥ E; "
                               + root_words("text after eq. 2704-5")),
)
