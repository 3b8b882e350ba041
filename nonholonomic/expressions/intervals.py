"""Interval enclosure of constant sub-expressions (pure float arithmetic: it cannot hang).

sympy's automatic evaluation asks assumption questions of constant expressions and answers them with
``evalf``, which may never return; the parser certifies every constant it builds with these outward
rounded float intervals first (real, finite, at most :data:`MAX_CONSTANT_MAGNITUDE`).
"""

from __future__ import annotations

import math
from fractions import Fraction

import sympy as sp

from nonholonomic.expressions.limits import MAX_CONSTANT_MAGNITUDE


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
