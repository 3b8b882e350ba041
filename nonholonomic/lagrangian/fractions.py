"""Exact rational-function arithmetic for the Lagrange–d'Alembert elimination: sin and cos of a coordinate
as two generators S, C with C² = 1 − S², everything else that is not a polynomial (a root, exp, sin(2x))
as a generator of its own.

Every entry is an element of sympy's fraction field over ℚ (``sympy.polys.fields``): a sum or product
cancels the gcd of numerator and denominator at once, in the sparse polynomial representation, which is
30–50 times faster than ``cancel`` on expression trees (the Suslov problem in Euler angles: 0.2 s against
6–10 s). After every operation numerator and denominator are reduced modulo C² + S² − 1 for each angle
(C² → 1 − S²: the relations have pairwise coprime leading monomials, so they are a Gröbner basis and the
reduced form of a polynomial is unique; a polynomial in sin and cos that vanishes identically reduces to 0).

Elimination (:func:`solve`) is Gaussian, a pivot chosen as the first entry of its column that is non-zero
both exactly and at the sample points (an exact zero is exact for polynomials in q, sin, cos; with other
generators, such as √(1 + y²), an identity among them is not seen, so the sample points decide).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import sympy as sp
from sympy.polys.domains import QQ
from sympy.polys.fields import FracElement, field

__all__ = ["MAX_FRACTION_TERMS", "Fractions", "TooLarge", "fractions_for"]

#: An entry counts as zero at a sample point below this times the matrix's largest entry there.
ZERO_TOLERANCE = 1e-12
#: Terms (numerator's and denominator's together) an entry of the exact elimination may reach; past it the
#: elimination gives way (:class:`TooLarge`) to the plain one. The classics stay far below (Suslov's problem
#: 248, the rolling disk 118); Chaplygin's sphere in Euler angles passes it (1,651 terms after 2.6 s, then an
#: entry of 6,554 terms that takes 20 s more): a deterministic measure of the work, not a clock.
MAX_FRACTION_TERMS = 1000


class TooLarge(RuntimeError):
    """An entry of the exact elimination outgrew :data:`MAX_FRACTION_TERMS` (gcds of large multivariate
    fractions would follow)."""


@dataclass
class Fractions:
    """The fraction field of one system: its generators, the trigonometric relations, the way back."""

    field: Any
    relations: list[Any]
    to_generators: dict[sp.Expr, sp.Symbol]
    back: dict[sp.Symbol, sp.Expr]
    points: list[dict[sp.Symbol, float]]

    def element(self, expr: sp.Expr) -> FracElement:
        """``expr`` as a reduced element of the field."""
        return self.reduce(self.field.from_expr(sp.sympify(expr).xreplace(self.to_generators)))

    def reduce(self, f: FracElement) -> FracElement:
        """Numerator and denominator reduced modulo C² + S² − 1, the gcd cancelled."""
        num, den = f.numer, f.denom
        size = len(num.terms()) + len(den.terms())
        if size > MAX_FRACTION_TERMS:
            raise TooLarge(f"an entry of the exact elimination has {size:,} terms > max {MAX_FRACTION_TERMS:,} "
                           "(MAX_FRACTION_TERMS)")
        for relation in self.relations:
            num, den = num.rem(relation), den.rem(relation)
        return self.field.new(num, den)

    def expr(self, f: FracElement) -> sp.Expr:
        """``f`` as a sympy expression in the user's symbols."""
        return f.as_expr().xreplace(self.back)

    def vanishes_at_points(self, f: FracElement) -> bool:
        """Whether ``f`` is (numerically) zero at every sample point, relative to its numerator's terms."""
        if not f:
            return True
        expr = f.numer.as_expr().xreplace(self.back)
        terms = sp.Add.make_args(sp.expand(expr)) if sp.count_ops(expr) < 2000 else (expr,)
        for point in self.points:
            try:
                value = complex(sp.sympify(expr.xreplace(point)).evalf())
                scale = sum(abs(complex(sp.sympify(t.xreplace(point)).evalf())) for t in terms)
            except (TypeError, ValueError, ZeroDivisionError):
                return False
            if not np.isfinite(value) or abs(value) > ZERO_TOLERANCE * max(scale, 1e-300):
                return False
        return True

    def solve(self, M: list[list[FracElement]], B: list[list[FracElement]]) -> list[list[FracElement]]:
        """``M⁻¹ B`` (rows of B: one per row of M) by Gaussian elimination with row exchanges."""
        m = len(M)
        M, B = [row[:] for row in M], [row[:] for row in B]
        for c in range(m):
            pivot = next((r for r in range(c, m) if M[r][c] and not self.vanishes_at_points(M[r][c])), None)
            if pivot is None:
                raise ZeroDivisionError(f"the matrix is singular (column {c + 1})")
            M[c], M[pivot], B[c], B[pivot] = M[pivot], M[c], B[pivot], B[c]
            for r in range(c + 1, m):
                if not M[r][c]:
                    continue
                factor = self.reduce(M[r][c] / M[c][c])
                M[r] = [self.reduce(M[r][j] - factor * M[c][j]) for j in range(m)]
                B[r] = [self.reduce(B[r][j] - factor * B[c][j]) for j in range(len(B[r]))]
        X: list[list[FracElement]] = [[] for _ in range(m)]
        for r in reversed(range(m)):
            row = B[r][:]
            for j in range(r + 1, m):
                if M[r][j]:
                    row = [self.reduce(row[t] - M[r][j] * X[j][t]) for t in range(len(row))]
            X[r] = [self.reduce(x / M[r][r]) for x in row]
        return X


