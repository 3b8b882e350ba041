"""Safe parsing of user expressions (Lagrangians, bracket entries, densities) into sympy — no eval.

Users send mechanical data as text, e.g. the Lagrangian of a body in Euler angles
``"1/2*(I1*thetadot**2 + sin(theta)**2*phidot**2)"`` or an entry ``"x*y - z"`` of a Poisson matrix
``P_ij = {x_i, x_j}`` (the form of eqs. (2604-6) and (2704-9); see :mod:`nonholonomic.brackets`). This
module turns such text into sympy objects without ``eval``, ``exec``, ``sympify`` or ``parse_expr``:
the text is parsed by Python's own parser (``ast.parse(text, mode="eval")``, which builds a tree and
runs nothing), the tree is checked against a whitelist, and the sympy expression is built node by node
from the whitelisted pieces only.

Grammar (everything else is refused with :class:`ExpressionError`):

* numbers: ``int`` and decimal ``float`` literals (``3``, ``2.5``, ``1e-3``); no complex, bool, None,
  strings or bytes;
* names: declared variables (see :func:`declare_symbols`) and the constants ``pi`` and ``E``;
* unary ``+``/``-``; binary ``+ - * / **``; ``^`` is refused with "use ** for powers";
* calls of :data:`ALLOWED_FUNCTIONS` by plain name with the right number of positional arguments.

Design decisions
----------------
* **Decimal literals are exact.** ``2.5`` becomes ``Rational(5, 2)`` and ``0.1`` becomes
  ``Rational(1, 10)``: the literal's *text* is converted through :class:`decimal.Decimal`, never through
  binary floating point, so symbolic identities (cancellations in brackets, divergences that must vanish
  identically) stay exact. ``2.5*x == 5*x/2`` holds structurally.
* **Euler's number is ``E``** (sympy's spelling); lower-case ``e`` is *not* a constant and stays free for
  a user variable (an eccentricity, a unit-vector component). Declared names may not collide with a
  function or constant name: declaring ``E``, ``pi`` or ``sin`` raises :class:`ExpressionError` at
  declaration, so a name in an expression always has exactly one meaning. ``E1, E2, E3`` (space-fixed
  components) are fine.
* **Declared variables are real** ``sympy.Symbol(name, real=True)``, matching
  :func:`nonholonomic.definition.vector_symbols`, so a declared ``M1`` equals the library's ``M1``.
* **Positions** are 0-based character offsets into the text as sent. Tabs, newlines, form feeds are
  treated as spaces (offsets unchanged), so a long expression may be wrapped over lines. For a refused
  node the position is the node's ``col_offset``; for a refused binary operator (``^``, ``%``, ``//``…)
  it is the operator's own character; for a numeric exponent out of range it is the exponent's start;
  for a syntax error it is Python's ``SyntaxError.offset - 1``; for a too long text ``max_length``; for
  too many nodes the last character of the shortest prefix holding ``max_nodes + 1`` nodes; for a
  non-certifiable constant (below) the call or operation that would form it.

Resource guards (all checked *before* sympy builds the offending object)
-----------------------------------------------------------------------
* text length ``max_length``; characters must be ASCII (non-ASCII and control characters are refused at
  their position); ``#`` comments are refused (they would silently swallow the rest of a line);
* bracket nesting and expression nesting ``max_depth`` — a run of ``+ -`` (or of ``* /``) counts as one
  level, so a long sum is limited by ``max_nodes``, not by ``max_depth``;
* node count ``max_nodes`` (expression nodes of the syntax tree);
* literal magnitude ``|value| <= 1e15`` (:data:`MAX_LITERAL`), at most :data:`MAX_DECIMAL_PLACES`
  decimals;
* numeric exponents: ``|n| <= 64`` and denominator ``<= 64`` (:data:`MAX_EXPONENT`). Exponents built only
  from literals (``9**9**9``) are evaluated exactly in :class:`fractions.Fraction` arithmetic with the
  same bounds first, so sympy never sees ``9**387420489``; exponents that become numbers only inside
  sympy (``2**sqrt(4096)``) are checked on the built exponent before the power is formed;
* exact numbers (and numeric coefficients) are limited to :data:`MAX_NUMBER_BITS` bits of numerator and
  denominator, predicted before a power is computed; exponents that sympy forms by combining powers
  (``((x**64)**64)**64 = x**262144``) are limited to :data:`MAX_RESULT_EXPONENT`;
* **constant sub-expressions are certified finite and real**: sympy's automatic evaluation asks
  assumption questions (``is_negative``...) of constant expressions and answers them with ``evalf``,
  which never returns for inputs as short as ``abs(tan(exp(10**15)))`` (mpmath needs ~10**15 bits to
  reduce the argument) or runs out of memory on ``exp(exp(10**15)) - 1``. Before sympy applies a
  function or a power to constant arguments, a small outward-rounded float interval arithmetic
  encloses the result; it must be real, finite and at most :data:`MAX_CONSTANT_MAGNITUDE` in size, and a
  denominator must certainly be non-zero. ``exp(c*log(b))``, which sympy rewrites into ``b**c``, is
  refused for ``|c| > 64``;
* a cumulative wall-clock budget :data:`PARSE_BUDGET_S` (checked between nodes).

Measured (tests/unit/test_expressions.py): every refusal, and the slowest accepted 2000-character
inputs (e.g. 60 ``sign(sin(k)**2 + cos(k)**2 - 1)``, which sympy evaluates numerically), take < 1 s.
Pass 2 still relies on sympy's automatic evaluation being cheap for certified constants; refused
inputs are never handed to sympy.
"""

