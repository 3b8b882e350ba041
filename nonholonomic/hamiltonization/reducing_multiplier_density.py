"""Theorem 1's density ρ(q): ∂ ln ρ/∂q₁ = A₂, ∂ ln ρ/∂q₂ = −A₁ (proof of Theorem 1), found three ways.

In turn (each run to its end by :func:`nonholonomic.hamiltonization.reducing_multiplier.hamiltonize`, which first
checks its size against the deterministic limits of :mod:`nonholonomic.work_limits`): an
ansatz ρ = Π fⱼ^kⱼ exp(α·q) over the irreducible factors of A₁, A₂ and det G, exponents fitted at random
points, rationalized and proved exactly (:func:`_density_ansatz`); sympy's ``integrate``
(:func:`_density_by_integration`); the line integral from :data:`BASE_POINT`
(:func:`_density_line_integral`). :func:`_density_equations_hold` checks a candidate exactly.
"""

from __future__ import annotations

from collections.abc import Sequence
from fractions import Fraction

import numpy as np
import sympy as sp

from nonholonomic.numerics.precision import working_digits
from nonholonomic.rational_trig import rational_trig_is_zero
from nonholonomic.work_limits import MAX_INTEGRATE_OPS, operations, over

#: Base point of the line integral for ln ρ (inside (0, π/2)², where angle charts are regular).
BASE_POINT = (sp.Rational(7, 10), sp.Rational(2, 5))