def _generators(exprs: Sequence[sp.Expr], variables: Sequence[sp.Symbol]) -> tuple[dict, dict, list, list]:
    """Substitutions to generators, back, the generators (C's, S's, then the rest), the angles."""
    angles = sorted({f.args[0] for e in exprs for f in e.atoms(sp.sin, sp.cos) if f.args[0] in variables},
                    key=sp.default_sort_key)
    to: dict[sp.Expr, sp.Symbol] = {}
    back: dict[sp.Symbol, sp.Expr] = {}
    cosines, sines = [], []
    for i, a in enumerate(angles):
        s, c = sp.Dummy(f"S{i}"), sp.Dummy(f"C{i}")
        to[sp.sin(a)], to[sp.cos(a)] = s, c
        back[s], back[c] = sp.sin(a), sp.cos(a)
        cosines.append(c)
        sines.append(s)
    others: list[sp.Symbol] = []
    atoms: set[sp.Expr] = set()
    for e in exprs:  # functions and non-integer powers left: a generator each
        e = e.xreplace(to)
        atoms |= {f for f in e.atoms(sp.Function)}
        atoms |= {p for p in e.atoms(sp.Pow) if not p.exp.is_Integer}
    for i, atom in enumerate(sorted(atoms, key=sp.default_sort_key)):
        g = sp.Dummy(f"G{i}")
        to[atom], back[g] = g, atom
        others.append(g)
    return to, back, [*cosines, *sines, *others], angles


def fractions_for(exprs: Sequence[sp.Expr], variables: Sequence[sp.Symbol], symbols: Sequence[sp.Symbol],
                  points: list[dict[sp.Symbol, float]]) -> Fractions:
    """The fraction field in which ``exprs`` live.

    Parameters
    ----------
    exprs : the expressions that will be converted (their sin, cos and other functions become generators).
    variables : the coordinates (an argument of sin or cos that is one of them is an angle).
    symbols : every other symbol (velocities, parameters, t).
    points : sample points (symbol → float) for the numeric zero test of pivots.
    """
    to, back, gens, angles = _generators(exprs, variables)
    nested = [a for a in to if any(g in back for g in a.free_symbols)]
    if nested:  # a function of a generator (sin(sqrt(x))): left to sympy, not a generator of generators
        to = {k: v for k, v in to.items() if k not in nested}
    K = field([*gens, *variables, *symbols], QQ)[0]
    index = {g: i for i, g in enumerate(K.symbols)}
    relations = []
    for i, _ in enumerate(angles):
        c, s = K.gens[index[gens[i]]], K.gens[index[gens[len(angles) + i]]]
        relations.append((c ** 2 + s ** 2 - 1).numer)
    exact_points = [{s: sp.Float(x) for s, x in point.items()} for point in points]
    return Fractions(K, relations, to, back, exact_points)
