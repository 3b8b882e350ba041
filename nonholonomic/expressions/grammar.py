"""The parser: Python's AST checked against a whitelist (pass 1, no sympy), then built into sympy node by
node with checks on what sympy produced (pass 2). See :mod:`nonholonomic.expressions` for the grammar."""

from __future__ import annotations

import ast
import difflib
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from decimal import Decimal, InvalidOperation
from fractions import Fraction

import sympy as sp

from nonholonomic.expressions.intervals import (
    _apply,
    _Enclosure,
    _inverse,
    _pow,
    _Uncertified,
)
from nonholonomic.expressions.limits import (
    MAX_DECIMAL_PLACES,
    MAX_EXPONENT,
    MAX_LITERAL,
    MAX_MATRIX_ENTRIES,
    MAX_NUMBER_BITS,
    MAX_RESULT_EXPONENT,
)
from nonholonomic.expressions.names import (
    _ARITY,
    _CONSTANTS,
    _FUNCTIONS,
    _HINTS,
    ExpressionError,
    _checked_symbols,
    _clip,
)

_WHITESPACE = "\t\n\r\f\v"
_OPEN, _CLOSE = "([{", ")]}"

_UNDEFINED = (sp.zoo, sp.nan, sp.oo, -sp.oo)
_SUM, _PRODUCT = "sum", "product"
_CHAIN = {ast.Add: _SUM, ast.Sub: _SUM, ast.Mult: _PRODUCT, ast.Div: _PRODUCT}
_OPERATORS = {ast.BitXor: "^", ast.FloorDiv: "//", ast.Mod: "%", ast.MatMult: "@", ast.LShift: "<<",
              ast.RShift: ">>", ast.BitOr: "|", ast.BitAnd: "&"}
_REFUSED = {
    ast.Attribute: "attribute access (x.y) is not allowed",
    ast.Subscript: "indexing (x[i]) is not allowed",
    ast.Slice: "slices are not allowed",
    ast.Lambda: "lambda expressions are not allowed",
    ast.ListComp: "comprehensions are not allowed",
    ast.SetComp: "comprehensions are not allowed",
    ast.DictComp: "comprehensions are not allowed",
    ast.GeneratorExp: "generator expressions are not allowed",
    ast.IfExp: "conditional expressions (a if c else b) are not allowed",
    ast.Compare: "comparisons are not allowed",
    ast.BoolOp: "boolean operators (and, or) are not allowed",
    ast.JoinedStr: "f-strings are not allowed",
    ast.FormattedValue: "f-strings are not allowed",
    ast.List: "lists are not allowed",
    ast.Tuple: "tuples are not allowed (one expression expected)",
    ast.Set: "sets are not allowed",
    ast.Dict: "dicts are not allowed",
    ast.NamedExpr: "assignment expressions (:=) are not allowed",
    ast.Starred: "starred expressions are not allowed",
    ast.Await: "await is not allowed",
    ast.Yield: "yield is not allowed",
    ast.YieldFrom: "yield is not allowed",
}


def _chain(node: ast.BinOp) -> tuple[ast.expr, list[tuple[ast.operator, ast.expr]]]:
    """Flatten a left-associated run of ``+ -`` (or ``* /``): first operand and (operator, operand)s."""
    kind = _CHAIN[type(node.op)]
    rest: list[tuple[ast.operator, ast.expr]] = []
    current: ast.expr = node
    while isinstance(current, ast.BinOp) and _CHAIN.get(type(current.op)) == kind:
        rest.append((current.op, current.right))
        current = current.left
    rest.reverse()
    return current, rest


def _children(node: ast.AST) -> list[ast.AST]:
    """Sub-expressions one nesting level down (a + / * run is one level)."""
    if isinstance(node, ast.BinOp) and type(node.op) in _CHAIN:
        first, rest = _chain(node)
        return [first, *(operand for _, operand in rest)]
    return [c for c in ast.iter_child_nodes(node) if isinstance(c, (ast.expr, ast.keyword))]