from __future__ import annotations

import ast
import difflib
import keyword
import math
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from decimal import Decimal, InvalidOperation
from fractions import Fraction
from types import MappingProxyType

import sympy as sp

__all__ = [
    "ALLOWED_CONSTANTS",
    "ALLOWED_FUNCTIONS",
    "ExpressionError",
    "FUNCTION_ARITY",
    "RESERVED_NAMES",
    "declare_symbols",
    "parse_expression",
    "parse_matrix",
]

#: Longest accepted variable name.
MAX_NAME_LENGTH = 32
#: Largest accepted numeric literal (absolute value).
MAX_LITERAL = 10**15
#: Most digits after the decimal point of a literal (``1e-150`` is accepted, ``1e-151`` not).
MAX_DECIMAL_PLACES = 150
#: Bound on |numeric exponent| and on its denominator.
MAX_EXPONENT = 64
#: Bound on |exponent| and its denominator of powers sympy forms by combining nested powers.
MAX_RESULT_EXPONENT = 4096
#: Bits of numerator / denominator of any exact number produced while parsing.
MAX_NUMBER_BITS = 512
#: Bound on |value| of any constant sub-expression (certified by interval arithmetic).
MAX_CONSTANT_MAGNITUDE = 1e150
#: Entries of a matrix accepted by :func:`parse_matrix` (override with ``max_entries=``).
MAX_MATRIX_ENTRIES = 400
#: Cumulative seconds one :func:`parse_expression` call may spend building sympy objects.
PARSE_BUDGET_S = 5.0

#: Functions a user may call (name as written → sympy constructor). This dict is for display; the
#: parser uses a private read-only copy, so mutating it cannot widen what is accepted.
ALLOWED_FUNCTIONS: dict[str, Callable[..., sp.Expr]] = {
    "sin": sp.sin, "cos": sp.cos, "tan": sp.tan, "cot": sp.cot, "sec": sp.sec, "csc": sp.csc,
    "asin": sp.asin, "acos": sp.acos, "atan": sp.atan, "atan2": sp.atan2,
    "sinh": sp.sinh, "cosh": sp.cosh, "tanh": sp.tanh,
    "exp": sp.exp, "log": sp.log, "sqrt": sp.sqrt, "abs": sp.Abs, "sign": sp.sign,
}
#: Number of positional arguments of each allowed function.
FUNCTION_ARITY: dict[str, int] = {name: 2 if name == "atan2" else 1 for name in ALLOWED_FUNCTIONS}
#: Named constants: ``pi`` and Euler's number ``E`` (lower-case ``e`` is free for user variables).
ALLOWED_CONSTANTS: dict[str, sp.Expr] = {"pi": sp.pi, "E": sp.E}

_FUNCTIONS: Mapping[str, Callable[..., sp.Expr]] = MappingProxyType(dict(ALLOWED_FUNCTIONS))
_ARITY: Mapping[str, int] = MappingProxyType(dict(FUNCTION_ARITY))
_CONSTANTS: Mapping[str, sp.Expr] = MappingProxyType(dict(ALLOWED_CONSTANTS))
#: Names a user may not declare: the functions and constants above.
RESERVED_NAMES: frozenset[str] = frozenset(_FUNCTIONS) | frozenset(_CONSTANTS)

