"""The Veselova system: a rigid body about a fixed point with the constraint (ω, γ) = 0.

Paper, section "Veselova system", eq. (2504-1)–(2504-5)::

    I dω/dt = Iω × ω + μ γ + γ × ∂U/∂γ,    dγ/dt = γ × ω,

with the multiplier μ eliminated by differentiating the constraint: (dω/dt, γ) + (ω, dγ/dt) = 0.
Solving that (done by sympy in :func:`constraint_multiplier`) gives

    μ = −(Iω × ω + γ × ∂U/∂γ, I⁻¹γ) / (γ, I⁻¹γ),

the opposite sign of the printed eq. (2504-2) (ERRATA 1; the tests integrate both forms).
Energy H = ½(Iω, ω) + U and γ² (the unnumbered eq. after 2504-2, here 2504-3), the density
ρ_ω = (γ, I⁻¹γ)^(1/2) (2504-4), and for U = 0, F = |Iω × γ|² (2504-5). The reduced time of the
Hamiltonization on e(3) is dτ = dt / (ρ_ω √det I) (text before eq. 2504-10-2).
"""

from __future__ import annotations

import sys
from functools import lru_cache

import sympy as sp

from nonholonomic.definition import (
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
from nonholonomic.kinds import Sampling, SystemKind
from nonholonomic.memo import remembered
from nonholonomic.potentials import ZERO, Potential, brun, catalog_of, linear, quadratic, resolve

KIND = "veselova"
TITLE = "Veselova system: a rigid body with a fixed point and the constraint (omega, gamma) = 0"

I1, I2, I3 = sp.symbols("I1 I2 I3", positive=True)
omega = vector_symbols("omega")
gamma = vector_symbols("gamma")
inertia = sp.diag(I1, I2, I3)
inertia_inv = sp.diag(1 / I1, 1 / I2, 1 / I3)

PARAMETERS = (
    Parameter("inertia", (I1, I2, I3), "principal moments of inertia I1, I2, I3 about the fixed point", "kg m^2",
              minimum=0.0, strict=True),
)
POTENTIALS = catalog_of(ZERO, linear("gamma"), brun("gamma"), quadratic("gamma"))
#: The state vectors a potential of this kind may depend on (an expression potential uses their components).
POTENTIAL_VARIABLES = ("gamma",)
#: A job request for this kind (the catalog shows it; tests and benchmarks run it).
EXAMPLE = {
    "system": {"kind": KIND, "inertia": [2.0, 3.0, 4.5], "potential": {"kind": "zero"}},
    "initial_state": {"omega": [0.5, -0.2, 0.15], "gamma": [0.0, 0.6, 0.8]},
    "t_final": 1000.0, "samples": 201,
}

STATE = (
    StateVector("omega", tuple(omega), "angular velocity, body frame", "rad/s"),
    StateVector("gamma", tuple(gamma), "unit vector of the space-fixed axis, body frame", "1"),
)


def measure_density(g: sp.Matrix = gamma, i_inv: sp.Matrix = inertia_inv) -> sp.Expr:
    """``ρ_ω = (γ, I⁻¹γ)^(1/2)`` (eq. 2504-4)."""
    return sp.sqrt(dot(g, i_inv * g))


def constraint_multiplier(U: sp.Expr) -> sp.Expr:
    """μ from ``d/dt (ω, γ) = 0`` with ``I dω/dt = Iω×ω + μγ + γ×∂U/∂γ`` (solved by sympy)."""
    mu = sp.Symbol("mu")
    omega_dot = inertia_inv * (cross(inertia * omega, omega) + mu * gamma + cross(gamma, gradient(U, gamma)))
    (solution,) = sp.solve(sp.Eq(dot(omega_dot, gamma) + dot(omega, cross(gamma, omega)), 0), mu)
    return solution


def equations_of_motion(U: sp.Expr, mu: sp.Expr) -> tuple[sp.Expr, ...]:
    """``(dω/dt, dγ/dt)`` of eq. (2504-1) for a given multiplier expression μ."""
    omega_dot = inertia_inv * (cross(inertia * omega, omega) + mu * gamma + cross(gamma, gradient(U, gamma)))
    return tuple(omega_dot) + tuple(cross(gamma, omega))


@lru_cache(maxsize=64)  # as the kernels and integrators compiled from it
@remembered("definition")  # derived once per machine and version (nonholonomic.memo)
def define(potential: str | Potential = "zero") -> MechanicalSystem:
    """The Veselova system with ``potential`` (a key of :data:`POTENTIALS`)."""
    pot = resolve(POTENTIALS, potential)
    variables = {"gamma": gamma, "I": inertia}
    U = pot.build(variables)
    rho = measure_density()
    kinetic = dot(inertia * omega, omega) / 2
    norm_w, norm_g = sp.sqrt(dot(omega, omega)), sp.sqrt(dot(gamma, gamma))
    integrals = [
        FirstIntegral("energy", kinetic + U, kinetic + pot.scale(variables), "H = (I omega, omega)/2 + U(gamma)",
                      "2504-3"),
        FirstIntegral("geometric", dot(gamma, gamma), sp.Integer(1), "(gamma, gamma)", "2504-3"),
        FirstIntegral("constraint", dot(omega, gamma), norm_w * norm_g, "(omega, gamma) = 0", "2504-1"),
    ]
    if pot.kind == "zero":
        Iw_x_g = cross(inertia * omega, gamma)
        integrals.append(FirstIntegral("F", dot(Iw_x_g, Iw_x_g),
                                       dot(inertia * omega, inertia * omega) * dot(gamma, gamma),
                                       "F = |I omega x gamma|^2", "2504-5"))
    return MechanicalSystem(
        kind=KIND,
        potential=pot.kind,
        title=TITLE,
        equation="2504-1",
        parameters=PARAMETERS + pot.parameters,
        state=STATE,
        rhs=equations_of_motion(U, constraint_multiplier(U)),
        integrals=tuple(integrals),
        measure=InvariantMeasure(rho, "rho_omega = (gamma, I^-1 gamma)^(1/2)", "2504-4"),
        reduced_time=ReducedTime(1 / (rho * sp.sqrt(I1 * I2 * I3)), "d tau = dt / (rho_omega sqrt(det I))",
                                 "2504-10-2", "s (kg m^2)^(-1)"),
        potential_formula=pot.formula,
        constraints=(
            StateConstraint("gamma", norm_g, 1.0, "|gamma| = 1", "2504-3",
                            projection=Projection("gamma", tuple(gamma / norm_g), "gamma -> gamma / |gamma|")),
            StateConstraint("omega", dot(omega, gamma), 0.0, "(omega, gamma) = 0", "2504-1", scale=norm_w * norm_g,
                            projection=Projection("omega", tuple(omega - dot(omega, gamma) / dot(gamma, gamma) * gamma),
                                                  "omega -> omega - (omega, gamma) gamma / (gamma, gamma)")),
        ),
        notes=("mu = -(I omega x omega + gamma x dU/dgamma, I^-1 gamma) / (gamma, I^-1 gamma): derived from "
               "d/dt (omega, gamma) = 0; the printed eq. 2504-2 has the opposite sign (ERRATA 1)",),
    )


#: The kind's record (nonholonomic.kinds): sampling on an energy level, the Hamiltonian form after the time
#: substitution (eq. 2504-10-2) and its Euler-angle forms (eq. 2504-6..9, Theorem 2).
SYSTEM_KIND = SystemKind(
    sys.modules[__name__],
    sampling=Sampling("sphere_then_velocity", "omega", ("energy",), "eq. 2504-3", position="gamma", plane=True),
    hamiltonian_form=True, local_forms=True,
)
