"""Theorem 1 for *arbitrary* data: the symbolic half of the verification of
:func:`nonholonomic.hamiltonization.reducing_multiplier.hamiltonize`.

For any G (symmetric), w, V, a₁, a₂, b of (q₁, q₂) and any N solving the density's equations
∂N/∂q₁ = N A₂, ∂N/∂q₂ = −N A₁, the τ-flow of eq. (2704-7) in (q, p = N ∂L/∂q̇) is the Hamiltonian field of
H̄ = H(q, p/N) with the bracket (2704-9), S̄ = N B (ERRATA 6; the printed proof's S̄ = B fails, and so does the
opposite sign convention of :mod:`nonholonomic.hamiltonization.poisson`). Also the 2×2 helpers both modules use.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import sympy as sp
from sympy.core.function import AppliedUndef

from nonholonomic.hamiltonization.poisson import generalized_chaplygin_bracket

__all__ = ["flow_fields", "prove_theorem_1"]


def _symbols_of(expr: sp.Expr) -> sp.Expr:
    """Derivatives and applied undefined functions replaced by fresh symbols (highest order first)."""
    ders = sorted(expr.atoms(sp.Derivative), key=lambda d: -sum(c for _, c in d.variable_count))
    expr = expr.xreplace({d: sp.Dummy() for d in ders})
    return expr.xreplace({f: sp.Dummy() for f in expr.atoms(AppliedUndef)})


def det2(M: sp.Matrix) -> sp.Expr:
    """Determinant of a 2×2 matrix, written out (sympy's ``det`` simplifies the entries)."""
    return M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]


def adj2(M: sp.Matrix) -> sp.Matrix:
    """Adjugate of a 2×2 matrix: ``adj(M) M = det(M) 1``."""
    return sp.Matrix([[M[1, 1], -M[0, 1]], [-M[1, 0], M[0, 0]]])




@lru_cache(maxsize=4)
def prove_theorem_1(s_bar: str = "N*B", convention: str = "theorem_1") -> tuple[bool, str]:
    """Theorem 1 for *arbitrary* functions: G (symmetric), w, V, a₁, a₂, b of (q₁, q₂) and N with
    ∂N/∂q₁ = N A₂, ∂N/∂q₂ = −N A₁ (the density's equations).

    The τ-flow of eq. (2704-7), written in (q, p = N ∂L/∂q̇), minus the Hamiltonian field of
    H̄ = H(q, p/N) with the bracket (2704-9): derivatives of N are replaced by the density's
    equations, every other function and derivative by a symbol, and the numerators over a common
    denominator are expanded. ``s_bar`` is "N*B" (ERRATA 6) or "B" (the printed proof);
    ``convention`` is "theorem_1" (dx/dτ = {x, H̄}) or "brackets_py" (dx/dτ = {H̄, x}).

    Returns
    -------
    (bool, str)
        Whether all four components vanish identically, and which do not.
    """
    q = sp.symbols("q1 q2", real=True)
    v = sp.symbols("v1 v2", real=True)
    F = {name: sp.Function(name)(*q) for name in ("g11", "g12", "g22", "w1", "w2", "V", "a1", "a2", "b")}
    G = sp.Matrix([[F["g11"], F["g12"]], [F["g12"], F["g22"]]])
    L = (sp.Matrix(v).T * G * sp.Matrix(v))[0, 0] / 2 + F["w1"] * v[0] + F["w2"] * v[1] - F["V"]
    a = sp.Matrix([F["a1"], F["a2"]])
    w = sp.Matrix([F["w1"], F["w2"]])
    Ginv = adj2(G) / det2(G)
    A1, A2 = Ginv * a
    B = F["b"] - (a.T * Ginv * w)[0, 0]
    S = F["a1"] * v[0] + F["a2"] * v[1] + F["b"]
    P = (sp.Dummy("P1"), sp.Dummy("P2"))
    p = sp.symbols("p1 p2", real=True)
    H = ((sp.Matrix(P) - w).T * Ginv * (sp.Matrix(P) - w))[0, 0] / 2 + F["V"]
    Nf = sp.Function("N")(*q)
    n = sp.Dummy("n")
    H_bar = H.xreplace({P[0]: p[0] / Nf, P[1]: p[1] / Nf})
    flow, theorem_1, brackets_py = flow_fields(L, q, v, S, Nf, Nf * B if s_bar == "N*B" else B, H_bar, p)
    field_ = theorem_1 if convention == "theorem_1" else brackets_py
    rules = {sp.Derivative(Nf, q[0]): n * A2, sp.Derivative(Nf, q[1]): -n * A1}
    failing = []
    for i, (x, y) in enumerate(zip(flow, field_)):
        d = _symbols_of((x - y).doit().xreplace(rules).xreplace({Nf: n}))
        if sp.expand(sp.numer(sp.together(d))) != 0:
            failing.append(("dq1", "dq2", "dp1", "dp2")[i] + "/dtau")
    what = f"S_bar = {s_bar}, dx/dtau = " + ("{x, H_bar}" if convention == "theorem_1" else "{H_bar, x}")
    if failing:
        return False, f"{what}: not identically equal to the tau-flow in {', '.join(failing)}"
    return True, (f"{what}: the tau-flow of eq. 2704-7 in (q, p = N dL/dq_dot) equals the Hamiltonian field for "
                  "arbitrary G, w, V, a1, a2, b and every N with dN/dq1 = N A2, dN/dq2 = -N A1 "
                  "(numerators expanded to 0)")


def flow_fields(L: sp.Expr, q: Sequence[sp.Symbol], v: Sequence[sp.Symbol], S: sp.Expr, N: sp.Expr,
                 S_bar: sp.Expr, H_bar: sp.Expr, p: Sequence[sp.Symbol]) -> tuple[list[sp.Expr], ...]:
    """The τ-flow of eq. (2704-7) in (q, p = N ∂L/∂q̇) and the two Hamiltonian fields of H̄ with the
    bracket (2704-9), all as functions of (q, q̇): ``(flow, theorem_1, brackets_py)`` where
    theorem_1 is dx/dτ = {x, H̄} = P∇H̄ and brackets_py is ``hamiltonian_vector_field(H̄)`` = −P∇H̄."""
    G = sp.Matrix(2, 2, lambda i, j: sp.diff(L, v[i], v[j]))
    # eq. (2704-7) solved for q̈ from L itself (not through the Legendre transform)
    rhs = (sp.Matrix([v[1] * S, -v[0] * S]) + sp.Matrix([sp.diff(L, qi) for qi in q])
           - sp.Matrix(2, 2, lambda i, j: sp.diff(L, v[i], q[j])) * sp.Matrix(v))
    qdd = adj2(G) * rhs / det2(G)
    p_of = [N * sp.diff(L, vi) for vi in v]
    flow = [v[0] / N, v[1] / N] + [
        (sum(sp.diff(pi, qj) * vj for qj, vj in zip(q, v)) + sum(sp.diff(pi, vj) * a for vj, a in zip(v, qdd))) / N
        for pi in p_of]
    bracket = generalized_chaplygin_bracket(S_bar, q, p)
    at = {p[0]: p_of[0], p[1]: p_of[1]}
    brackets_py = [f.xreplace(at) for f in bracket.hamiltonian_vector_field(H_bar)]
    theorem_1 = [-f for f in brackets_py]
    return flow, theorem_1, brackets_py