#: Common spellings of allowed functions, for hints in error messages.
_HINTS = {"ln": "log", "arcsin": "asin", "arccos": "acos", "arctan": "atan", "arctan2": "atan2",
          "Abs": "abs", "fabs": "abs", "pow": "**", "power": "**", "e": "E"}
_WHITESPACE = "\t\n\r\f\v"
_OPEN, _CLOSE = "([{", ")]}"


class ExpressionError(ValueError):
    """A refused expression or name.

    Attributes
    ----------
    reason : str
        What is wrong, in words.
    position : int or None
        0-based character offset into ``text`` where the problem is; None when it concerns the whole
        input (e.g. a bad declared name).
    text : str
        The text that was parsed (the entry's text for :func:`parse_matrix`).
    entry : tuple of int or None
        ``(row, column)`` of the matrix entry, for errors raised by :func:`parse_matrix`.

    ``str(error)`` is ``"<reason> at character <position>"`` (plus ``" of matrix entry (i, j)"``).
    """

    def __init__(self, reason: str, position: int | None = None, text: str = "",
                 entry: tuple[int, int] | None = None) -> None:
        super().__init__(reason, position, text, entry)  # args make the error picklable (workers)
        self.reason = reason
        self.position = position
        self.text = text
        self.entry = entry

    def __str__(self) -> str:
        out = self.reason if self.position is None else f"{self.reason} at character {self.position}"
        if self.entry is not None:
            where = f"matrix entry ({self.entry[0]}, {self.entry[1]})"
            out += f" of {where}" if self.position is not None else f" ({where})"
        return out

    def __repr__(self) -> str:
        return (f"ExpressionError(reason={self.reason!r}, position={self.position!r}, "
                f"text={_clip(self.text, 60)!r}, entry={self.entry!r})")

    def as_dict(self) -> dict[str, object]:
        """JSON-ready form: ``reason``, ``position``, ``entry`` (list or None), ``message``."""
        return {"reason": self.reason, "position": self.position,
                "entry": list(self.entry) if self.entry is not None else None, "message": str(self)}


def _clip(s: str, n: int = 40) -> str:
    return s if len(s) <= n else s[: n - 1] + "…"


# ---------------------------------------------------------------------------------------------------
# Names
# ---------------------------------------------------------------------------------------------------

def _name_problem(name: object) -> str | None:
    """Why ``name`` cannot be a declared variable, or None if it can."""
    if not isinstance(name, str):
        return f"variable names must be strings, got {type(name).__name__}"
    shown = repr(_clip(name))
    if not name:
        return "empty variable name"
    if not name.isascii():
        return f"variable name {shown} is not ASCII (use e.g. 'theta' for θ)"
    if not name.isidentifier():
        return f"variable name {shown} is not an identifier (letters, digits, '_', not starting with a digit)"
    if len(name) > MAX_NAME_LENGTH:
        return f"variable name {shown} is longer than {MAX_NAME_LENGTH} characters"
    if name.startswith("_"):
        return f"variable name {shown} starts with '_'"
    if keyword.iskeyword(name):
        return f"variable name {shown} is a Python keyword"
    if name in _FUNCTIONS:
        return f"variable name {shown} collides with the function {name}()"
    if name in _CONSTANTS:
        return f"variable name {shown} collides with the constant {name}"
    return None


def declare_symbols(names: Sequence[str]) -> dict[str, sp.Symbol]:
    """Validate user variable names and create their (real) sympy symbols.

    Parameters
    ----------
    names : sequence of str
        Python identifiers, ASCII, at most :data:`MAX_NAME_LENGTH` characters, not starting with
        ``_``, not a keyword, not a function or constant name (:data:`RESERVED_NAMES`), no duplicates.

    Returns
    -------
    dict of str to sympy.Symbol
        ``name → Symbol(name, real=True)`` in the given order.

    Raises
    ------
    ExpressionError
        With ``position=None`` and a reason naming the bad name.
    """
    if isinstance(names, (str, bytes)) or not isinstance(names, Sequence):
        raise ExpressionError("variable names must be a list of strings, not "
                              f"{'a single string' if isinstance(names, str) else type(names).__name__}")
    out: dict[str, sp.Symbol] = {}
    for name in names:
        problem = _name_problem(name)
        if problem is not None:
            raise ExpressionError(problem)
        if name in out:
            raise ExpressionError(f"variable name {name!r} is declared twice")
        out[name] = sp.Symbol(name, real=True)
    return out