def _fmt(v: Fraction | sp.Rational) -> str:
    return str(v) if len(str(v)) <= 40 else f"a number with {len(str(v))} characters"


def _bits(v: Fraction | sp.Rational) -> int:
    num, den = (v.numerator, v.denominator) if isinstance(v, Fraction) else (int(v.p), int(v.q))
    return max(abs(num).bit_length(), den.bit_length())


class _Parser:
    def __init__(self, text: str, clean: str, symbols: Mapping[str, sp.Symbol]) -> None:
        self.text = text    # as sent (for error messages)
        self.clean = clean  # whitespace-normalised, same offsets
        self.symbols = symbols
        self.enclosure = _Enclosure()

    def error(self, reason: str, position: int | None) -> ExpressionError:
        return ExpressionError(reason, position, self.text)

    def at(self, node: ast.AST, reason: str) -> ExpressionError:
        return self.error(reason, getattr(node, "col_offset", None))

    # -- pass 1: whitelist, names, calls, literals and exact literal arithmetic (no sympy) ----------

    def validate(self, node: ast.AST) -> Fraction | None:
        """Check ``node``; return its exact value if it is built from literals only, else None."""
        if isinstance(node, ast.Constant):
            return self.literal(node)
        if isinstance(node, ast.Name):
            self.name(node)
            return None
        if isinstance(node, ast.UnaryOp):
            if not isinstance(node.op, (ast.UAdd, ast.USub)):
                raise self.at(node, f"operator '{'not' if isinstance(node.op, ast.Not) else '~'}' is not allowed")
            v = self.validate(node.operand)
            return None if v is None else (-v if isinstance(node.op, ast.USub) else v)
        if isinstance(node, ast.BinOp):
            if type(node.op) in _CHAIN:
                return self.validate_chain(node)
            if isinstance(node.op, ast.Pow):
                return self.validate_power(node)
            raise self.operator_error(node)
        if isinstance(node, ast.Call):
            self.validate_call(node)
            return None
        raise self.at(node, _REFUSED.get(type(node), f"{type(node).__name__} expressions are not allowed"))

    def operator_error(self, node: ast.BinOp) -> ExpressionError:
        symbol = _OPERATORS.get(type(node.op), "?")
        gap = self.clean[node.left.end_col_offset:node.right.col_offset]
        found = gap.find(symbol)
        position = _end(node.left) + found if found >= 0 else node.col_offset
        if isinstance(node.op, ast.BitXor):
            return self.error("'^' is not a power operator: use ** for powers", position)
        return self.error(f"operator '{symbol}' is not allowed (use + - * / **)", position)

    def literal(self, node: ast.Constant) -> Fraction:
        v = node.value
        if isinstance(v, bool) or v is None or v is Ellipsis:
            raise self.at(node, f"{v!r} is not allowed; only numbers, variables and functions")
        if isinstance(v, (str, bytes)):
            raise self.at(node, "string literals are not allowed")
        if isinstance(v, complex):
            raise self.at(node, "complex literals (…j) are not allowed")
        if isinstance(v, int):
            if abs(v) > MAX_LITERAL:
                raise self.at(node, f"number {_fmt(Fraction(v))} is too large (|value| <= 1e15)")
            return Fraction(v)
        if isinstance(v, float):
            source = self.clean[node.col_offset:node.end_col_offset].replace("_", "")
            try:
                d = Decimal(source)
            except InvalidOperation as err:  # pragma: no cover - Python accepted it as a float
                raise self.at(node, f"unreadable number {_clip(source)!r}") from err
            if not d.is_finite() or d.adjusted() > 15 or abs(d) > MAX_LITERAL:
                raise self.at(node, f"number {_clip(source)} is too large (|value| <= 1e15)")
            if -int(d.as_tuple().exponent) > MAX_DECIMAL_PLACES:
                raise self.at(node, f"number {_clip(source)} has more than {MAX_DECIMAL_PLACES} decimal places")
            return Fraction(d)  # exact: 2.5 -> 5/2, 0.1 -> 1/10
        raise self.at(node, f"{type(v).__name__} literals are not allowed")  # pragma: no cover

    def name(self, node: ast.Name) -> None:
        name = node.id
        if name in self.symbols or name in _CONSTANTS:
            return
        if name.startswith("_"):
            raise self.at(node, f"names starting with '_' are not allowed ({_clip(name)!r})")
        if name in _FUNCTIONS:
            raise self.at(node, f"'{name}' is a function: call it as {name}(...)")
        raise self.at(node, self.unknown("name", name, self.symbols))

    def unknown(self, what: str, name: str, known: Mapping[str, object]) -> str:
        listed = sorted(known)
        shown = ", ".join(listed[:30]) + (f", … ({len(listed) - 30} more)" if len(listed) > 30 else "")
        label = "declared" if what == "name" else "allowed"
        reason = f"unknown {what} {_clip(name)!r}; {label}: {shown or '(none)'}"
        hint = _HINTS.get(name)
        close = difflib.get_close_matches(name, list(known) + (list(_CONSTANTS) if what == "name" else []), 1)
        if hint:
            reason += f" (did you mean {hint}?" + (" Euler's number is E or exp(1))" if name == "e" else ")")
        elif close:
            reason += f" (did you mean {close[0]!r}?)"
        return reason

    def validate_chain(self, node: ast.BinOp) -> Fraction | None:
        first, rest = _chain(node)
        acc = self.validate(first)
        for op, operand in rest:
            v = self.validate(operand)
            if isinstance(op, ast.Div) and v == 0:
                raise self.at(operand, "division by zero")
            if acc is None or v is None:
                acc = None
                continue
            acc = {ast.Add: acc.__add__, ast.Sub: acc.__sub__, ast.Mult: acc.__mul__,
                   ast.Div: acc.__truediv__}[type(op)](v)
            if _bits(acc) > MAX_NUMBER_BITS:
                raise self.at(node, f"a number with more than {MAX_NUMBER_BITS} bits arises here")
        return acc

    def check_exponent(self, exponent: Fraction | sp.Rational, node: ast.AST) -> None:
        den = exponent.denominator if isinstance(exponent, Fraction) else int(exponent.q)
        if abs(exponent) > MAX_EXPONENT:
            raise self.at(node, f"exponent {_fmt(exponent)} is too large (numeric exponents must satisfy "
                                f"|n| <= {MAX_EXPONENT})")
        if den > MAX_EXPONENT:
            raise self.at(node, f"exponent {_fmt(exponent)} has a denominator above {MAX_EXPONENT} "
                                "(write a simple fraction such as 1/3)")

    def validate_power(self, node: ast.BinOp) -> Fraction | None:
        base = self.validate(node.left)
        exponent = self.validate(node.right)
        if exponent is None:
            return None
        self.check_exponent(exponent, node.right)
        if base is None or exponent.denominator != 1:
            return None
        n = exponent.numerator
        if base == 0 and n < 0:
            raise self.at(node, "division by zero (0 to a negative power)")
        if _bits(base) * abs(n) > MAX_NUMBER_BITS:
            raise self.at(node, f"a number with more than {MAX_NUMBER_BITS} bits arises here")
        return base**n

    def validate_call(self, node: ast.Call) -> None:
        func = node.func
        if not isinstance(func, ast.Name):
            self.validate(func)  # reports a lambda / attribute / ... inside first
            raise self.at(node, "only the allowed functions can be called, by plain name")
        name = func.id
        if name.startswith("_"):
            raise self.at(func, f"names starting with '_' are not allowed ({_clip(name)!r})")
        if name not in _FUNCTIONS:
            if name in self.symbols:
                raise self.at(func, f"'{name}' is a declared variable, not a function (write {name}*(...))")
            if name in _CONSTANTS:
                raise self.at(func, f"'{name}' is a constant, not a function")
            raise self.at(func, self.unknown("function", name, _FUNCTIONS))
        if node.keywords:
            kw = node.keywords[0]
            raise self.at(kw, f"keyword arguments are not allowed in {name}(...)")
        for arg in node.args:
            if isinstance(arg, ast.Starred):
                raise self.at(arg, f"starred arguments are not allowed in {name}(...)")
        arity = _ARITY[name]
        if len(node.args) > arity:
            raise self.at(node.args[arity], f"{name}() takes {arity} argument{'s' if arity > 1 else ''} "
                                            f"({len(node.args)} given)")
        if len(node.args) < arity:
            raise self.at(node, f"{name}() takes {arity} argument{'s' if arity > 1 else ''} "
                                f"({len(node.args)} given)")
        for arg in node.args:
            self.validate(arg)

    # -- pass 2: build sympy objects, with checks on what sympy produced ----------------------------

    def build(self, node: ast.AST) -> sp.Expr:
        if isinstance(node, ast.Constant):
            v = self.literal(node)
            return sp.Rational(v.numerator, v.denominator)
        if isinstance(node, ast.Name):
            return self.symbols[node.id] if node.id in self.symbols else _CONSTANTS[node.id]
        if isinstance(node, ast.UnaryOp):
            operand = self.build(node.operand)
            return self.checked(-operand if isinstance(node.op, ast.USub) else operand, node)
        if isinstance(node, ast.BinOp) and type(node.op) in _CHAIN:
            return self.build_chain(node)
        if isinstance(node, ast.BinOp):  # ** (pass 1 refused the other operators)
            return self.power(self.build(node.left), self.build(node.right), node, node.right)
        assert isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
        return self.call(node.func.id, [self.build(a) for a in node.args], node)

    def build_chain(self, node: ast.BinOp) -> sp.Expr:
        first, rest = _chain(node)
        items = [self.build(first)]
        for op, operand in rest:
            v = self.build(operand)
            if isinstance(op, ast.Sub):
                v = self.checked(-v, operand)
            elif isinstance(op, ast.Div):
                if v == 0:
                    raise self.at(operand, "division by zero")
                if self.enclosure.constant(v):
                    def inverse(denominator: sp.Expr = v) -> tuple[float, float]:
                        return _inverse(self.enclosure.box(denominator), "the denominator")

                    self.certify(operand, inverse)
                v = self.power(v, sp.Integer(-1), operand, operand)
            items.append(v)
        return self.checked((sp.Add if _CHAIN[type(node.op)] == _SUM else sp.Mul)(*items), node)

    def power(self, base: sp.Expr, exponent: sp.Expr, node: ast.AST, exponent_node: ast.AST) -> sp.Expr:
        if exponent.is_Number:
            if not exponent.is_Rational:  # pragma: no cover - literals are exact
                raise self.at(exponent_node, "inexact exponent")
            self.check_exponent(exponent, exponent_node)
            coefficient = base if base.is_Rational else base.as_coeff_Mul()[0] if base.is_Mul else None
            if coefficient is not None and coefficient.is_Rational:
                if coefficient == 0 and exponent < 0:
                    raise self.at(node, "division by zero (0 to a negative power)")
                # sympy distributes the power over the coefficient: predict its size (|p|, not |p|/q)
                if _bits(coefficient) * abs(int(exponent.p)) > MAX_NUMBER_BITS:
                    raise self.at(node, f"a number with more than {MAX_NUMBER_BITS} bits arises here")
        if base is sp.E:
            self.exp_guard(exponent, node)
        if base != 0 and self.enclosure.constant(base) and self.enclosure.constant(exponent):
            self.certify(node, lambda: _pow(self.enclosure.box(base), self.enclosure.box(exponent),
                                            exponent if exponent.is_Rational else None))
        return self.checked(sp.Pow(base, exponent), node)

    def call(self, name: str, args: list[sp.Expr], node: ast.Call) -> sp.Expr:
        if name == "exp":
            self.exp_guard(args[0], node)
        if name == "sqrt":
            return self.power(args[0], sp.Rational(1, 2), node, node)
        if all(self.enclosure.constant(a) for a in args):
            self.certify(node, lambda: _apply("Abs" if name == "abs" else name,
                                              [self.enclosure.box(a) for a in args]))
        return self.checked(_FUNCTIONS[name](*args), node)

    def exp_guard(self, argument: sp.Expr, node: ast.AST) -> None:
        """sympy rewrites ``exp(c*log(b))`` as ``b**c`` while constructing it: bound ``c`` first."""
        for term in sp.Add.make_args(argument):
            if term.is_Mul and term.has(sp.log):
                c = term.as_coeff_Mul()[0]
                if abs(c) > MAX_EXPONENT or c.q > MAX_EXPONENT:
                    raise self.at(node, f"exp(c*log(...)) is a power with exponent c = {_fmt(c)}; numeric "
                                        f"exponents must satisfy |n| <= {MAX_EXPONENT}")

    def certify(self, node: ast.AST, enclose: Callable[[], tuple[float, float]]) -> None:
        try:
            enclose()
        except _Uncertified as err:
            raise self.at(node, str(err)) from None

    def checked(self, result: sp.Expr, node: ast.AST) -> sp.Expr:
        """Refuse what sympy produced if it is undefined, or holds a too large number or constant."""
        if result in _UNDEFINED or any(a in _UNDEFINED for a in result.args):
            raise self.at(node, "the expression is undefined here (division by zero or a singular value)")
        for kind, number in _top_numbers(result):
            if kind == "exponent" and (abs(number) > MAX_RESULT_EXPONENT or number.q > MAX_RESULT_EXPONENT):
                raise self.at(node, f"a power with exponent {_fmt(number)} arises here (combined "
                                    f"exponents must satisfy |n| <= {MAX_RESULT_EXPONENT})")
            if kind == "number" and _bits(number) > MAX_NUMBER_BITS:
                raise self.at(node, f"a number with more than {MAX_NUMBER_BITS} bits arises here")
        if self.enclosure.constant(result):
            self.certify(node, lambda: self.enclosure.box(result))
        return result


