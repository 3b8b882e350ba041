"""Poisson structures: the e(3) Lie–Poisson bracket, Chaplygin's ball bracket (eq. 2604-6) and the
generalized Chaplygin bracket (eq. 2704-9).

A structure is its Poisson matrix ``P_ij = {x_i, x_j}`` in named variables. Sign convention (the
paper's, eq. 2504-10-2 and ERRATA 4/5): the flow of a Hamiltonian H is

    dx_i/dτ = {H, x_i} = Σ_j {x_j, x_i} ∂H/∂x_j = −Σ_j P_ij ∂H/∂x_j,

which for e(3) gives dM/dτ = M × ∂H/∂M + Γ × ∂H/∂Γ, dΓ/dτ = Γ × ∂H/∂M.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import sympy as sp

from nonholonomic.definition import vector_symbols


@dataclass(frozen=True)
class PoissonStructure:
    """A Poisson bracket given by its matrix ``P_ij = {x_i, x_j}``.

    ``casimirs`` are claimed Casimir functions (name → expression); ``parameters`` the symbols the
    matrix depends on besides the variables.
    """

    name: str
    equation: str
    variables: tuple[sp.Symbol, ...]
    matrix: sp.Matrix
    parameters: tuple[sp.Symbol, ...] = ()
    casimirs: tuple[tuple[str, sp.Expr], ...] = ()
    formula: str = ""
    notes: tuple[str, ...] = field(default=())

    def __hash__(self) -> int:
        return hash((self.name, self.variables, tuple(self.matrix), self.parameters))

    def gradient(self, f: sp.Expr) -> sp.Matrix:
        return sp.Matrix([sp.diff(f, x) for x in self.variables])

    def bracket(self, f: sp.Expr, g: sp.Expr) -> sp.Expr:
        """``{f, g} = Σ_ij ∂f/∂x_i P_ij ∂g/∂x_j``."""
        return (self.gradient(f).T * self.matrix * self.gradient(g))[0, 0]

    def hamiltonian_vector_field(self, H: sp.Expr) -> tuple[sp.Expr, ...]:
        """``dx_i/dτ = {H, x_i} = −(P ∇H)_i`` (the paper's convention)."""
        return tuple(-(self.matrix * self.gradient(H)))


def _antisymmetric(entries: dict[tuple[int, int], sp.Expr], n: int) -> sp.Matrix:
    P = sp.zeros(n, n)
    for (i, j), value in entries.items():
        P[i, j], P[j, i] = value, -value
    return P


def e3(M: Sequence[sp.Symbol] | None = None, Gamma: Sequence[sp.Symbol] | None = None) -> PoissonStructure:
    """The Lie–Poisson bracket of e(3): {M_i, M_j} = ε_ijk M_k, {M_i, Γ_j} = ε_ijk Γ_k, {Γ_i, Γ_j} = 0.

    Casimirs: Γ² and (M, Γ). (Variables ``M1..3, Gamma1..3`` unless given.)
    """
    M = tuple(M or vector_symbols("M"))
    G = tuple(Gamma or vector_symbols("Gamma"))
    entries: dict[tuple[int, int], sp.Expr] = {}
    for i in range(3):
        for j in range(3):
            for k in range(3):
                eps = sp.LeviCivita(i, j, k)
                if eps and i < j:
                    entries[(i, j)] = eps * M[k]
                if eps:
                    entries[(i, 3 + j)] = eps * G[k]
    P = _antisymmetric(entries, 6)
    Mv, Gv = sp.Matrix(M), sp.Matrix(G)
    return PoissonStructure(
        "e3", "2504-10-2", M + G, P,
        casimirs=(("Gamma^2", Gv.dot(Gv)), ("(M, Gamma)", Mv.dot(Gv))),
        formula="{M_i, M_j} = e_ijk M_k, {M_i, Gamma_j} = e_ijk Gamma_k, {Gamma_i, Gamma_j} = 0",
    )


def chaplygin_ball_bracket() -> PoissonStructure:
    """Eq. (2604-6) in (L, γ), for any J = I + D·1, D and constant of areas:

        {L_i, L_j} = ε_ijk (L_k − D (L, γ) ρ_μ² J_i J_j γ_k),  {L_i, γ_j} = ε_ijk γ_k,  {γ_i, γ_j} = 0,

    ρ_μ² = 1/det I_Q = 1/(det J (1 − D (γ, J⁻¹γ))). Casimirs γ² and (L, γ)/ρ_μ = (M, γ).
    """
    from nonholonomic.systems import chaplygin_ball as ball

    L = vector_symbols("L")
    g = ball.gamma
    Jd = [ball.I1 + ball.D, ball.I2 + ball.D, ball.I3 + ball.D]
    rho2 = 1 / ball.contact_inertia_determinant(g)
    Lg = L.dot(g)
    entries: dict[tuple[int, int], sp.Expr] = {}
    for i in range(3):
        for j in range(3):
            for k in range(3):
                eps = sp.LeviCivita(i, j, k)
                if eps and i < j:
                    entries[(i, j)] = eps * (L[k] - ball.D * Lg * rho2 * Jd[i] * Jd[j] * g[k])
                if eps:
                    entries[(i, 3 + j)] = eps * g[k]
    P = _antisymmetric(entries, 6)
    return PoissonStructure(
        "chaplygin_ball", "2604-6", tuple(L) + tuple(g), P, parameters=(ball.I1, ball.I2, ball.I3, ball.D),
        casimirs=(("gamma^2", g.dot(g)),
                  ("(L, gamma)/rho_mu = (M, gamma)", Lg * sp.sqrt(ball.contact_inertia_determinant(g)))),
        formula="{L_i, L_j} = e_ijk (L_k - D (L, gamma) rho_mu^2 J_i J_j gamma_k), {L_i, gamma_j} = e_ijk gamma_k, "
                "{gamma_i, gamma_j} = 0",
    )


def generalized_chaplygin_bracket(S_bar: sp.Expr, q: Sequence[sp.Symbol], p: Sequence[sp.Symbol],
                                  parameters: Sequence[sp.Symbol] = ()) -> PoissonStructure:
    """Eq. (2704-9): {q_i, p_j} = δ_ij, {p_1, p_2} = S̄(q), all other brackets zero (variables q1, q2, p1, p2)."""
    P = _antisymmetric({(0, 2): sp.Integer(1), (1, 3): sp.Integer(1), (2, 3): S_bar}, 4)
    return PoissonStructure("generalized_chaplygin", "2704-9", tuple(q) + tuple(p), P, parameters=tuple(parameters),
                            formula="{q_i, p_j} = delta_ij, {p_1, p_2} = S_bar(q)")
