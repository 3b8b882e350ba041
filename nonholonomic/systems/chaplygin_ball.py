"""Chaplygin's ball: a balanced, dynamically asymmetric ball rolling without slipping on a plane.

Paper, section "Chaplygin's ball", eq. (2604-1)–(2604-4)::

    dM/dt = M × ω + γ × ∂U/∂γ,    dγ/dt = γ × ω,
    M = I ω + D γ × (ω × γ) = I_Q ω,    I_Q = J − D γ⊗γ,    J = I + D·1,    D = m R².

ω = I_Q⁻¹ M is written with the Sherman–Morrison formula,
``I_Q⁻¹ = J⁻¹ + D J⁻¹γ γᵀJ⁻¹ / (1 − D (γ, J⁻¹γ))``, and det I_Q with the matrix determinant lemma,
``det I_Q = det J (1 − D (γ, J⁻¹γ))`` (eq. 2604-3), so every expression is rational in the state and
no matrix is inverted numerically. Both identities hold for any γ, not only on |γ| = 1, and are
checked in the tests.
"""

from __future__ import annotations

import sys
from functools import lru_cache

import sympy as sp

from nonholonomic.definition import (
    AlternativeInput,
    DerivedVector,
    FirstIntegral,
    InvariantMeasure,
    MechanicalSystem,
    Parameter,
    Projection,
    ReducedTime,
    StateConstraint,
    StateVector,
    cross,
    dot,
    gradient,
    vector_symbols,
)
from nonholonomic.kinds import ExplorerPlane, Sampling, SystemKind
from nonholonomic.memo import remembered
from nonholonomic.potentials import ZERO, Potential, brun, catalog_of, linear, resolve

KIND = "chaplygin_ball"
TITLE = "Chaplygin's ball rolling without slipping on a horizontal plane"

I1, I2, I3 = sp.symbols("I1 I2 I3", positive=True)
D = sp.Symbol("D", nonnegative=True)
M = vector_symbols("M")
gamma = vector_symbols("gamma")
omega_in = vector_symbols("omega")

inertia = sp.diag(I1, I2, I3)
J = inertia + D * sp.eye(3)
J_inv = sp.diag(1 / (I1 + D), 1 / (I2 + D), 1 / (I3 + D))
det_J = (I1 + D) * (I2 + D) * (I3 + D)


def contact_inertia(g: sp.Matrix = gamma) -> sp.Matrix:
    """``I_Q = J − D γ⊗γ`` (text after eq. 2604-1)."""
    return J - D * g * g.T


def contact_inertia_inverse(g: sp.Matrix = gamma) -> sp.Matrix:
    """``I_Q⁻¹`` by Sherman–Morrison."""
    Jg = J_inv * g
    return J_inv + D * Jg * Jg.T / (1 - D * dot(g, Jg))


def contact_inertia_determinant(g: sp.Matrix = gamma) -> sp.Expr:
    """``det I_Q = det J (1 − D (γ, J⁻¹γ))`` (eq. 2604-3)."""
    return det_J * (1 - D * dot(g, J_inv * g))


def measure_density(g: sp.Matrix = gamma) -> sp.Expr:
    """Chaplygin's invariant measure density ``ρ_μ = (det I_Q)^(−1/2)`` (eq. 2604-3)."""
    return 1 / sp.sqrt(contact_inertia_determinant(g))


PARAMETERS = (
    Parameter("inertia", (I1, I2, I3), "principal moments of inertia I1, I2, I3 about the centre", "kg m^2",
              minimum=0.0, strict=True),
    Parameter("D", (D,), "D = m R^2 (mass times squared radius)", "kg m^2", minimum=0.0),
)

POTENTIALS = catalog_of(ZERO, linear("gamma"), brun("gamma"))
#: The state vectors a potential of this kind may depend on (an expression potential uses their components).
POTENTIAL_VARIABLES = ("gamma",)

#: A job request for this kind (the catalog shows it; tests and benchmarks run it).
EXAMPLE = {
    "system": {"kind": KIND, "inertia": [2.0, 3.0, 4.5], "D": 0.7, "potential": {"kind": "zero"}},
    "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]},
    "t_final": 1000.0, "samples": 201,
}

