"""Deterministic size measures of a user's expression, read from its syntax tree (no sympy).

What sympy does with an expression (a surface's gradient, a potential's field, a Poincaré surface's
derivative along the flow) can take minutes for a text of 25 characters: ``(M1 + gamma2 + gamma3 + 1)**64``
expands to 47,905 monomials (46 s to check as a Poincaré surface), and ``sin(sin(...sin(x1)...))`` nested 59
deep has second derivatives of 59² factors (13 s as a surface). A request is refused for such a text by
two measures of the work, the same on every machine and at any load (never a clock):

* :func:`expanded_terms`: an upper bound on the monomials of the expression multiplied out (a sum adds,
  a product multiplies, ``(a)**n`` with n a non-negative integer literal gives ``C(terms(a) + n − 1, n)``,
  a function call or another power counts as one monomial whose arguments are measured apart), the
  largest over its sub-expressions; at most :data:`MAX_EXPANDED_TERMS`;
* :func:`function_nesting`: how deeply calls (and non-integer powers) are nested; at most
  :data:`MAX_FUNCTION_NESTING`.
"""

from __future__ import annotations

import ast
from math import comb

#: Largest accepted :func:`expanded_terms`.
MAX_EXPANDED_TERMS = 10_000
#: Largest accepted :func:`function_nesting`.
MAX_FUNCTION_NESTING = 12
#: Past this a count is not refined further (comb of large numbers stays cheap, but need not be exact).
_CAP = 10**12


def _integer_exponent(node: ast.expr) -> int | None:
    """A non-negative integer literal exponent (``2``, ``+3``), else None."""
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.UAdd):
        node = node.operand
    if isinstance(node, ast.Constant) and isinstance(node.value, int) and not isinstance(node.value, bool):
        return node.value if node.value >= 0 else None
    return None


class _Measure:
    def __init__(self) -> None:
        self.largest = 1
        self.deepest = 0

    def terms(self, node: ast.AST, depth: int = 0) -> int:
        """Monomials of ``node`` multiplied out (capped); records the largest and the deepest nesting."""
        if isinstance(node, ast.Expression):
            return self.terms(node.body, depth)
        if isinstance(node, ast.UnaryOp):
            out = self.terms(node.operand, depth)
        elif isinstance(node, ast.BinOp):
            left = self.terms(node.left, depth)
            if isinstance(node.op, (ast.Add, ast.Sub)):
                out = left + self.terms(node.right, depth)
            elif isinstance(node.op, (ast.Mult, ast.Div)):
                out = left * self.terms(node.right, depth)
            elif isinstance(node.op, ast.Pow) and (n := _integer_exponent(node.right)) is not None:
                out = comb(min(left, _CAP) + n - 1, n) if n else 1
            else:  # a root, a symbolic exponent: one monomial of its own
                self.terms(node.right, depth + 1)
                self.deepest = max(self.deepest, depth + 1)
                out = 1
        elif isinstance(node, ast.Call):
            self.deepest = max(self.deepest, depth + 1)
            for arg in node.args:
                self.terms(arg, depth + 1)
            out = 1
        else:
            out = 1
        out = min(out, _CAP)
        self.largest = max(self.largest, out)
        return out


def _measure(text: str) -> _Measure:
    measure = _Measure()
    measure.terms(ast.parse(" ".join(text.split()), mode="eval"))
    return measure


def expanded_terms(text: str) -> int:
    """An upper bound on the monomials of ``text`` (already checked by the safe parser) multiplied out:
    the largest over its sub-expressions (module doc)."""
    return _measure(text).largest


def function_nesting(text: str) -> int:
    """How deeply function calls and non-integer powers nest in ``text`` (``sin(cos(x))``: 2)."""
    return _measure(text).deepest


def size_problem(text: str, max_terms: int = MAX_EXPANDED_TERMS,
                 max_nesting: int = MAX_FUNCTION_NESTING) -> str | None:
    """Why ``text`` is too large to be read by sympy on a request's path, or None (module doc)."""
    try:
        measure = _measure(text)
    except (SyntaxError, ValueError, RecursionError):
        return None  # the safe parser says what is wrong with it
    if measure.largest > max_terms:
        return (f"expands to up to {measure.largest:,} monomials > max {max_terms:,} (MAX_EXPANDED_TERMS): "
                "write it without large powers of sums")
    if measure.deepest > max_nesting:
        return (f"nests functions {measure.deepest} deep > max {max_nesting} (MAX_FUNCTION_NESTING): write it "
                "with fewer nested functions")
    return None