def _reduce_cos_squares(expr: sp.Expr, q: Sequence[sp.Symbol]) -> sp.Expr:
    """``cos(qᵢ)^k → cos(qᵢ)^(k mod 2) (1 − sin²qᵢ)^(k div 2)``, expanded: a normal form modulo
    sin² + cos² = 1, so that factoring does not split sin² into (1 − cos)(1 + cos)."""
    def reduce(e: sp.Expr) -> sp.Expr:
        for qi in q:
            e = e.replace(lambda x, qi=qi: x.is_Pow and x.base == sp.cos(qi) and x.exp.is_Integer and x.exp >= 2,
                          lambda x, qi=qi: sp.cos(qi) ** (x.exp % 2) * (1 - sp.sin(qi) ** 2) ** (x.exp // 2))
        return e

    return sp.expand(reduce(sp.expand(expr)))


def _candidate_factors(exprs: Sequence[sp.Expr], q: tuple[sp.Symbol, sp.Symbol]) -> list[sp.Expr]:
    """Irreducible factors (polynomials in sin qᵢ, cos qᵢ, q and the parameters) of the numerators
    and denominators of ``exprs``, plus sin qᵢ, cos qᵢ, qᵢ: the basis of the ansatz ρ = Π fⱼ^kⱼ."""
    out: list[sp.Expr] = []

    def add(f: sp.Expr) -> None:
        _, f = f.as_independent(*q, as_Add=False)
        if f.has(*q) and f not in out and sp.expand(-f) not in out:
            out.append(f)

    for e in exprs:
        for part in sp.fraction(sp.together(e)):
            if part.has(*q):
                for f, _ in sp.factor_list(_reduce_cos_squares(part, q))[1]:
                    add(f)
    for qi in q:
        if any(e.has(sp.sin(qi), sp.cos(qi), sp.tan(qi)) for e in exprs):
            add(sp.sin(qi))
            add(sp.cos(qi))
        add(qi)
    return out


def _density_ansatz(A1: sp.Expr, A2: sp.Expr, extra: tuple[sp.Expr, ...], q: tuple[sp.Symbol, sp.Symbol],
                    values: tuple[tuple[sp.Symbol, float], ...]) -> tuple[sp.Expr, str] | None:
    """ρ = Π fⱼ^kⱼ exp(α₁q₁ + α₂q₂) with rational kⱼ fitted by least squares at random points to
    ∂ ln ρ/∂q₁ = A₂, ∂ ln ρ/∂q₂ = −A₁, then proved exactly. None if no such ρ is found."""
    import scipy.linalg

    factors = _candidate_factors((A1, A2) + extra, q)
    names = [s for s, _ in values]
    par = [x for _, x in values]
    targets = [A2, -A1]
    rows = [[sp.diff(f, qi) / f for f in factors] for qi in q]
    fn = sp.lambdify(list(q) + names, rows[0] + rows[1] + targets, modules="numpy")
    nf = len(factors)
    M, y = [], []
    for q1, q2 in np.random.default_rng(7).uniform(0.2, 1.35, (3 * (nf + 2) + 6, 2)):
        vals = np.asarray(fn(q1, q2, *par), dtype=float)
        M += [list(vals[:nf]) + [1.0, 0.0], list(vals[nf:2 * nf]) + [0.0, 1.0]]
        y += [vals[2 * nf], vals[2 * nf + 1]]
    M_arr, y_arr = np.array(M), np.array(y)
    if not (np.all(np.isfinite(M_arr)) and np.all(np.isfinite(y_arr))):
        return None
    # independent columns (column-pivoted QR), then the unique least-squares solution on them
    _, R, piv = scipy.linalg.qr(M_arr, pivoting=True, mode="economic")
    diag = np.abs(np.diag(R))
    keep = sorted(piv[: int(np.sum(diag > 1e-9 * diag[0]))]) if diag.size and diag[0] > 0 else []
    k = np.zeros(nf + 2)
    if keep:
        k[keep] = np.linalg.lstsq(M_arr[:, keep], y_arr, rcond=None)[0]
    if np.linalg.norm(M_arr @ k - y_arr) > 1e-7 * max(float(np.linalg.norm(y_arr)), 1e-300):
        return None
    exps = []
    for kj in k[:nf]:
        frac = Fraction(float(kj)).limit_denominator(24)
        if abs(float(frac) - kj) > 1e-6:
            return None
        exps.append(sp.Rational(frac.numerator, frac.denominator))
    used = [(e, f) for e, f in zip(exps, factors) if e != 0]
    # α: the rest of the 1-form must be constant; take it exactly at the base point
    alpha = []
    for i, (qi, target) in enumerate(zip(q, targets)):
        if abs(k[nf + i]) < 1e-9 * max(1.0, float(np.max(np.abs(y_arr)))):
            alpha.append(sp.Integer(0))
        else:
            rest = target - sum((e * sp.diff(f, qi) / f for e, f in used), sp.Integer(0))
            alpha.append(sp.cancel(rest.xreplace(dict(zip(q, BASE_POINT)))))
    log_rho = sum((e * sp.log(f) for e, f in used), sp.Integer(0)) + alpha[0] * q[0] + alpha[1] * q[1]
    for qi, target in zip(q, targets):  # an exact proof that d ln ρ = A₂ dq₁ − A₁ dq₂
        if rational_trig_is_zero(sp.diff(log_rho, qi) - target, q) is not True:
            return None
    # each factor's sign chosen positive at the base point (ρ is defined up to a constant factor)
    with working_digits(15):  # mpmath's precision is global: at double precision, whatever other threads ask
        at_base = sp.lambdify(list(q) + names, [f for _, f in used], modules="mpmath")(*BASE_POINT, *par)
    pieces = [((-f if float(s) < 0 else f) ** e) for (e, f), s in zip(used, at_base)]
    rho = sp.Mul(*pieces) * sp.exp(alpha[0] * q[0] + alpha[1] * q[1])
    return rho, ("ansatz rho = prod f_j^k_j exp(alpha.q) over the irreducible factors of A1, A2 and det G; exponents "
                 "fitted at random points, rationalized, and d ln rho = A2 dq1 - A1 dq2 proved exactly")


def _density_by_integration(A1: sp.Expr, A2: sp.Expr,
                            q: tuple[sp.Symbol, sp.Symbol]) -> tuple[sp.Expr, str, sp.Expr] | None:
    """ln ρ = ∫A₂ dq₁ + g(q₂), g′ = −A₁ − ∂/∂q₂ ∫A₂ dq₁ (sympy ``integrate``); None if sympy
    leaves an integral or g′ depends on q₁."""
    F = sp.integrate(sp.cancel(A2), q[0])
    if F.has(sp.Integral):
        return None
    h = sp.cancel(-A1 - sp.diff(F, q[1]))
    if h.has(q[0]):
        h = sp.simplify(h)
        if h.has(q[0]):
            return None
    G = sp.integrate(h, q[1])
    if G.has(sp.Integral):
        return None
    return (sp.exp(F + G), "ln rho = integral of A2 dq1 + g(q2), g' = -A1 - d/dq2 integral of A2 dq1 (sympy integrate)",
            F + G)


def _density_line_integral(A1: sp.Expr, A2: sp.Expr, q: tuple[sp.Symbol, sp.Symbol],
                           max_integrate_ops: int = MAX_INTEGRATE_OPS) -> tuple[sp.Expr, str, sp.Expr]:
    """ln ρ(q) = ∫₀¹ [A₂ (q₁ − q₁⁰) − A₁ (q₂ − q₂⁰)](q⁰ + s(q − q⁰)) ds, the straight segment from
    the base point q⁰ (valid on a star-shaped domain around it), in closed form if sympy finds one.

    sympy's ``integrate`` is only given an integrand of at most ``max_integrate_ops`` operations
    (:data:`nonholonomic.work_limits.MAX_INTEGRATE_OPS`); a larger one is left as an unevaluated integral
    (the same function, evaluated numerically where it is used)."""
    s = sp.Dummy("s")
    on_segment = {qi: q0 + s * (qi - q0) for qi, q0 in zip(q, BASE_POINT)}
    integrand = A2.xreplace(on_segment) * (q[0] - BASE_POINT[0]) - A1.xreplace(on_segment) * (q[1] - BASE_POINT[1])
    skipped = over(operations(integrand), max_integrate_ops, "max_integrate_ops", "sympy's integrate")
    if skipped is not None:
        integral, how = sp.Integral(integrand, (s, 0, 1)), f"left as an integral ({skipped})"
    else:
        integral = sp.integrate(integrand, (s, 0, 1))
        how = "left as an integral (no closed form found)" if integral.has(sp.Integral) else "evaluated by sympy"
    return sp.exp(integral), (f"ln rho = line integral of A2 dq1 - A1 dq2 along the segment from q0 = "
                              f"({BASE_POINT[0]}, {BASE_POINT[1]}), {how}"), integral


def _density_equations_hold(log_rho: sp.Expr, A1: sp.Expr, A2: sp.Expr, q: tuple[sp.Symbol, sp.Symbol]) -> bool | None:
    """Whether ∂ ln ρ/∂q₁ = A₂ and ∂ ln ρ/∂q₂ = −A₁ identically (None: undecided)."""
    verdicts = []
    for qi, target in zip(q, (A2, -A1)):
        e = sp.diff(log_rho, qi) - target
        verdict = rational_trig_is_zero(e, q)
        if verdict is None and not e.has(sp.Integral):
            verdict = True if sp.simplify(e) == 0 else None
        verdicts.append(verdict)
    return False if False in verdicts else (True if all(verdicts) else None)


