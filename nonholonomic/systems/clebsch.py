"""The Clebsch case of the Kirchhoff equations on e(3): the target field of Proposition 1.

Paper, section "Veselova system", Proposition 1, eq. (2504-13) (``s`` a unit vector, ``L`` its
conjugate momentum, ``I = diag(I1, I2, I3)``)::

    ds/dt = k (α s × L + β s × I L),
    dL/dt = k (α c s × I s + β (L × I L − c (det I) s × I⁻¹ s)).

It is written here as a Hamiltonian system on e(3) in the convention of eq. (2504-10-2),

    ds/dt = s × ∂H/∂L,    dL/dt = L × ∂H/∂L + s × ∂H/∂s,

which is ``ẋ = {H, x}`` for the printed bracket ``{L_i, L_j} = ε_ijk L_k``, ``{L_i, s_j} = ε_ijk s_k``,
``{s_i, s_j} = 0``. The right-hand side is DERIVED from H by differentiation (sympy), with

    H = k (α H_α + β H_β),
    H_α = ½ (L, L) + c/2 (s, I s),
    H_β = ½ (L, I L) − c/2 (det I) (s, I⁻¹ s).

Misprint in the paper: the Hamiltonian printed after the proof of Proposition 1 has the β-part's
potential ``−c/2 det I (Γ, I Γ)``; it must be ``−c/2 det I (Γ, I⁻¹ Γ)`` to generate the printed field
(2504-13). With ``(Γ, I Γ)`` the torque would be ``−c det I s × I s`` instead of
``−c det I s × I⁻¹ s``; the printed form is also dimensionally inconsistent with the α-part and breaks
the Clebsch condition ``Σ (B_j − B_k)/A_i = 0`` unless β = 0. The corrected potential is Brun's
``∝ (s, I⁻¹ s)`` at α = 0, as the paper's own text ("the Brun problem") says. The tests derive the
field of both forms and compare with (2504-13).

Integrals: the energy H, the Casimirs (s, s) and (s, L) (the constant of areas: Proposition 1 uses the
level (s, L) = 0, but the Kirchhoff system is defined, and kept, for any value), and H_α and H_β
separately: their e(3) bracket vanishes identically (not only on (s, L) = 0), so each is conserved
for every α, β, c, k and I. Lie–Poisson flows on e(3) preserve d³s d³L (density 1).

Time scale ``k``: with the e(3) convention of eq. (2504-10-2) the Veselova map gives k = +√det I
(ERRATA 4; the printed −√det I belongs to ``ẋ = {x, H}``). In this standalone system k is a parameter
the caller gives; its sign only reverses time, and the same H generates (2504-13) with the same k.
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
from nonholonomic.memo import remembered
from nonholonomic.potentials import ZERO, Potential, catalog_of, resolve

KIND = "clebsch"
TITLE = "Clebsch case of the Kirchhoff equations on e(3) (target of Proposition 1)"

I1, I2, I3 = sp.symbols("I1 I2 I3", positive=True)
alpha, beta, c, k = sp.symbols("alpha beta c k", real=True)
s = vector_symbols("s")
L = vector_symbols("L")
inertia = sp.diag(I1, I2, I3)
inertia_inv = sp.diag(1 / I1, 1 / I2, 1 / I3)
det_inertia = I1 * I2 * I3

# Units: one consistent assignment with I in kg m^2, t in s and k = √det I (Proposition 1).
UNIT_L = "1/(s (kg m^2)^(3/2))"
UNIT_C = "1/(s^2 (kg m^2)^4)"
UNIT_K = "(kg m^2)^(3/2)"

INERTIA = Parameter("inertia", (I1, I2, I3), "I = diag(I1, I2, I3) of Proposition 1", "kg m^2",
                    minimum=0.0, strict=True)
ALPHA = Parameter("alpha", (alpha,), "weight alpha of H_alpha = L^2/2 + c/2 (s, I s)", "1")
BETA = Parameter("beta", (beta,), "weight beta of H_beta = (L, I L)/2 - c/2 det I (s, I^-1 s)", "1/(kg m^2)")
C = Parameter("c", (c,), "c = M^2 (Gamma, I Gamma) / det I of Proposition 1, here a constant parameter", UNIT_C)
K = Parameter("k", (k,), "time scale k (Proposition 1 with the convention of eq. 2504-10-2: k = +sqrt(det I))",
              UNIT_K)

PARAMETERS = (INERTIA, ALPHA, BETA, C, K)
POTENTIALS = catalog_of(ZERO)
#: The state vectors a potential of this kind may depend on (an expression potential uses their components).
POTENTIAL_VARIABLES = ("s",)
#: A job request for this kind (the catalog shows it; tests and benchmarks run it).
EXAMPLE = {
    "system": {"kind": KIND, "inertia": [1.0, 2.0, 3.0], "alpha": 0.7, "beta": -0.4, "c": 1.3, "k": 2.449489742783178,
               "potential": {"kind": "zero"}},
    "initial_state": {"s": [0.0, 0.6, 0.8], "L": [0.3, 0.4, -0.3]},
    "t_final": 1000.0, "samples": 201,
}

STATE = (
    StateVector("s", tuple(s), "unit vector s = (Gamma, I Gamma)^(-1/2) I^(1/2) Gamma of Proposition 1", "1"),
    StateVector("L", tuple(L), "momentum L = I^(-1/2) M of Proposition 1", UNIT_L),
)


def hamiltonian_alpha(s_: sp.Matrix = s, L_: sp.Matrix = L) -> sp.Expr:
    """``H_α = ½ (L, L) + c/2 (s, I s)`` (the Neumann part)."""
    return dot(L_, L_) / 2 + c / 2 * dot(s_, inertia * s_)


def hamiltonian_beta(s_: sp.Matrix = s, L_: sp.Matrix = L) -> sp.Expr:
    """``H_β = ½ (L, I L) − c/2 (det I) (s, I⁻¹ s)`` (the Brun part; corrected, see module docstring)."""
    return dot(L_, inertia * L_) / 2 - c / 2 * det_inertia * dot(s_, inertia_inv * s_)


def printed_hamiltonian_beta(s_: sp.Matrix = s, L_: sp.Matrix = L) -> sp.Expr:
    """The β-part as printed after the proof of Proposition 1: ``½ (L, I L) − c/2 det I (s, I s)``
    (a misprint; kept so the tests can show it does not generate eq. 2504-13)."""
    return dot(L_, inertia * L_) / 2 - c / 2 * det_inertia * dot(s_, inertia * s_)


def hamiltonian(a: sp.Expr = alpha, b: sp.Expr = beta) -> sp.Expr:
    """``H = k (a H_α + b H_β)``: for ``a = α, b = β`` the Clebsch case, for ``a = 1, b = 0`` Neumann's."""
    return k * (a * hamiltonian_alpha() + b * hamiltonian_beta())


