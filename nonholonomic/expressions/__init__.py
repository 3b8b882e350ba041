"""Safe parsing of user expressions (Lagrangians, bracket entries, densities) into sympy — no eval.

Users send mechanical data as text, e.g. the Lagrangian of a body in Euler angles
``"1/2*(I1*thetadot**2 + sin(theta)**2*phidot**2)"`` or an entry ``"x*y - z"`` of a Poisson matrix
``P_ij = {x_i, x_j}`` (the form of eqs. (2604-6) and (2704-9); see :mod:`nonholonomic.hamiltonization.poisson`). This
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
  refused for ``|c| > 64``.

No clock decides anything here: every guard is a deterministic measure of the text or of what sympy
built, so the same expression is accepted or refused (an :class:`ExpressionError`, a 422 in the API)
with the same words on every machine and at any load. These limits bound the work: measured
(tests/unit/test_expressions.py), every refusal, and the slowest accepted 2000-character inputs (e.g.
60 ``sign(sin(k)**2 + cos(k)**2 - 1)``, which sympy evaluates numerically), take < 1 s. Pass 2 still
relies on sympy's automatic evaluation being cheap for certified constants; refused inputs are never
handed to sympy. A machine too loaded to finish is for the caller's safety cap to report (the symbolic
routes parse in a child process under theirs: a 503, never a refusal of the expression).
"""

from nonholonomic.expressions.grammar import (
    _Parser,
    check_expression,
    parse_expression,
    parse_matrix,
)
from nonholonomic.expressions.limits import (
    MAX_CONSTANT_MAGNITUDE,
    MAX_DECIMAL_PLACES,
    MAX_EXPONENT,
    MAX_LITERAL,
    MAX_MATRIX_ENTRIES,
    MAX_NAME_LENGTH,
    MAX_NUMBER_BITS,
    MAX_RESULT_EXPONENT,
)
from nonholonomic.expressions.names import (
    ALLOWED_CONSTANTS,
    ALLOWED_FUNCTIONS,
    FUNCTION_ARITY,
    RESERVED_NAMES,
    ExpressionError,
    _name_problem,
    declare_symbols,
)
from nonholonomic.expressions.smoothness import differentiable, integrable

__all__ = [
    "ALLOWED_CONSTANTS",
    "ALLOWED_FUNCTIONS",
    "FUNCTION_ARITY",
    "MAX_CONSTANT_MAGNITUDE",
    "MAX_DECIMAL_PLACES",
    "MAX_EXPONENT",
    "MAX_LITERAL",
    "MAX_MATRIX_ENTRIES",
    "MAX_NAME_LENGTH",
    "MAX_NUMBER_BITS",
    "MAX_RESULT_EXPONENT",
    "RESERVED_NAMES",
    "ExpressionError",
    "_Parser",
    "_name_problem",
    "check_expression",
    "declare_symbols",
    "differentiable",
    "integrable",
    "parse_expression",
    "parse_matrix",
]
