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