def kirchhoff_equations(H: sp.Expr) -> tuple[sp.Expr, ...]:
    """``(ds/dt, dL/dt) = (s × ∂H/∂L, L × ∂H/∂L + s × ∂H/∂s)`` (convention of eq. 2504-10-2)."""
    dH_dL, dH_ds = gradient(H, L), gradient(H, s)
    return tuple(cross(s, dH_dL)) + tuple(cross(L, dH_dL) + cross(s, dH_ds))


def lie_poisson_bracket(f: sp.Expr, g: sp.Expr) -> sp.Expr:
    """``{f, g}`` on e(3) with ``{L_i, L_j} = ε_ijk L_k``, ``{L_i, s_j} = ε_ijk s_k``, ``{s_i, s_j} = 0``."""
    fL, fs, gL, gs = gradient(f, L), gradient(f, s), gradient(g, L), gradient(g, s)
    return dot(L, cross(fL, gL)) + dot(s, cross(fL, gs) + cross(fs, gL))


def size_alpha() -> sp.Expr:
    """Natural size of H_α (sum of its terms' magnitudes), to normalise its drift."""
    return dot(L, L) / 2 + sp.Abs(c) / 2 * dot(s, inertia * s)


def size_beta() -> sp.Expr:
    """Natural size of H_β."""
    return dot(L, inertia * L) / 2 + sp.Abs(c) / 2 * det_inertia * dot(s, inertia_inv * s)


def common_integrals(H: sp.Expr, H_size: sp.Expr, H_formula: str) -> list[FirstIntegral]:
    """The energy and the two Casimirs of e(3), shared by :mod:`clebsch` and :mod:`neumann`."""
    return [
        FirstIntegral("energy", H, H_size, H_formula, "2504-13"),
        FirstIntegral("geometric", dot(s, s), sp.Integer(1), "(s, s)", "2504-13"),
        FirstIntegral("area", dot(s, L), sp.sqrt(dot(s, s) * dot(L, L)), "(s, L) (constant of areas, any value)",
                      "2504-13"),
    ]