def _top_numbers(e: sp.Expr) -> Iterator[tuple[str, sp.Rational]]:
    """Exact numbers sympy may have just created at the top of ``e``: ``("number", q)`` for a number,
    coefficient or power base, ``("exponent", q)`` for a rational exponent (``(x**64)**64 = x**4096``)."""
    for term in e.args if e.is_Add else (e,):
        for factor in term.args if term.is_Mul else (term,):
            if factor.is_Rational:
                yield "number", factor
            elif factor.is_Pow:
                base, exponent = factor.args
                if base.is_Rational:
                    yield "number", base
                if exponent.is_Rational:
                    yield "exponent", exponent


def _prescan(text: str, max_length: int, max_depth: int) -> str:
    """Text-level checks; returns the text with tabs/newlines turned into spaces (same offsets)."""
    if len(text) > max_length:
        raise ExpressionError(f"expression is {len(text)} characters long; the limit is {max_length}",
                              max_length, text)
    depth = 0
    for i, ch in enumerate(text):
        if ch in _OPEN:
            depth += 1
            if depth > max_depth:
                raise ExpressionError(f"brackets nested deeper than {max_depth} levels", i, text)
        elif ch in _CLOSE:
            depth = max(depth - 1, 0)
        elif ch == "#":
            raise ExpressionError("comments ('#') are not allowed", i, text)
        elif not ch.isascii():
            raise ExpressionError(f"non-ASCII character {ch!r} (U+{ord(ch):04X}) is not allowed; names are "
                                  "ASCII identifiers (e.g. 'theta')", i, text)
        elif not ch.isprintable() and ch not in _WHITESPACE:
            raise ExpressionError(f"control character U+{ord(ch):04X} is not allowed", i, text)
    clean = text.translate({ord(c): " " for c in _WHITESPACE})
    if not clean.strip():
        raise ExpressionError("empty expression", 0, text)
    return clean


