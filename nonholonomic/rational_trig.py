"""Exact decision of identities rational in q, sin qᵢ, cos qᵢ and parameters (the Weierstrass substitution).

Used by Theorem 1 (:mod:`nonholonomic.hamiltonization.reducing_multiplier`), the measure check
(:mod:`nonholonomic.evidence.measure`) and the paper report: t = tan(q/2), a common denominator, the
numerator expanded; an expression that is not of that form is undecided (None), never guessed.
"""

from __future__ import annotations

from collections.abc import Sequence

import sympy as sp


def _weierstrass(expr: sp.Expr, q: Sequence[sp.Symbol]) -> sp.Expr | None:
    """``expr`` with sin qᵢ = 2tᵢ/(1+tᵢ²), cos qᵢ = (1−tᵢ²)/(1+tᵢ²) (after ``expand_trig``); None if
    a qᵢ survives inside a function (then the substitution does not make ``expr`` rational)."""
    e = expr.replace(sp.tan, lambda x: sp.sin(x) / sp.cos(x)).replace(sp.cot, lambda x: sp.cos(x) / sp.sin(x))
    e = e.replace(sp.sec, lambda x: 1 / sp.cos(x)).replace(sp.csc, lambda x: 1 / sp.sin(x))
    e = sp.expand_trig(e)
    subs = {}
    for i, qi in enumerate(q):
        t = sp.Dummy(f"t{i + 1}")
        subs[sp.sin(qi)] = 2 * t / (1 + t**2)
        subs[sp.cos(qi)] = (1 - t**2) / (1 + t**2)
    e = e.xreplace(subs)
    if any(f.has(*q) for f in e.atoms(sp.Function)):
        return None
    return e


def rational_trig_is_zero(expr: sp.Expr, q: tuple[sp.Symbol, ...]) -> bool | None:
    """Exact decision of ``expr ≡ 0`` for ``expr`` rational in q, sin qᵢ, cos qᵢ and the parameters
    (t = tan(q/2), common denominator, numerator expanded). None if ``expr`` is not of that form."""
    e = _weierstrass(expr, q)
    if e is None:
        return None
    numerator = sp.expand(sp.numer(sp.together(e)))
    if numerator == 0:
        return True
    if any(isinstance(a, sp.Pow) and not a.exp.is_Integer for a in numerator.atoms(sp.Pow)):
        return None  # algebraic parts: a non-zero expanded numerator proves nothing
    return False