def unit_s_constraint() -> StateConstraint:
    """``|s| = 1`` with the projection ``s → s/|s|``. (s, L) is NOT a constraint: any value is kept."""
    norm_s = sp.sqrt(dot(s, s))
    return StateConstraint("s", norm_s, 1.0, "|s| = 1", "2504-13",
                           projection=Projection("s", tuple(s / norm_s), "s -> s / |s|"))


MEASURE = InvariantMeasure(sp.Integer(1), "rho = 1 (Lie-Poisson flow on e(3): div f = 0)", "2504-13")


@lru_cache(maxsize=64)  # as the kernels and integrators compiled from it
@remembered("definition")  # derived once per machine and version (nonholonomic.memo)
def define(potential: str | Potential = "zero") -> MechanicalSystem:
    """The Clebsch case of the Kirchhoff equations, eq. (2504-13), with H after Proposition 1 (corrected).

    Returns
    -------
    MechanicalSystem
        rhs derived from ``H = k (α H_α + β H_β)`` through the Kirchhoff equations; integrals H,
        (s, s), (s, L), H_α, H_β; density 1; no reduced time.
    """
    pot = resolve(POTENTIALS, potential)
    U = pot.build({"s": s})  # a user's U(s) is added to H; the field stays Lie-Poisson (density 1)
    H = hamiltonian() + U
    H_size = sp.Abs(k) * (sp.Abs(alpha) * size_alpha() + sp.Abs(beta) * size_beta()) + pot.scale({"s": s})
    integrals = common_integrals(
        H, H_size, "H = k (alpha (L^2/2 + c/2 (s, I s)) + beta ((L, I L)/2 - c/2 det I (s, I^-1 s)))"
        + (" + U(s)" if U != 0 else ""))
    if pot.kind == "zero":  # H_alpha and H_beta commute only without an added U
        integrals += [
            FirstIntegral("H_alpha", hamiltonian_alpha(), size_alpha(), "H_alpha = L^2/2 + c/2 (s, I s)", "2504-13"),
            FirstIntegral("H_beta", hamiltonian_beta(), size_beta(), "H_beta = (L, I L)/2 - c/2 det I (s, I^-1 s)",
                          "2504-13"),
        ]
    return MechanicalSystem(
        kind=KIND,
        potential=pot.kind,
        title=TITLE,
        equation="2504-13",
        parameters=PARAMETERS + pot.parameters,
        state=STATE,
        rhs=kirchhoff_equations(H),
        integrals=tuple(integrals),
        measure=MEASURE,
        reduced_time=None,
        potential_formula=(f"{pot.formula}, added to H" if pot.kind != "zero" else
                           "U = 0 (the potentials c/2 (s, I s) and -c/2 det I (s, I^-1 s) are part of H)"),
        constraints=(unit_s_constraint(),),
        notes=(
            "rhs derived from H through ds/dt = s x dH/dL, dL/dt = L x dH/dL + s x dH/ds (eq. 2504-10-2 "
            "convention, x' = {H, x}); it equals eq. 2504-13 as printed",
            "the Hamiltonian printed after the proof of Proposition 1 has -c/2 det I (Gamma, I Gamma) in the beta "
            "part; the field 2504-13 needs -c/2 det I (Gamma, I^-1 Gamma) (used here)",
            "k is the caller's time scale; Proposition 1 with the e(3) convention of eq. 2504-10-2 has "
            "k = +sqrt(det I) (ERRATA 4)",
            "{H_alpha, H_beta} = 0 identically on e(3): both are conserved for any (s, L), not only (s, L) = 0",
            "(s, L) is a conserved Casimir, not a constraint: Proposition 1 uses the level (s, L) = 0, "
            "any value is integrated",
        ),
    )


#: The kind's record (nonholonomic.kinds): sampling on a level of H and the area (s, L).
SYSTEM_KIND = SystemKind(
    sys.modules[__name__],
    sampling=Sampling("sphere_then_velocity", "L", ("energy", "area"), "eq. 2504-13", position="s", linear="area"),
)