def _end(node: ast.expr) -> int:
    """Where ``node`` ends in the source (``ast.parse`` sets it on every node of a parsed expression)."""
    assert node.end_col_offset is not None
    return node.end_col_offset


def _check_size(tree: ast.Expression, text: str, max_depth: int, max_nodes: int) -> None:
    """Node count and nesting depth, both computed without recursion."""
    nodes = [n for n in ast.walk(tree.body) if isinstance(n, ast.expr)]
    if len(nodes) > max_nodes:  # position: text[:position + 1] already holds max_nodes + 1 nodes
        position = sorted(_end(n) for n in nodes)[max_nodes] - 1
        raise ExpressionError(f"expression has {len(nodes)} nodes; the limit is {max_nodes}", position, text)
    stack: list[tuple[ast.AST, int]] = [(tree.body, 1)]
    while stack:
        node, level = stack.pop()
        if level > max_depth:
            raise ExpressionError(f"expression nested deeper than {max_depth} levels",
                                  getattr(node, "col_offset", None), text)
        stack.extend((child, level + 1) for child in _children(node))


def _tree(text: str, max_length: int, max_depth: int, max_nodes: int) -> tuple[str, ast.Expression]:
    """Text-level checks and Python's syntax tree (parsed, never executed), its size checked."""
    if not isinstance(text, str):
        raise ExpressionError(f"an expression must be a string, got {type(text).__name__}")
    clean = _prescan(text, max_length, max_depth)
    try:
        tree = ast.parse(clean, mode="eval")  # parses only; nothing is executed
    except SyntaxError as err:
        reason = "invalid syntax" if err.msg == "invalid syntax" else f"invalid syntax: {err.msg}"
        position = None if err.offset is None else min(max(err.offset - 1, 0), len(text))
        raise ExpressionError(reason, position, text) from None
    except (ValueError, MemoryError, RecursionError) as err:  # e.g. a sum of thousands of terms
        raise ExpressionError(f"expression is too large to parse ({type(err).__name__})", None, text) from None
    _check_size(tree, text, max_depth, max_nodes)
    return clean, tree


