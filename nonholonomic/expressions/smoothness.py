"""What the numeric side needs of a parsed expression: derivatives that are functions, and powers the
integrator can take.

The grammar allows ``abs`` and ``sign`` (a claim or a Casimir may use them) and any constant exponent,
but the equations of motion, the Jacobi identity and Theorem 1 differentiate what the user wrote:
the derivative of ``sign(x)`` is a Dirac delta and that of ``abs(x)`` is ``sign(x)``, which no numeric
check can evaluate (sympy's ``DiracDelta`` has no numpy counterpart), and heyoka's translation takes
rational exponents only (``x**pi`` would recurse without end). Each use refuses such input here, with
the reason and a smooth stand-in, before anything is computed with it.
"""

from __future__ import annotations

import sympy as sp

from nonholonomic.expressions.names import ExpressionError

#: Functions whose derivatives are not functions, with a smooth stand-in; the number is how many
#: derivatives are functions (sign: none; abs: the first, sign).
NOT_SMOOTH: dict[type, tuple[str, int, str]] = {
    sp.sign: ("sign", 0, "for sign(x) write x/sqrt(x**2 + eps**2)"),
    sp.Abs: ("abs", 1, "for |x| write sqrt(x**2 + eps**2)"),
}


def differentiable(expr: sp.Expr, why: str, order: int = 2) -> sp.Expr:
    """``expr`` unchanged if its derivatives up to ``order`` are functions (no Dirac delta).

    Parameters
    ----------
    expr : sympy.Expr
        A parsed expression.
    why : str
        What differentiates it, for the message (e.g. "the equations need U's gradient").
    order : int
        1: ``sign`` of a non-constant argument is refused; 2 or more: ``abs`` too.

    Raises
    ------
    ExpressionError
        Naming the function, ``why`` and a smooth stand-in.
    """
    for func, (name, derivatives, instead) in NOT_SMOOTH.items():
        if order > derivatives and any(not a.is_number for a in expr.atoms(func)):
            raise ExpressionError(f"{name}() is not smooth: {why} ({instead})")
    return expr


def integrable(expr: sp.Expr) -> sp.Expr:
    """``expr`` as the integrator takes it: rational exponents only, ``cot``, ``sec``, ``csc`` written
    with ``sin`` and ``cos``.

    Raises
    ------
    ExpressionError
        For a power whose exponent is not a rational number (``x**pi``, ``x**sqrt(2)``, ``x**q``).
    """
    for power in expr.atoms(sp.Pow):
        if not power.exp.is_Rational:
            raise ExpressionError(f"the exponent of {power} must be a rational number (write exp(y*log(x)) for "
                                  "x**y)")
    return expr.replace(sp.cot, lambda x: sp.cos(x) / sp.sin(x)).replace(
        sp.sec, lambda x: 1 / sp.cos(x)).replace(sp.csc, lambda x: 1 / sp.sin(x))


#: Functions that are not analytic where their argument is 0 (or at all).
_KINKS = (sp.Abs, sp.sign, sp.Piecewise, sp.Heaviside, sp.Min, sp.Max, sp.floor, sp.ceiling)


def analytic_and_positive(expr: sp.Expr) -> bool:
    """Whether sympy proves ``expr`` analytic and positive for every real value of its symbols.

    No ``abs``, ``sign``, ``Piecewise`` ..., every power with a non-integer exponent (and every ``log``) of an
    argument sympy proves positive, and ``expr`` itself proven positive. False means "not proven": e.g.
    √(1 − sin θ)·√(1 + sin θ) (= |cos θ|, a kink at each zero), sin ψ sin θ (a sign change), √(J + m a²) with
    m of either sign.
    """
    real = expr.xreplace({s: sp.Dummy(s.name, real=True) for s in expr.free_symbols})
    if real.has(*_KINKS):
        return False
    if any(not p.exp.is_integer and p.base.is_positive is not True for p in real.atoms(sp.Pow)):
        return False
    if any(a.args[0].is_positive is not True for a in real.atoms(sp.log)):
        return False
    return real.is_positive is True


def kink_arguments(expr: sp.Expr) -> list[sp.Expr]:
    """The expressions at whose zeros ``expr`` may fail to be analytic: the arguments of ``abs``, ``sign`` and
    ``Heaviside``, the bases of powers with a non-integer exponent and the arguments of ``log``, the two sides'
    difference of each condition of a ``Piecewise`` and the pairwise differences of ``Min``/``Max``."""
    found: list[sp.Expr] = []
    for node in sp.preorder_traversal(expr):
        if isinstance(node, (sp.Abs, sp.sign, sp.Heaviside, sp.log)):
            found.append(node.args[0])
        elif isinstance(node, sp.Pow) and not node.exp.is_integer:
            found.append(node.base)
        elif isinstance(node, sp.Piecewise):
            found += [c.lhs - c.rhs for _, c in node.args if isinstance(c, sp.core.relational.Relational)]
        elif isinstance(node, (sp.Min, sp.Max)):
            found += [x - y for i, x in enumerate(node.args) for y in node.args[i + 1:]]
    return list(dict.fromkeys(e for e in found if not e.is_number))
