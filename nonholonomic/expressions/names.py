"""Names of the safe parser: allowed functions and constants, declared variables, the error type."""

from __future__ import annotations

import keyword
from collections.abc import Callable, Mapping, Sequence
from types import MappingProxyType

import sympy as sp

from nonholonomic.expressions.limits import MAX_NAME_LENGTH

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
