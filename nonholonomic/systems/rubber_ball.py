"""The rubber ball: Chaplygin's ball that rolls without slipping and without spinning, (ω, γ) = 0.

Paper, section "Realization of constraints. Chaplygin's ball with the Veselova constraint", the
paragraph after eq. (2704-6): the case E = γ of eq. (2704-4)::

    I_Q dω/dt = Iω × ω + μ γ + γ × ∂U/∂γ,    dγ/dt = γ × ω,    (ω, γ) = 0,
    I_Q = J − D γ⊗γ,    J = I + D·1.

μ is derived, not copied: sympy solves these equations together with
``d/dt (ω, γ) = (dω/dt, γ) + (ω, γ × ω) = 0`` for (dω/dt, μ)
(:func:`nonholonomic.systems.chaplygin_ball_veselova.constrained_acceleration` with e = γ), giving

    μ = −(Iω × ω + γ × ∂U/∂γ, I_Q⁻¹γ) / (γ, I_Q⁻¹γ),
    dω/dt = (I_Q (γ × n)) × γ / (γ, adj(I_Q) γ),    n = Iω × ω + γ × ∂U/∂γ.

The paper's argument: (dω/dt, γ) = 0, so ``I_Q dω/dt = J dω/dt − D (dω/dt, γ) γ = J dω/dt`` (the
printed "Jω" lacks the dot, ERRATA 10), ``I_Q ω = J ω`` and ``Iω × ω = Jω × ω``: the rubber ball is
the Veselova system (eq. 2504-1) with I → J. With I_Q = J − D γ⊗γ this holds on all of R⁶, not
only on |γ| = 1: ``I_Q (γ × n) = J (γ × n)`` and ``(γ, adj(I_Q) γ) = det J (γ, J⁻¹γ)`` identically,
so the right-hand side is Veselova's with I → J as a rational function (checked in the tests).

Hence, from the Veselova system with I → J: the energy H = ½(I_Q ω, ω) + U (text after eq. 2704-5;
= ½(J ω, ω) + U on (ω, γ) = 0), γ² = 1, the constraint (ω, γ), for U = 0 the integral
F = |Jω × γ|² (eq. 2504-5 with I → J), the invariant measure ρ = (γ, J⁻¹γ)^(1/2) d³ω d³γ
(eq. 2504-4 with I → J; it is the density (E, adj(I_Q) E)^(1/2) of eq. 2704-5 at E = γ divided by
the constant √det J) and the reduced time dτ = dt / (ρ √det J) of the Veselova Hamiltonization
(text before eq. 2504-10-2 with I → J).
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
from nonholonomic.potentials import ZERO, Potential, catalog_of, linear, resolve
from nonholonomic.systems.chaplygin_ball import I1, I2, I3, D, J, J_inv, contact_inertia, det_J, inertia
from nonholonomic.systems.chaplygin_ball_veselova import constrained_acceleration

KIND = "rubber_ball"
TITLE = "Rubber ball: Chaplygin's ball rolling without slipping or spinning, (omega, gamma) = 0"

omega = vector_symbols("omega")
gamma = vector_symbols("gamma")

PARAMETERS = (
    Parameter("inertia", (I1, I2, I3), "principal moments of inertia I1, I2, I3 about the centre", "kg m^2",
              minimum=0.0, strict=True),
    Parameter("D", (D,), "D = m R^2 (mass times squared radius)", "kg m^2", minimum=0.0),
)

POTENTIALS = catalog_of(ZERO, linear("gamma"))
#: The state vectors a potential of this kind may depend on (an expression potential uses their components).
POTENTIAL_VARIABLES = ("gamma",)

#: A job request for this kind (the catalog shows it; tests and benchmarks run it).
EXAMPLE = {
    "system": {"kind": KIND, "inertia": [2.0, 3.0, 4.5], "D": 0.7, "potential": {"kind": "zero"}},
    "initial_state": {"omega": [0.5, -0.2, 0.15], "gamma": [0.0, 0.6, 0.8]},
    "t_final": 1000.0, "samples": 201,
}

STATE = (
    StateVector("omega", tuple(omega), "angular velocity, body frame", "rad/s"),
    StateVector("gamma", tuple(gamma), "unit vertical in the body frame", "1"),
)


def free_torque(U: sp.Expr) -> sp.Matrix:
    """``n = Iω × ω + γ × ∂U/∂γ``: the right-hand side without μγ."""
    return cross(inertia * omega, omega) + cross(gamma, gradient(U, gamma))


def constraint_multiplier(U: sp.Expr) -> sp.Expr:
    """μ derived from ``d/dt (ω, γ) = 0``: ``−(n, adj(I_Q) γ) / (γ, adj(I_Q) γ)``."""
    return constrained_acceleration(contact_inertia(gamma), free_torque(U), gamma)[1]


def measure_density(g: sp.Matrix = gamma) -> sp.Expr:
    """``ρ = (γ, J⁻¹γ)^(1/2)``: Veselova's ρ_ω (eq. 2504-4) with I → J."""
    return sp.sqrt(dot(g, J_inv * g))