def _checked_symbols(symbols: Mapping[str, sp.Symbol]) -> Mapping[str, sp.Symbol]:
    """The same checks for a mapping that did not necessarily come from :func:`declare_symbols`."""
    if not isinstance(symbols, Mapping):
        raise TypeError(f"symbols must be a mapping name -> sympy.Symbol, got {type(symbols).__name__}")
    for name, symbol in symbols.items():
        problem = _name_problem(name)
        if problem is not None:
            raise ExpressionError(problem)
        if not isinstance(symbol, sp.Symbol):
            raise TypeError(f"symbols[{name!r}] must be a sympy.Symbol, got {type(symbol).__name__}")
    return symbols


# ---------------------------------------------------------------------------------------------------
# Interval enclosure of constant sub-expressions (pure float arithmetic: it cannot hang)
# ---------------------------------------------------------------------------------------------------

class _Uncertified(Exception):
    """A constant sub-expression could not be certified real, finite and of bounded size."""


_REL = 2.0**-50  # outward widening, ~4 ulp: covers the rounding of libm functions
_ABS = 2.0**-1000
_PI = math.pi


def _bounded(lo: float, hi: float) -> tuple[float, float]:
    if not (math.isfinite(lo) and math.isfinite(hi)) or max(-lo, hi) > MAX_CONSTANT_MAGNITUDE:
        raise _Uncertified(f"a constant sub-expression exceeds {MAX_CONSTANT_MAGNITUDE:g} in size")
    return lo, hi


def _widen(lo: float, hi: float) -> tuple[float, float]:
    """Round outward by a few ulp (covers the rounding of float operations and libm functions)."""
    return _bounded(lo - abs(lo) * _REL - _ABS, hi + abs(hi) * _REL + _ABS)


def _contains(lo: float, hi: float, offset: float, period: float) -> bool:
    """Whether [lo, hi] may contain ``offset + k*period`` for an integer k (conservative: errs to yes)."""
    slack = 1e-9 * (1.0 + abs(lo) + abs(hi))
    k = math.floor((lo - slack - offset) / period)
    return any(lo - slack <= offset + (k + i) * period <= hi + slack for i in range(3))


def _mul(a: tuple[float, float], b: tuple[float, float]) -> tuple[float, float]:
    p = (a[0] * b[0], a[0] * b[1], a[1] * b[0], a[1] * b[1])
    return _widen(min(p), max(p))


def _inverse(a: tuple[float, float], what: str = "a denominator") -> tuple[float, float]:
    if a[0] <= 0.0 <= a[1]:
        raise _Uncertified(f"{what} may be zero")
    return _widen(1.0 / a[1], 1.0 / a[0])


def _fpow(x: float, n: int) -> float:
    try:
        return x**n
    except OverflowError as err:
        raise _Uncertified(f"a constant sub-expression exceeds {MAX_CONSTANT_MAGNITUDE:g} in size") from err


def _pow(b: tuple[float, float], e: tuple[float, float], exact: sp.Rational | None) -> tuple[float, float]:
    """Enclosure of ``b**e``; ``exact`` is the exponent when it is a rational number."""
    lo, hi = b
    if exact is not None and exact.q == 1:
        n = int(exact.p)
        if n == 0:
            return 1.0, 1.0
        if n < 0:
            return _inverse(_pow(b, e, sp.Integer(-n)), "a base raised to a negative power")
        if n % 2:
            return _widen(_fpow(lo, n), _fpow(hi, n))
        small = 0.0 if lo <= 0.0 <= hi else min(abs(lo), abs(hi))
        out = _widen(_fpow(small, n), _fpow(max(abs(lo), abs(hi)), n))
        return max(out[0], 0.0), out[1]
    # fractional or irrational exponent: b**e = exp(e*log b), real only for b >= 0
    if lo < 0.0:
        raise _Uncertified("a fractional power of a constant that may be negative is not certainly real")
    if lo == 0.0:  # b in [0, hi]: increasing in b for e > 0
        if e[0] <= 0.0:
            raise _Uncertified("a constant that may be zero is raised to a power that may be negative")
        if hi == 0.0:
            return 0.0, 0.0
        return 0.0, _exp(_mul(_widen(math.log(hi), math.log(hi)), e))[1]
    return _exp(_mul(_widen(math.log(lo), math.log(hi)), e))


