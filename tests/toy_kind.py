"""A toy system kind, registered from outside the tree: the Euler–Poisson equations of a rigid body about a
fixed point (Chaplygin's ball at D = 0, eq. 2604-1 with I_Q = I).

It is the whole of what adding a kind takes (``docs/layout.md``, "Adding a system kind"): one module
declaring the kind and its record ``SYSTEM_KIND``. ``tests/integration/test_kind_registry.py`` declares it
under the entry-point group ``nonholonomic.kinds`` of a throwaway distribution and sees it served end to
end: catalog, job, page, export, ensemble.

    dM/dt = M × ω + γ × ∂U/∂γ,    dγ/dt = γ × ω,    ω = I⁻¹ M;

integrals H = (M, ω)/2 + U(γ), (γ, γ), (M, γ), and (M, M) for U = 0; the measure dM dγ (density 1).
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
    cross,
    dot,
    gradient,
    vector_symbols,
)
from nonholonomic.kinds import Sampling, SystemKind
from nonholonomic.potentials import ZERO, Potential, catalog_of, linear, resolve

KIND = "toy_euler_poisson"
TITLE = "Toy kind: a rigid body about a fixed point (the Euler-Poisson equations)"

I1, I2, I3 = sp.symbols("I1 I2 I3", positive=True)
M = vector_symbols("M")
gamma = vector_symbols("gamma")

PARAMETERS = (Parameter("inertia", (I1, I2, I3), "principal moments of inertia I1, I2, I3 about the fixed point",
                        "kg m^2", minimum=0.0, strict=True),)
POTENTIALS = catalog_of(ZERO, linear("gamma"))
POTENTIAL_VARIABLES = ("gamma",)
EXAMPLE = {
    "system": {"kind": KIND, "inertia": [2.0, 3.0, 4.5], "potential": {"kind": "zero"}},
    "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]},
    "t_final": 20.0, "samples": 21,
}
STATE = (StateVector("M", tuple(M), "angular momentum, body frame", "kg m^2/s"),
         StateVector("gamma", tuple(gamma), "unit vertical in the body frame", "1"))


@lru_cache(maxsize=8)
def define(potential: str | Potential = "zero") -> MechanicalSystem:
    """The Euler–Poisson equations with the potential ``potential``."""
    pot = resolve(POTENTIALS, potential)
    variables = {"gamma": gamma, "I": sp.diag(I1, I2, I3)}
    U = pot.build(variables)
    omega = sp.Matrix([M[0] / I1, M[1] / I2, M[2] / I3])
    kinetic = dot(M, omega) / 2
    integrals = [
        FirstIntegral("energy", kinetic + U, kinetic + pot.scale(variables), "H = (M, omega)/2 + U(gamma)", "2604-2"),
        FirstIntegral("geometric", dot(gamma, gamma), sp.Integer(1), "(gamma, gamma)", "2604-2"),
        FirstIntegral("area", dot(M, gamma), sp.sqrt(dot(M, M) * dot(gamma, gamma)), "c = (M, gamma)", "2604-2"),
    ]
    if pot.kind == "zero":
        integrals.append(FirstIntegral("F", dot(M, M), dot(M, M), "F = (M, M)", "2604-4"))
    return MechanicalSystem(
        kind=KIND, potential=pot.kind, title=TITLE, equation="2604-1 at D = 0",
        parameters=PARAMETERS + pot.parameters, state=STATE,
        rhs=tuple(list(cross(M, omega) + cross(gamma, gradient(U, gamma))) + list(cross(gamma, omega))),
        integrals=tuple(integrals),
        measure=InvariantMeasure(sp.Integer(1), "rho = 1 (eq. 2604-3 at D = 0)", "2604-3"),
        reduced_time=None, potential_formula=pot.formula,
        constraints=(StateConstraint("gamma", sp.sqrt(dot(gamma, gamma)), 1.0, "|gamma| = 1", "2604-2",
                                     projection=Projection("gamma", tuple(gamma / sp.sqrt(dot(gamma, gamma))),
                                                           "gamma -> gamma / |gamma|")),),
    )


SYSTEM_KIND = SystemKind(
    sys.modules[__name__],
    sampling=Sampling("sphere_then_velocity", "M", ("energy", "area"), "eq. 2604-2 at D = 0", position="gamma",
                      linear="area"),
)