@lru_cache(maxsize=64)  # as the kernels and integrators compiled from it
@remembered("definition")  # derived once per machine and version (nonholonomic.memo)
def define(potential: str | Potential = "zero") -> MechanicalSystem:
    """The rubber ball with the potential ``potential`` (a key of :data:`POTENTIALS`).

    Returns
    -------
    MechanicalSystem
        Eq. (2704-4) with E = γ and μ derived from d/dt (ω, γ) = 0; the Veselova system's integrals,
        measure and reduced time with I → J = I + D·1.
    """
    pot = resolve(POTENTIALS, potential)
    variables = {"gamma": gamma, "I": inertia}
    U = pot.build(variables)
    IQ = contact_inertia(gamma)
    omega_dot, _ = constrained_acceleration(IQ, free_torque(U), gamma)
    rhs = tuple(omega_dot) + tuple(cross(gamma, omega))
    rho = measure_density()

    kinetic = dot(IQ * omega, omega) / 2
    norm_w, norm_g = sp.sqrt(dot(omega, omega)), sp.sqrt(dot(gamma, gamma))
    integrals = [
        FirstIntegral("energy", kinetic + U, kinetic + pot.scale(variables),
                      "H = (I_Q omega, omega)/2 + U(gamma) = (J omega, omega)/2 + U on (omega, gamma) = 0",
                      "after 2704-5"),
        FirstIntegral("geometric", dot(gamma, gamma), dot(gamma, gamma), "(gamma, gamma)", "after 2704-5"),
        FirstIntegral("constraint", dot(omega, gamma), norm_w * norm_g, "(omega, gamma) = 0", "2704-2 (E = gamma)"),
    ]
    if pot.kind == "zero":
        Jw = J * omega
        Jw_x_g = cross(Jw, gamma)
        integrals.append(FirstIntegral("F", dot(Jw_x_g, Jw_x_g), dot(Jw, Jw) * dot(gamma, gamma),
                                       "F = |J omega x gamma|^2, J = I + D·1", "2504-5 (I -> J)"))

    return MechanicalSystem(
        kind=KIND,
        potential=pot.kind,
        title=TITLE,
        equation="2704-4 (E = gamma)",
        parameters=PARAMETERS + pot.parameters,
        state=STATE,
        rhs=rhs,
        integrals=tuple(integrals),
        measure=InvariantMeasure(rho, "rho = (gamma, J^-1 gamma)^(1/2), J = I + D·1", "2504-4 (I -> J)"),
        reduced_time=ReducedTime(1 / (rho * sp.sqrt(det_J)), "d tau = dt / (rho sqrt(det J)), J = I + D·1",
                                 "2504-10-2 (I -> J)", "s (kg m^2)^(-1)"),
        potential_formula=pot.formula,
        constraints=(
            StateConstraint("gamma", norm_g, 1.0, "|gamma| = 1", "after 2704-5",
                            projection=Projection("gamma", tuple(gamma / norm_g), "gamma -> gamma / |gamma|")),
            StateConstraint("omega", dot(omega, gamma), 0.0, "(omega, gamma) = 0", "2704-2 (E = gamma)",
                            scale=norm_w * norm_g,
                            projection=Projection("omega", tuple(omega - dot(omega, gamma) / dot(gamma, gamma) * gamma),
                                                  "omega -> omega - (omega, gamma) gamma / (gamma, gamma)")),
        ),
        notes=(
            "the rubber ball is the Veselova system with I -> J = I + D·1 (paragraph after eq. 2704-6): same "
            "trajectories, integrals, measure and reduced time",
            "mu = -(I omega x omega + gamma x dU/dgamma, I_Q^-1 gamma) / (gamma, I_Q^-1 gamma): derived from "
            "d/dt (omega, gamma) = 0",
            "I_Q dw/dt = J dw/dt - D (dw/dt, gamma) gamma; the printed 'J omega' lacks the dot (ERRATA 10)",
        ),
    )


#: The kind's record (nonholonomic.kinds): sampling on an energy level.
SYSTEM_KIND = SystemKind(
    sys.modules[__name__],
    sampling=Sampling("sphere_then_velocity", "omega", ("energy",), "text after eq. 2704-5", position="gamma",
                      plane=True),
)