def _exp(a: tuple[float, float]) -> tuple[float, float]:
    if a[1] > math.log(MAX_CONSTANT_MAGNITUDE):
        raise _Uncertified(f"a constant exponential exceeds {MAX_CONSTANT_MAGNITUDE:g}")
    out = _widen(math.exp(a[0]), math.exp(a[1]))
    return max(out[0], 0.0), out[1]


def _sin(a: tuple[float, float], shift: float = 0.0) -> tuple[float, float]:
    """sin on [lo, hi]; ``shift = pi/2`` gives cos (maxima at pi/2 - shift + 2k pi)."""
    lo, hi = a
    if hi - lo >= 2 * _PI:
        return -1.0, 1.0
    f = math.cos if shift else math.sin
    ends = sorted((f(lo), f(hi)))
    top = 1.0 if _contains(lo, hi, _PI / 2 - shift, 2 * _PI) else ends[1]
    bottom = -1.0 if _contains(lo, hi, -_PI / 2 - shift, 2 * _PI) else ends[0]
    lo2, hi2 = _widen(bottom, top)
    return max(lo2, -1.0), min(hi2, 1.0)


def _tan(a: tuple[float, float], cot: bool = False) -> tuple[float, float]:
    lo, hi = a
    if hi - lo >= _PI or _contains(lo, hi, 0.0 if cot else _PI / 2, _PI):
        raise _Uncertified(f"{'cot' if cot else 'tan'} of a constant may be infinite")
    if cot:
        return _widen(1.0 / math.tan(hi), 1.0 / math.tan(lo))
    return _widen(math.tan(lo), math.tan(hi))


def _apply(name: str, args: list[tuple[float, float]]) -> tuple[float, float]:
    """Enclosure of ``name(*args)`` for the functions sympy may produce from the allowed ones."""
    a = args[0]
    lo, hi = a
    if name in ("sin", "cos"):
        return _sin(a, _PI / 2 if name == "cos" else 0.0)
    if name in ("tan", "cot"):
        return _tan(a, cot=name == "cot")
    if name in ("sec", "csc"):
        return _inverse(_sin(a, _PI / 2 if name == "sec" else 0.0), f"the {name} denominator")
    if name in ("asin", "acos"):
        if lo < -1.0 or hi > 1.0:
            raise _Uncertified(f"{name} of a constant outside [-1, 1] is not real")
        return _widen(math.asin(lo), math.asin(hi)) if name == "asin" else _widen(math.acos(hi), math.acos(lo))
    if name == "atan":
        return _widen(math.atan(lo), math.atan(hi))
    if name == "atan2":
        if a[0] <= 0.0 <= a[1] and args[1][0] <= 0.0 <= args[1][1]:
            raise _Uncertified("atan2 of constants that may both be zero is undefined")
        return _widen(-_PI, _PI)
    if name in ("exp", "sinh", "cosh"):
        if max(-lo, hi) > math.log(MAX_CONSTANT_MAGNITUDE):
            raise _Uncertified(f"a constant {name} exceeds {MAX_CONSTANT_MAGNITUDE:g}")
        if name == "exp":
            return _exp(a)
        if name == "sinh":
            return _widen(math.sinh(lo), math.sinh(hi))
        small = 0.0 if lo <= 0.0 <= hi else min(abs(lo), abs(hi))
        out = _widen(math.cosh(small), math.cosh(max(abs(lo), abs(hi))))
        return max(out[0], 1.0), out[1]
    if name == "tanh":
        return _widen(math.tanh(lo), math.tanh(hi))
    if name == "log":
        if lo <= 0.0:
            raise _Uncertified("log of a constant that may be zero or negative")
        return _widen(math.log(lo), math.log(hi))
    if name == "Abs":
        small = 0.0 if lo <= 0.0 <= hi else min(abs(lo), abs(hi))
        out = _widen(small, max(abs(lo), abs(hi)))
        return max(out[0], 0.0), out[1]
    if name == "sign":
        return (1.0, 1.0) if lo > 0.0 else (-1.0, -1.0) if hi < 0.0 else (-1.0, 1.0)
    raise _Uncertified(f"cannot certify a constant {name}(...)")


_SYMPY_NAMES = {sp.Abs: "Abs", sp.sign: "sign", sp.exp: "exp", sp.log: "log", sp.atan2: "atan2",
                sp.sin: "sin", sp.cos: "cos", sp.tan: "tan", sp.cot: "cot", sp.sec: "sec", sp.csc: "csc",
                sp.asin: "asin", sp.acos: "acos", sp.atan: "atan",
                sp.sinh: "sinh", sp.cosh: "cosh", sp.tanh: "tanh"}


