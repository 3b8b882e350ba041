"""A user's Lagrangian system reduced to a generalized Chaplygin system with two degrees of freedom
(paper, eq. 2704-7), so that Theorem 1 (:func:`nonholonomic.systems.generalized_chaplygin.define`)
gives its invariant measure, the reducing multiplier N, the time dτ = N dt (2704-8) and the
Hamiltonian form (2704-9), or says why not.

A Chaplygin system (Chaplygin; Neimark & Fufaev, ch. III): the coordinates split into 2 shape
coordinates q = (q₁, q₂) and k = n − 2 cyclic coordinates s; the constraints solve as

    ṡ_α = Σᵢ β_αi(q) q̇ᵢ,     L = L(q, q̇, ṡ)   (no s in L or β).

The Lagrange–d'Alembert equations with δs_α = Σᵢ β_αi δqᵢ, written with the reduced Lagrangian
L*(q, q̇) = L|_{ṡ = βq̇}, are Chaplygin's equations::

    d/dt ∂L*/∂q̇ᵢ − ∂L*/∂qᵢ = Σ_α (∂L/∂ṡ_α)|* Σⱼ (∂β_αi/∂qⱼ − ∂β_αj/∂qᵢ) q̇ⱼ

(from ∂L*/∂q̇ᵢ = ∂L/∂q̇ᵢ + Σ_α ∂L/∂ṡ_α β_αi and ∂L*/∂qᵢ = ∂L/∂qᵢ + Σ_α ∂L/∂ṡ_α Σⱼ ∂β_αj/∂qᵢ q̇ⱼ;
the sign is checked against :func:`nonholonomic.lagrangian.derive` in the tests). With two shape
coordinates the right side is (q̇₂ S, −q̇₁ S), i.e. eq. (2704-7), with

    S = Σ_α (∂L/∂ṡ_α)|* κ_α,   κ_α = ∂β_α1/∂q₂ − ∂β_α2/∂q₁,   S = a₁ q̇₁ + a₂ q̇₂ + b,

b coming from terms of L linear in the velocities; U = −L*|_{q̇=0}.

Measures: Theorem 1's ρ(q) dP dq (P = ∂L*/∂q̇) is ρ det G* dq dq̇ (G* = ∂²L*/∂q̇²). Since nothing
depends on s and ∂ṡ/∂s = 0, a density of q alone for the reduced flow is one for the flow in
(q, s, q̇) too: the density ρ(q, s) dq ds du of :func:`nonholonomic.lagrangian.measure_search.measure_verdict`
(with u = q̇, the shape velocities) is N det G* up to a constant factor.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np
import sympy as sp

from nonholonomic.lagrangian.checks import number, numeric_matrix, regular, sample_points
from nonholonomic.lagrangian.equations import _solve, tidy
from nonholonomic.lagrangian.parse import LagrangianData
from nonholonomic.systems.generalized_chaplygin import ChaplyginData

__all__ = ["ChaplyginReduction", "chaplygin_reduction"]

#: A derivative counts as non-zero at a sample point above this.
NONZERO = 1e-12


@dataclass(frozen=True)
class ChaplyginReduction:
    """Whether a Lagrangian system is a Chaplygin system with a 2-dimensional shape space, and its
    reduced form (eq. 2704-7).

    Attributes
    ----------
    data : ChaplyginData or None
        The reduced system for :func:`nonholonomic.systems.generalized_chaplygin.define`: L*'s velocity
        terms as ``L``, U = −L*|_{q̇=0}, a₁, a₂, b; None when not reduced.
    reason : str
        Why not (empty when reduced).
    shape : tuple of int
        Indices of the shape coordinates q₁, q₂ in the user's coordinates.
    dependent : tuple of (sympy.Symbol, sympy.Expr)
        ``(ṡ_α, Σᵢ β_αi q̇ᵢ)`` per cyclic coordinate s_α.
    values : tuple of float
        The values of ``data.parameters`` (the user's parameters the reduced system still uses).
    """

    data: ChaplyginData | None
    reason: str
    shape: tuple[int, ...] = ()
    dependent: tuple[tuple[sp.Symbol, sp.Expr], ...] = ()
    values: tuple[float, ...] = ()

    @property
    def reduced(self) -> bool:
        """Whether the system is of the form (2704-7)."""
        return self.data is not None

    def reduced_state(self, state: np.ndarray) -> np.ndarray:
        """The state (q₁, q₂, q̇₁, q̇₂) of the reduced system from the user's (q, q̇) (rows allowed)."""
        x = np.asarray(state, dtype=float)
        n = x.shape[-1] // 2
        return x[..., [*self.shape, *(n + i for i in self.shape)]]


class _Refused(Exception):
    """One choice of the cyclic coordinates does not work, with the reason."""


def _depends(expr: sp.Expr, s: sp.Symbol, points: list[dict[sp.Symbol, float]]) -> bool:
    """Whether ``expr`` depends on ``s`` (∂/∂s non-zero at a sample point, or not proven zero)."""
    d = tidy(sp.diff(expr, s))
    if d == 0:
        return False
    values = [number(d, p) for p in points]
    if any(v is not None and abs(v) > NONZERO for v in values):
        return True
    return sp.simplify(d) != 0  # zero at the points: proven only if it simplifies to 0


def _points(data: LagrangianData) -> list[dict[sp.Symbol, float]]:
    """The sample points of :mod:`checks` with random velocities too."""
    rng = np.random.default_rng(2704)
    return [{**p, **dict(zip(data.v, (float(x) for x in rng.uniform(-1.0, 1.0, len(data.v)))))}
            for p in sample_points(data)]


def _velocity_polynomial(expr: sp.Expr, v: tuple[sp.Symbol, ...]) -> sp.Expr:
    """``expr`` (a polynomial in ``v``) with each coefficient tidied."""
    poly = sp.Poly(sp.expand(expr), *v)
    return sp.Add(*(tidy(c) * sp.Mul(*(vi**e for vi, e in zip(v, m))) for m, c in poly.terms()))


def _try(data: LagrangianData, cyclic: tuple[int, ...], points: list[dict[sp.Symbol, float]]) -> ChaplyginReduction:
    """The reduction with the coordinates ``cyclic`` as s; raises :class:`_Refused`."""
    q, v, n = data.q, data.v, len(data.q)
    shape = tuple(i for i in range(n) if i not in cyclic)
    names = ", ".join(str(q[i]) for i in cyclic)
    A = sp.Matrix(data.A)
    k = len(cyclic)
    beta = sp.zeros(k, 2)
    if k:
        minor = A.extract(list(range(k)), list(cyclic))
        numeric = [numeric_matrix(minor, p) for p in points]
        if not all(m is not None and regular(m) for m in numeric):
            raise _Refused(f"the constraints cannot be solved for {', '.join(str(v[i]) for i in cyclic)} "
                           "(their minor of A is singular at a sample point)")
        beta = _solve(minor, -A.extract(list(range(k)), list(shape)), points).applyfunc(tidy)
    for i in cyclic:
        if _depends(data.L, q[i], points):
            raise _Refused(f"L depends on the dependent coordinate {q[i]}")
        if any(_depends(b, q[i], points) for b in beta):
            raise _Refused(f"the constraint coefficients depend on {q[i]} (after solving for the velocities of "
                           f"{names})")
    q1, q2 = (q[i] for i in shape)
    u = tuple(v[i] for i in shape)
    on = {v[c]: sp.expand(beta[a, 0] * u[0] + beta[a, 1] * u[1]) for a, c in enumerate(cyclic)}
    L_star = _velocity_polynomial(data.L.xreplace(on), u)
    G = sp.hessian(L_star, u)
    if not any(m is not None and regular(m) for m in (numeric_matrix(G, p) for p in points)):
        raise _Refused("the reduced Lagrangian L* has a singular kinetic matrix d2L*/dq_dot2 at every sample point")
    # S = Σ_α (∂L/∂ṡ_α)|* κ_α, κ_α = ∂β_α1/∂q₂ − ∂β_α2/∂q₁ (eq. 2704-7's right side)
    kappa = [tidy(sp.diff(beta[a, 0], q2) - sp.diff(beta[a, 1], q1)) for a in range(k)]
    S = sp.expand(sum((sp.diff(data.L, v[c]).xreplace(on) * kappa[a] for a, c in enumerate(cyclic)), sp.Integer(0)))
    a1, a2 = (tidy(sp.diff(S, ui)) for ui in u)
    b = tidy(S.xreplace({u[0]: 0, u[1]: 0}))
    if any(e.has(*u) for e in (a1, a2)):
        raise _Refused("S is not linear in the velocities (is L quadratic in them?)")
    U = -tidy(L_star.xreplace({u[0]: 0, u[1]: 0}))
    kinetic = sp.expand(L_star + U)
    used = set().union(*(e.free_symbols for e in (kinetic, U, a1, a2, b)))
    kept = [(p, val) for p, val in zip(data.parameters, data.values) if p in used]
    texts = (("L", sp.sstr(kinetic)), ("a1", sp.sstr(a1)), ("a2", sp.sstr(a2)), ("b", sp.sstr(b)),
             ("potential", sp.sstr(U)))
    chaplygin = ChaplyginData(q=(q1, q2), v=u, L=kinetic, U=U, a1=a1, a2=a2, b=b,
                              parameters=tuple(p for p, _ in kept), texts=texts)
    return ChaplyginReduction(chaplygin, "", shape, tuple((v[c], on[v[c]]) for c in cyclic),
                              tuple(val for _, val in kept))


def chaplygin_reduction(data: LagrangianData, at_values: bool = False) -> ChaplyginReduction:
    """Whether ``data`` is a Chaplygin system with a 2-dimensional shape space, and its reduced form (2704-7).

    Every choice of k = n − 2 coordinates as the cyclic ones s is tried, the last coordinates first (the
    first ones stay shape coordinates, as in :mod:`nonholonomic.lagrangian.measure_search`): the constraints must
    solve for ṡ (regular minor at every sample point), and L and the solved coefficients β must not depend
    on s. The first choice that works is returned.

    Parameters
    ----------
    data : LagrangianData
        From :func:`nonholonomic.lagrangian.parse_system`.
    at_values : bool
        Substitute the parameters' values exactly (as rationals) first. Theorem 1 then decides for these
        values; with the parameters symbolic (default) it decides for generic values (the sleigh with
        a = 0 has a measure that a symbolic a hides).

    Returns
    -------
    ChaplyginReduction
        With ``data`` (a :class:`ChaplyginData`: L* = L|_{ṡ=βq̇} split into its velocity terms and
        U = −L*|_{q̇=0}; S = Σ_α (∂L/∂ṡ_α)|* (∂β_α1/∂q₂ − ∂β_α2/∂q₁) = a₁q̇₁ + a₂q̇₂ + b), or with the
        reason it is not of this form (the number of independent velocities; per choice of s, what fails).
    """
    n, k = len(data.q), data.A.shape[0]
    m = n - k
    if m != 2:
        return ChaplyginReduction(None, f"{m} independent velocit{'y' if m == 1 else 'ies'} (n - k = {n} - {k}): "
                                        "eq. 2704-7 needs exactly 2")
    for field, expr in (("L", data.L), *((f"constraints[{i}]", f) for i, f in enumerate(data.constraints))):
        if expr.has(data.t):
            return ChaplyginReduction(None, f"{field} depends on the time t explicitly: eq. 2704-7 is autonomous")
    if at_values and data.parameters:
        exact = {p: sp.nsimplify(val, rational=True) for p, val in data.parameter_values.items()}
        data = replace(data, L=data.L.xreplace(exact), constraints=tuple(f.xreplace(exact) for f in data.constraints),
                       A=sp.ImmutableMatrix(data.A.xreplace(exact)), parameters=(), values=())
    points = _points(data)
    reasons = []
    for cyclic in sorted(itertools.combinations(range(n), k), key=lambda c: tuple(-i for i in reversed(c))):
        try:
            return _try(data, cyclic, points)
        except _Refused as refused:
            reasons.append(f"with {', '.join(str(data.q[i]) for i in cyclic)} cyclic: {refused}")
    return ChaplyginReduction(None, "not a Chaplygin system with 2 shape coordinates: " + "; ".join(reasons))