STATE = (
    StateVector("M", tuple(M), "angular momentum about the contact point, body frame", "kg m^2/s"),
    StateVector("gamma", tuple(gamma), "unit vertical in the body frame", "1"),
)


@lru_cache(maxsize=64)  # as the kernels and integrators compiled from it
@remembered("definition")  # derived once per machine and version (nonholonomic.memo)
def define(potential: str | Potential = "zero") -> MechanicalSystem:
    """Chaplygin's ball with the potential ``potential`` (a key of :data:`POTENTIALS`).

    Returns
    -------
    MechanicalSystem
        The right-hand side of eq. (2604-1), the integrals of eq. (2604-2) and, for U = 0,
        F = (M, M) (eq. 2604-4), the measure of eq. (2604-3), and the reduced time
        ``dτ = ρ_μ dt`` (eq. 2604-5).
    """
    pot = resolve(POTENTIALS, potential)
    variables = {"gamma": gamma, "I": inertia}
    U = pot.build(variables)
    omega = contact_inertia_inverse() * M
    rhs = list(cross(M, omega) + cross(gamma, gradient(U, gamma))) + list(cross(gamma, omega))
    rho = measure_density()
    norm_M = sp.sqrt(dot(M, M))
    kinetic = dot(M, omega) / 2

    integrals = [
        FirstIntegral("energy", kinetic + U, kinetic + pot.scale(variables), "H = (M, omega)/2 + U(gamma)",
                      "2604-2"),
        FirstIntegral("geometric", dot(gamma, gamma), sp.Integer(1), "(gamma, gamma)", "2604-2"),
        FirstIntegral("area", dot(M, gamma), norm_M * sp.sqrt(dot(gamma, gamma)), "c = (M, gamma)", "2604-2"),
    ]
    if pot.kind == "zero":
        integrals.append(FirstIntegral("F", dot(M, M), dot(M, M), "F = (M, M)", "2604-4"))

    return MechanicalSystem(
        kind=KIND,
        potential=pot.kind,
        title=TITLE,
        equation="2604-1",
        parameters=PARAMETERS + pot.parameters,
        state=STATE,
        rhs=tuple(rhs),
        integrals=tuple(integrals),
        measure=InvariantMeasure(rho, "rho_mu = det(I_Q)^(-1/2) = [det J (1 - D (gamma, J^-1 gamma))]^(-1/2)",
                                 "2604-3"),
        reduced_time=ReducedTime(rho, "d tau = rho_mu dt", "2604-5", "s (kg m^2)^(-3/2)"),
        potential_formula=pot.formula,
        derived=(DerivedVector("omega", tuple(omega), "omega = I_Q^-1 M, I_Q = J - D gamma⊗gamma, J = I + D·1",
                               "angular velocity, body frame", "rad/s"),),
        alternative_inputs=(AlternativeInput("omega", "M", tuple(omega_in), tuple(contact_inertia() * omega_in),
                                             "M = I_Q omega"),),
        constraints=(StateConstraint("gamma", sp.sqrt(dot(gamma, gamma)), 1.0, "|gamma| = 1", "2604-2",
                                     projection=Projection("gamma", tuple(gamma / sp.sqrt(dot(gamma, gamma))),
                                                           "gamma -> gamma / |gamma|")),),
    )


#: The kind's record (nonholonomic.kinds): sampling on a level of H and the area (eq. 2604-2), the Hamiltonian form
#: after dτ = ρ_μ dt (eq. 2604-5..7) and its Euler-angle forms, the explorer's plane of the docs' chaos map.
SYSTEM_KIND = SystemKind(
    sys.modules[__name__],
    sampling=Sampling("sphere_then_velocity", "M", ("energy", "area"), "eq. 2604-2", position="gamma", linear="area"),
    hamiltonian_form=True, local_forms=True,
    explorer_plane=ExplorerPlane("gamma3", ("gamma1", "M3"), {"energy": 2.0, "area": 0.0}),
)