class _Enclosure:
    """Memoised interval enclosures of constant sympy expressions."""

    def __init__(self) -> None:
        self._const: dict[sp.Basic, bool] = {}
        self._box: dict[sp.Basic, tuple[float, float]] = {}

    def constant(self, e: sp.Basic) -> bool:
        """Whether ``e`` contains no symbol (memoised; the tree depth is bounded by the parser)."""
        hit = self._const.get(e)
        if hit is None:
            hit = not e.is_Symbol and all(self.constant(a) for a in e.args)
            self._const[e] = hit
        return hit

    def box(self, e: sp.Basic) -> tuple[float, float]:
        """Enclosure of a constant expression; raises :class:`_Uncertified`."""
        hit = self._box.get(e)
        if hit is None:
            hit = self._compute(e)
            self._box[e] = hit
        return hit

    def _compute(self, e: sp.Basic) -> tuple[float, float]:
        if e.is_Rational:
            try:
                v = int(e.p) / int(e.q)  # correctly rounded
            except OverflowError as err:
                raise _Uncertified(f"a constant exceeds {MAX_CONSTANT_MAGNITUDE:g} in size") from err
            exact = Fraction(v) == Fraction(int(e.p), int(e.q))  # e.g. 1, 1/2: asin(1) stays allowed
            return _bounded(v, v) if exact else _widen(v, v)
        if e is sp.pi or e is sp.E:
            v = math.pi if e is sp.pi else math.e
            return _widen(v, v)
        if e is sp.I:
            raise _Uncertified("a constant sub-expression is not real (contains the imaginary unit)")
        if e in (sp.zoo, sp.nan, sp.oo, -sp.oo):
            raise _Uncertified(f"a constant sub-expression is undefined or infinite ({e})")
        if e.is_Float:
            v = float(e)
            return _widen(v, v)
        if e.is_Add:
            lo = hi = 0.0
            for a in e.args:
                b = self.box(a)
                lo, hi = _widen(lo + b[0], hi + b[1])
            return lo, hi
        if e.is_Mul:
            out = (1.0, 1.0)
            for a in e.args:
                out = _mul(out, self.box(a))
            return out
        if e.is_Pow:
            base, exponent = e.args
            return _pow(self.box(base), self.box(exponent), exponent if exponent.is_Rational else None)
        name = _SYMPY_NAMES.get(type(e))
        if name is None:
            raise _Uncertified(f"cannot certify a constant {type(e).__name__}(...)")
        return _apply(name, [self.box(a) for a in e.args])


# ---------------------------------------------------------------------------------------------------
# The parser
# ---------------------------------------------------------------------------------------------------

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
        self.deadline = time.monotonic() + PARSE_BUDGET_S

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
        gap = self.clean[node.left.end_col_offset:node.right.col_offset]  # type: ignore[attr-defined]
        found = gap.find(symbol)
        position = node.left.end_col_offset + found if found >= 0 else node.col_offset  # type: ignore[attr-defined]
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
            source = self.clean[node.col_offset:node.end_col_offset].replace("_", "")  # type: ignore[attr-defined]
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
        if time.monotonic() > self.deadline:
            raise self.at(node, f"expression took more than {PARSE_BUDGET_S:g} s to build")
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
                    self.certify(operand, lambda: _inverse(self.enclosure.box(v), "the denominator"))
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


def _check_size(tree: ast.Expression, text: str, max_depth: int, max_nodes: int) -> None:
    """Node count and nesting depth, both computed without recursion."""
    nodes = [n for n in ast.walk(tree.body) if isinstance(n, ast.expr)]
    if len(nodes) > max_nodes:  # position: text[:position + 1] already holds max_nodes + 1 nodes
        position = sorted(n.end_col_offset for n in nodes)[max_nodes] - 1  # type: ignore[misc]
        raise ExpressionError(f"expression has {len(nodes)} nodes; the limit is {max_nodes}", position, text)
    stack: list[tuple[ast.AST, int]] = [(tree.body, 1)]
    while stack:
        node, level = stack.pop()
        if level > max_depth:
            raise ExpressionError(f"expression nested deeper than {max_depth} levels",
                                  getattr(node, "col_offset", None), text)
        stack.extend((child, level + 1) for child in _children(node))


def _parse(text: str, symbols: Mapping[str, sp.Symbol], max_length: int, max_depth: int,
           max_nodes: int) -> sp.Expr:
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
