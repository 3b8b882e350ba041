"""The Hamiltonian family on e(3) of eq. (2504-12): the source of Proposition 1.

Paper, section "Veselova system", after eq. (2504-11)::

    H = α ½ M² (Γ, IΓ) + β ½ ((M, IM)(Γ, IΓ) − (M, IΓ)²),

on e(3) with {M_i, M_j} = ε_ijk M_k, {M_i, Γ_j} = ε_ijk Γ_k, {Γ_i, Γ_j} = 0 and the convention of
eq. (2504-10-2), dx/dt = {H, x} (ERRATA 4). At α = 1, β = 0 it is Veselova's system (U = 0) after
the time substitution dτ = dt/(ρ_ω √det I) (eq. 2504-11). The right-hand side is DERIVED from H by
sympy through the bracket.

The paper works "in the case (M, γ) = 0", which must read (M, Γ) = 0 (not in ERRATA): both terms of
H are integrals only there ({H_α, H_β} ∝ (M, Γ)), and Proposition 1 needs Γ² = 1 as well (its map
s = (Γ, IΓ)^(−1/2) I^(1/2) Γ gives the Clebsch field only on Γ² = 1; off it the residual is O(1)).
Both are constraints of this kind, with projections.
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
    StateConstraint,
    StateVector,
    dot,
)
from nonholonomic.hamiltonization.poisson import e3
from nonholonomic.kinds import Sampling, SystemKind
from nonholonomic.memo import remembered
from nonholonomic.potentials import ZERO, Potential, catalog_of, resolve
from nonholonomic.systems.clebsch import I1, I2, I3, INERTIA, inertia

KIND = "veselova_e3"
TITLE = "Hamiltonian system on e(3) with H = alpha H_alpha + beta H_beta (eq. 2504-12), the source of Proposition 1"

alpha, beta = sp.symbols("alpha beta", real=True)
BRACKET = e3()
M = sp.Matrix(BRACKET.variables[:3])
Gamma = sp.Matrix(BRACKET.variables[3:])

PARAMETERS = (
    INERTIA,
    Parameter("alpha", (alpha,), "weight alpha of H_alpha = M^2 (Gamma, I Gamma) / 2", "1"),
    Parameter("beta", (beta,), "weight beta of H_beta = ((M, I M)(Gamma, I Gamma) - (M, I Gamma)^2) / 2",
              "1/(kg m^2)"),
)
POTENTIALS = catalog_of(ZERO)
#: The state vectors a potential of this kind may depend on (an expression potential uses their components).
POTENTIAL_VARIABLES = ("Gamma",)
STATE = (
    StateVector("M", tuple(M), "momentum M = rho_omega I^(1/2) omega of eq. 2504-10-2", "1/s"),
    StateVector("Gamma", tuple(Gamma), "Gamma = rho_omega^-1 I^(-1/2) gamma of eq. 2504-10-2", "(kg m^2)^(-1/2)"),
)
#: A job request for this kind (the catalog shows it; tests and benchmarks run it).
EXAMPLE = {
    "system": {"kind": KIND, "inertia": [1.0, 2.0, 3.0], "alpha": 0.7, "beta": -0.4, "potential": {"kind": "zero"}},
    "initial_state": {"M": [0.8, -0.3, 0.0], "Gamma": [0.0, 0.0, 1.0]},
    "t_final": 1000.0, "samples": 201,
}


def hamiltonian_alpha() -> sp.Expr:
    """``H_α = ½ M² (Γ, IΓ)`` (eq. 2504-11 with U = 0)."""
    return dot(M, M) * dot(Gamma, inertia * Gamma) / 2


def hamiltonian_beta() -> sp.Expr:
    """``H_β = ½ ((M, IM)(Γ, IΓ) − (M, IΓ)²)`` (eq. 2504-12; = F/2 of eq. 2504-5 in (M, Γ))."""
    return (dot(M, inertia * M) * dot(Gamma, inertia * Gamma) - dot(M, inertia * Gamma) ** 2) / 2


def hamiltonian() -> sp.Expr:
    """``H = α H_α + β H_β`` (eq. 2504-12)."""
    return alpha * hamiltonian_alpha() + beta * hamiltonian_beta()


@lru_cache(maxsize=64)  # as the kernels and integrators compiled from it
@remembered("definition")  # derived once per machine and version (nonholonomic.memo)
def define(potential: str | Potential = "zero") -> MechanicalSystem:
    """Eq. (2504-12) on e(3), rhs ``dx/dt = {H, x}`` derived by sympy.

    Returns
    -------
    MechanicalSystem
        Integrals H, H_α, H_β (on (M, Γ) = 0) and the Casimirs Γ², (M, Γ); density 1 (Lie–Poisson).
    """
    pot = resolve(POTENTIALS, potential)
    U = pot.build({"Gamma": Gamma})  # a user's U(Gamma) is added to H (eq. 2504-11 with its U)
    H = hamiltonian() + U
    GIG = dot(Gamma, inertia * Gamma)
    size_M, size_G = sp.sqrt(dot(M, M)), sp.sqrt(dot(Gamma, Gamma))
    size_alpha = dot(M, M) * GIG / 2
    size_beta = dot(M, inertia * M) * GIG / 2 + dot(M, inertia * Gamma) ** 2 / 2
    energy = FirstIntegral(
        "energy", H, sp.Abs(alpha) * size_alpha + sp.Abs(beta) * size_beta + pot.scale({"Gamma": Gamma}),
        "H = alpha M^2 (Gamma, I Gamma)/2 + beta ((M, I M)(Gamma, I Gamma) - (M, I Gamma)^2)/2"
        + (" + U(Gamma)" if U != 0 else ""), "2504-12")
    pair = (  # they commute only without an added U
        FirstIntegral("H_alpha", hamiltonian_alpha(), size_alpha, "H_alpha = M^2 (Gamma, I Gamma)/2", "2504-12"),
        FirstIntegral("H_beta", hamiltonian_beta(), size_beta,
                      "H_beta = ((M, I M)(Gamma, I Gamma) - (M, I Gamma)^2)/2 (on (M, Gamma) = 0)", "2504-12"),
    ) if pot.kind == "zero" else ()
    integrals = (
        energy, *pair,
        FirstIntegral("geometric", dot(Gamma, Gamma), sp.Integer(1), "(Gamma, Gamma)", "2504-10-2"),
        FirstIntegral("area", dot(M, Gamma), size_M * size_G, "(M, Gamma) = 0", "2504-10-2"),
    )
    return MechanicalSystem(
        kind=KIND,
        potential=pot.kind,
        title=TITLE,
        equation="2504-12",
        parameters=PARAMETERS + pot.parameters,
        state=STATE,
        rhs=BRACKET.hamiltonian_vector_field(H),
        integrals=integrals,
        measure=InvariantMeasure(sp.Integer(1), "rho = 1 (Lie-Poisson flow on e(3): div f = 0)", "2504-12"),
        reduced_time=None,
        potential_formula=pot.formula,
        constraints=(
            StateConstraint("Gamma", size_G, 1.0, "|Gamma| = 1", "2504-10-2",
                            projection=Projection("Gamma", tuple(Gamma / size_G), "Gamma -> Gamma / |Gamma|")),
            StateConstraint("M", dot(M, Gamma), 0.0, "(M, Gamma) = 0", "2504-12 (printed '(M, gamma) = 0')",
                            scale=size_M * size_G,
                            projection=Projection("M", tuple(M - dot(M, Gamma) / dot(Gamma, Gamma) * Gamma),
                                                  "M -> M - (M, Gamma) Gamma / (Gamma, Gamma)")),
        ),
        notes=("rhs derived from H through the e(3) bracket, dx/dt = {H, x} (eq. 2504-10-2; ERRATA 4)",
               "the paper's 'in the case (M, gamma) = 0' must read (M, Gamma) = 0: {H_alpha, H_beta} vanishes "
               "only there"),
    )


__all__ = ["KIND", "TITLE", "PARAMETERS", "POTENTIALS", "POTENTIAL_VARIABLES", "STATE", "EXAMPLE", "define",
           "I1", "I2", "I3"]


#: The kind's record (nonholonomic.kinds): sampling on an energy level.
SYSTEM_KIND = SystemKind(
    sys.modules[__name__],
    sampling=Sampling("sphere_then_velocity", "M", ("energy",), "eq. 2504-12", position="Gamma", plane=True),
)
