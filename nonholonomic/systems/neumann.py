"""The Neumann problem on e(3): a point on the sphere in the quadratic potential c/2 (s, I s).

Paper, section "Veselova system", eq. (2504-13) and the Hamiltonian after the proof of
Proposition 1 at α = 1, β = 0 ("the Hamiltonian of the Neumann case")::

    H = k (½ (L, L) + c/2 (s, I s)),
    ds/dt = k s × L,    dL/dt = k c s × I s,

in the Kirchhoff form ``ds/dt = s × ∂H/∂L, dL/dt = L × ∂H/∂L + s × ∂H/∂s`` of eq. (2504-10-2). H, the
field and the shared integrals are built by :mod:`nonholonomic.systems.clebsch` (H is
``clebsch.hamiltonian(1, 0)``; nothing is written twice).

Uhlenbeck's integrals (derived and checked symbolically in the tests, ``d/dt F_i = 0`` identically,
for ANY value of (s, L), not only (s, L) = 0), with (i, j, m) a permutation of (1, 2, 3)::

    F_i = s_i² + L_m² / (c (I_i − I_j)) + L_j² / (c (I_i − I_m)),

which need c ≠ 0 and distinct I_i. They are stored multiplied by ``c (I_i − I_j)(I_i − I_m)``,

    G_i = c (I_i − I_j)(I_i − I_m) s_i² + (I_i − I_m) L_m² + (I_i − I_j) L_j²,

a polynomial that is conserved for every I and c (by continuity; for I_i = I_j it reduces to the
axial momentum (I_i − I_m) L_m²). Σ F_i = (s, s) and Σ c I_i F_i = 2 H / k, so one F_i is new beyond
H and the Casimirs.
"""

from __future__ import annotations

import sys
from functools import lru_cache

import sympy as sp

from nonholonomic.definition import FirstIntegral, MechanicalSystem, Parameter, dot
from nonholonomic.kinds import SystemKind
from nonholonomic.memo import remembered
from nonholonomic.potentials import ZERO, Potential, catalog_of, resolve
from nonholonomic.systems import clebsch
from nonholonomic.systems.clebsch import I1, I2, I3, INERTIA, UNIT_C, UNIT_K, L, c, k, s

KIND = "neumann"
TITLE = "Neumann problem: a point on the sphere in the quadratic potential c/2 (s, I s) (Kirchhoff form on e(3))"

PARAMETERS = (
    INERTIA,
    Parameter("c", (c,), "strength c of the quadratic potential c/2 (s, I s)", UNIT_C),
    Parameter("k", (k,), "time scale k (Proposition 1 with the convention of eq. 2504-10-2: k = +sqrt(det I))",
              UNIT_K),
)
POTENTIALS = catalog_of(ZERO)
#: The state vectors a potential of this kind may depend on (an expression potential uses their components).
POTENTIAL_VARIABLES = ("s",)
#: A job request for this kind (the catalog shows it; tests and benchmarks run it).
EXAMPLE = {
    "system": {"kind": KIND, "inertia": [1.0, 2.0, 3.0], "c": 1.3, "k": 2.449489742783178,
               "potential": {"kind": "zero"}},
    "initial_state": {"s": [0.0, 0.6, 0.8], "L": [0.3, 0.4, -0.3]},
    "t_final": 1000.0, "samples": 201,
}

STATE = clebsch.STATE


def uhlenbeck_integrals() -> list[FirstIntegral]:
    """``G_i = c (I_i − I_j)(I_i − I_m) F_i`` for i = 1, 2, 3 (polynomial form of Uhlenbeck's F_i)."""
    moments = (I1, I2, I3)
    out = []
    for i in range(3):
        j, m = (i + 1) % 3, (i + 2) % 3
        dij, dim = moments[i] - moments[j], moments[i] - moments[m]
        G = c * dij * dim * s[i] ** 2 + dim * L[m] ** 2 + dij * L[j] ** 2
        size = sp.Abs(c * dij * dim) * dot(s, s) + (sp.Abs(dij) + sp.Abs(dim)) * dot(L, L)
        n_i, n_j, n_m = i + 1, j + 1, m + 1
        out.append(FirstIntegral(
            f"uhlenbeck_{n_i}", G, size,
            f"G_{n_i} = c (I{n_i} - I{n_j})(I{n_i} - I{n_m}) F_{n_i}, "
            f"F_{n_i} = s{n_i}^2 + L{n_m}^2/(c (I{n_i} - I{n_j})) + L{n_j}^2/(c (I{n_i} - I{n_m}))",
            "2504-13"))
    return out


@lru_cache(maxsize=64)  # as the kernels and integrators compiled from it
@remembered("definition")  # derived once per machine and version (nonholonomic.memo)
def define(potential: str | Potential = "zero") -> MechanicalSystem:
    """The Neumann problem: eq. (2504-13) at α = 1, β = 0.

    Returns
    -------
    MechanicalSystem
        rhs derived from ``H = k (L²/2 + c/2 (s, I s))``; integrals H, (s, s), (s, L) and G_1, G_2, G_3
        (Uhlenbeck); density 1; no reduced time.
    """
    pot = resolve(POTENTIALS, potential)
    U = pot.build({"s": clebsch.s})  # a user's U(s) is added to H
    H = clebsch.hamiltonian(sp.Integer(1), sp.Integer(0)) + U
    integrals = clebsch.common_integrals(H, sp.Abs(k) * clebsch.size_alpha() + pot.scale({"s": clebsch.s}),
                                         "H = k (L^2/2 + c/2 (s, I s))" + (" + U(s)" if U != 0 else ""))
    if pot.kind == "zero":  # Uhlenbeck's integrals need H as it is
        integrals += uhlenbeck_integrals()
    return MechanicalSystem(
        kind=KIND,
        potential=pot.kind,
        title=TITLE,
        equation="2504-13",
        parameters=PARAMETERS + pot.parameters,
        state=STATE,
        rhs=clebsch.kirchhoff_equations(H),
        integrals=tuple(integrals),
        measure=clebsch.MEASURE,
        reduced_time=None,
        potential_formula=(f"{pot.formula}, added to H" if pot.kind != "zero" else
                           "U = 0 (the potential c/2 (s, I s) is part of H)"),
        constraints=(clebsch.unit_s_constraint(),),
        notes=(
            "the Clebsch system of eq. 2504-13 at alpha = 1, beta = 0; rhs derived from H through the Kirchhoff "
            "equations of eq. 2504-10-2 (x' = {H, x})",
            "Uhlenbeck's F_i need c != 0 and distinct I_i; the stored G_i = c (I_i - I_j)(I_i - I_m) F_i hold for "
            "every I and c, and for any (s, L) (not only (s, L) = 0)",
            "k is the caller's time scale; Proposition 1 with the e(3) convention of eq. 2504-10-2 has "
            "k = +sqrt(det I) (ERRATA 4)",
        ),
    )


#: The kind's record (nonholonomic.kinds): sampling on a level of H and the area (s, L), as the Clebsch system's.
SYSTEM_KIND = SystemKind(sys.modules[__name__], sampling=clebsch.SYSTEM_KIND.sampling)
