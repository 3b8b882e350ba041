"""Which of a request's expressions cannot be evaluated in floating point at sample points (issue 34, item 2).

A tower of exponentials, exp(exp(exp(exp(exp(θ))))), is a valid expression whose value at θ ~ 1 has about a
million digits in its exponent: mpmath's high-precision checks then raise ``OverflowError`` or run out of memory.
When that happens the request is refused naming the field(s) whose value overflows a float at the sample points
(math's functions raise ``OverflowError`` at once, with no large allocation), instead of a 500.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Mapping, Sequence

import sympy as sp

from nonholonomic.expressions import parse_expression

__all__ = ["NUMERIC_ERRORS", "numeric_problems", "overflowing_fields"]

#: What a numeric evaluation of a user's expression may raise past the float range or the memory.
NUMERIC_ERRORS = (OverflowError, MemoryError, RecursionError, FloatingPointError)

#: The coordinates' values at which the expressions are probed (inside (0, π/2), away from charts' poles).
PROBES = (0.35, 0.7, 1.05, 1.3)


def overflowing_fields(fields: Mapping[str, sp.Expr | None], variables: Sequence[sp.Symbol],
                       values: Mapping[sp.Symbol, float]) -> list[tuple[str, str]]:
    """``(field, reason)`` for each expression whose float value overflows at a probe point.

    Parameters
    ----------
    fields : the request's parsed expressions by field name (None: not given).
    variables : the symbols probed at :data:`PROBES` (coordinates and velocities).
    values : fixed values of the other symbols (the parameters).
    """
    out = []
    for name, expr in fields.items():
        if expr is None:
            continue
        symbols = sorted(expr.free_symbols, key=str)
        try:
            fn = sp.lambdify(symbols, expr, modules="math")
        except Exception:  # noqa: BLE001 - a printer limit: nothing to say about magnitude
            continue
        for probe in PROBES:
            point = [values.get(s, probe) if s not in variables else probe for s in symbols]
            try:
                value = complex(fn(*point))
            except NUMERIC_ERRORS as exc:
                out.append((name, "its value overflows the floating-point range at the sample points "
                                  f"({type(exc).__name__} at {probe:g}): an expression that grows this fast cannot "
                                  "be evaluated or checked (a tower of exponentials, say)"))
                break
            except (ValueError, ZeroDivisionError, TypeError):
                continue
            if not (math.isfinite(value.real) and math.isfinite(value.imag)):
                out.append((name, f"its value is not finite at the sample points (at {probe:g}): an expression that "
                                  "grows this fast cannot be evaluated or checked"))
                break
    return out


def _variable_names(text: str) -> set[str]:
    """The names an expression uses as variables (not called, not a constant), read from its syntax tree."""
    tree = ast.parse(text.replace("^", "**"), mode="eval")
    called = {id(n.func) for n in ast.walk(tree) if isinstance(n, ast.Call)}
    return {n.id for n in ast.walk(tree) if isinstance(n, ast.Name) and id(n) not in called} - {"pi", "E"}


def numeric_problems(expressions: Sequence[tuple[str, str]], exc: BaseException) -> list[tuple[str, str]]:
    """The fields of a request whose check raised ``exc`` (one of :data:`NUMERIC_ERRORS`): those of
    ``expressions`` (``(field, text)``) whose float value overflows at sample points, else every one of them
    (issue 34, item 2: a numeric failure is a 422 naming the field, never a 500)."""
    parsed: dict[str, sp.Expr | None] = {}
    for field, text in expressions:
        try:
            parsed[field] = parse_expression(text, {n: sp.Symbol(n) for n in _variable_names(text)})
        except Exception:  # noqa: BLE001 - an expression the parser refuses was reported already
            continue
    symbols = sorted({s for e in parsed.values() if e is not None for s in e.free_symbols}, key=str)
    culprits = overflowing_fields(parsed, symbols, {})
    if culprits:
        return culprits
    why = (f"evaluating it left the floating-point range or the memory ({type(exc).__name__}): its values grow "
           "too fast (a tower of exponentials, say) or its constants are too large or too small")
    return [(field, why) for field, _ in expressions] or [("body", why)]
