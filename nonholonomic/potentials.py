"""Potentials U(γ) of an axisymmetric external field (paper, sections on Veselova and the ball).

Each potential is a symbolic expression in the unit vertical γ (and, for Brun's field, in the
inertia tensor I), with its own named parameters.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import sympy as sp

from nonholonomic.definition import Parameter, dot, vector_symbols


@dataclass(frozen=True)
class Potential:
    """A kind of potential: its request name, formula, parameters and symbolic form."""

    kind: str
    formula: str
    parameters: tuple[Parameter, ...]
    build: Callable[[sp.Matrix, sp.Matrix], sp.Expr]
    """``build(gamma, I)`` → U as a sympy expression."""
    scale: Callable[[sp.Matrix, sp.Matrix], sp.Expr]
    """``scale(gamma, I)`` → the size of U's variation (e.g. |a||γ|), used to judge energy drift
    when U itself happens to vanish at the initial state."""


_a = vector_symbols("a")
_k = sp.Symbol("k", real=True)

ZERO = Potential(kind="zero", formula="U = 0", parameters=(), build=lambda gamma, inertia: sp.Integer(0),
                 scale=lambda gamma, inertia: sp.Integer(0))

LINEAR = Potential(
    kind="linear",
    formula="U = (a, gamma)",
    parameters=(
        Parameter("a", tuple(_a), "field vector of the linear potential (a, γ) (e.g. m g r_c for a shifted centre)",
                  "kg m^2/s^2"),
    ),
    build=lambda gamma, inertia: dot(_a, gamma),
    scale=lambda gamma, inertia: sp.sqrt(dot(_a, _a) * dot(gamma, gamma)),
)

BRUN = Potential(
    kind="brun",
    formula="U = k/2 (gamma, I gamma)",
    parameters=(Parameter("k", (_k,), "strength of Brun's field k/2 (γ, Iγ)", "1/s^2"),),
    build=lambda gamma, inertia: _k / 2 * dot(gamma, inertia * gamma),
    scale=lambda gamma, inertia: sp.Abs(_k) / 2 * dot(gamma, inertia * gamma),
)

POTENTIALS: dict[str, Potential] = {p.kind: p for p in (ZERO, LINEAR, BRUN)}