def _parse(text: str, symbols: Mapping[str, sp.Symbol], max_length: int, max_depth: int,
           max_nodes: int) -> sp.Expr:
    clean, tree = _tree(text, max_length, max_depth, max_nodes)
    parser = _Parser(text, clean, symbols)
    try:
        parser.validate(tree.body)
        result = parser.build(tree.body)
    except RecursionError:
        raise ExpressionError("expression is too deeply nested", None, text) from None
    if result.has(sp.zoo, sp.nan, sp.oo, -sp.oo):
        raise ExpressionError("the expression is undefined (division by zero or a singular value)", 0, text)
    return result


def _check_limits(max_length: int, max_depth: int, max_nodes: int) -> None:
    for label, value in (("max_length", max_length), ("max_depth", max_depth), ("max_nodes", max_nodes)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{label} must be a positive integer, got {value!r}")


def parse_expression(text: str, symbols: Mapping[str, sp.Symbol], *, max_length: int = 2000,
                     max_depth: int = 60, max_nodes: int = 2000) -> sp.Expr:
    """Parse a user expression into sympy without evaluating any code.

    Parameters
    ----------
    text : str
        The expression, e.g. ``"1/2*(I1*thetadot**2 + sin(theta)**2*phidot**2)"``.
    symbols : mapping of str to sympy.Symbol
        The declared variables (normally from :func:`declare_symbols`; the same name rules are
        enforced here).
    max_length, max_depth, max_nodes : int
        Length of the text; nesting depth of brackets and of operations (a run of ``+ -`` or of
        ``* /`` is one level); number of expression nodes.

    Returns
    -------
    sympy.Expr
        With decimal literals converted exactly (``2.5 → 5/2``).

    Raises
    ------
    ExpressionError
        With ``reason``, ``position`` (0-based character offset) and ``text``.
    """
    _check_limits(max_length, max_depth, max_nodes)
    return _parse(text, _checked_symbols(symbols), max_length, max_depth, max_nodes)


def parse_matrix(rows: Sequence[Sequence[str]], symbols: Mapping[str, sp.Symbol], **limits: int) -> sp.Matrix:
    """Parse a rectangular matrix of expression strings, e.g. a Poisson matrix ``P_ij = {x_i, x_j}``.

    Parameters
    ----------
    rows : sequence of sequences of str
        Row-major entries, all rows of equal length.
    symbols : mapping of str to sympy.Symbol
        As for :func:`parse_expression`.
    **limits : int
        ``max_length``, ``max_depth``, ``max_nodes`` (per entry, see :func:`parse_expression`) and
        ``max_entries`` (default :data:`MAX_MATRIX_ENTRIES`).

    Returns
    -------
    sympy.Matrix

    Raises
    ------
    ExpressionError
        With ``entry = (row, column)`` for a bad entry; ``entry=None`` and ``position=None`` for a bad
        shape.
    """
    max_entries = limits.pop("max_entries", MAX_MATRIX_ENTRIES)
    unknown = set(limits) - {"max_length", "max_depth", "max_nodes"}
    if unknown:
        raise TypeError(f"unknown limits: {sorted(unknown)}")
    sizes = {"max_length": 2000, "max_depth": 60, "max_nodes": 2000, **limits}
    _check_limits(**sizes)
    symbols = _checked_symbols(symbols)
    if isinstance(rows, (str, bytes)) or not isinstance(rows, Sequence) or not rows:
        raise ExpressionError("a matrix must be a non-empty list of rows")
    width = None
    for i, row in enumerate(rows):
        if isinstance(row, (str, bytes)) or not isinstance(row, Sequence) or not row:
            raise ExpressionError(f"row {i} must be a non-empty list of expression strings")
        if width is None:
            width = len(row)
        elif len(row) != width:
            raise ExpressionError(f"row {i} has {len(row)} entries; row 0 has {width}")
    assert width is not None
    if len(rows) * width > max_entries:
        raise ExpressionError(f"matrix has {len(rows) * width} entries; the limit is {max_entries}")
    out = sp.zeros(len(rows), width)
    for i, row in enumerate(rows):
        for j, entry in enumerate(row):
            try:
                out[i, j] = _parse(entry, symbols, **sizes)
            except ExpressionError as err:
                raise ExpressionError(err.reason, err.position, err.text, (i, j)) from None
    return out


def check_expression(text: str, names: Iterable[str], *, max_length: int = 2000, max_depth: int = 60,
                     max_nodes: int = 2000) -> None:
    """The cheap part of :func:`parse_expression`: characters, length, syntax, size, the whitelist, the
    names and the literals, with no sympy (milliseconds, so it may run where a request is read).

    Parameters
    ----------
    text : str
        The expression.
    names : iterable of str
        The names it may use (besides ``pi`` and ``E``).
    max_length, max_depth, max_nodes : int
        As for :func:`parse_expression`.

    Raises
    ------
    ExpressionError
        As :func:`parse_expression` would for the same reason (its pass 2 may still refuse more).
    """
    _check_limits(max_length, max_depth, max_nodes)
    clean, tree = _tree(text, max_length, max_depth, max_nodes)
    try:
        _Parser(text, clean, {name: sp.Symbol(name) for name in names}).validate(tree.body)
    except RecursionError:
        raise ExpressionError("expression is too deeply nested", None, text) from None
