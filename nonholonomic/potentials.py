"""Potentials U of the external field, as symbolic building blocks.

A potential acts on named state vectors (``gamma``, ``E``, ``x``) and may use the inertia tensor
(Brun's field). Each system module lists the potentials it accepts in its ``POTENTIALS`` dict,
built with the factories below, so the same request name (``linear``) can mean (a, γ) for a body
and (a, x) for a ball on a surface.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import lru_cache

import sympy as sp

from nonholonomic.definition import Parameter, dot, symmetric_matrix_symbols, upper_triangle, vector_symbols
from nonholonomic.expressions import ExpressionError, declare_symbols, differentiable, integrable, parse_expression

Variables = Mapping[str, sp.Matrix]
"""State vectors by name, plus ``"I"``: the inertia tensor, where the system has one."""


@dataclass(frozen=True)
class Potential:
    """A kind of potential: its request name, formula, parameters and symbolic form."""

    kind: str
    formula: str
    parameters: tuple[Parameter, ...]
    build: Callable[[Variables], sp.Expr]
    """``build(variables)`` → U as a sympy expression."""
    scale: Callable[[Variables], sp.Expr]
    """``scale(variables)`` → the size of U's variation (e.g. |a||γ|), used to judge energy drift
    when U itself happens to vanish at the initial state."""

    def memo_key(self) -> tuple[str, str, tuple[Parameter, ...]]:
        """What identifies this potential for :mod:`nonholonomic.memo` (its closures do not pickle):
        its kind, its formula (a user's text) and its parameters."""
        return self.kind, self.formula, self.parameters


def _vector(name: str, meaning: str, unit: str) -> tuple[sp.Matrix, Parameter]:
    v = vector_symbols(name)
    return v, Parameter(name, tuple(v), meaning, unit)


ZERO = Potential(kind="zero", formula="U = 0", parameters=(), build=lambda v: sp.Integer(0),
                 scale=lambda v: sp.Integer(0))


def linear(on: str = "gamma", also_on: str | None = None, unit: str = "kg m^2/s^2") -> Potential:
    """``U = (a, v)`` on the vector ``on`` (plus ``(b, w)`` on ``also_on``); ``unit`` is a's (and b's)
    unit: energy for a unit vector, force (kg m/s^2) for a position."""
    a, par_a = _vector("a", f"field vector of the linear potential (a, {on})", unit)
    parameters: tuple[Parameter, ...] = (par_a,)
    formula = f"U = (a, {on})"
    if also_on is not None:
        b, par_b = _vector("b", f"field vector of the term (b, {also_on})", unit)
        parameters += (par_b,)
        formula += f" + (b, {also_on})"

        def build(v: Variables) -> sp.Expr:
            return dot(a, v[on]) + dot(b, v[also_on])

        def scale(v: Variables) -> sp.Expr:
            return sp.sqrt(dot(a, a) * dot(v[on], v[on])) + sp.sqrt(dot(b, b) * dot(v[also_on], v[also_on]))
    else:
        def build(v: Variables) -> sp.Expr:
            return dot(a, v[on])

        def scale(v: Variables) -> sp.Expr:
            return sp.sqrt(dot(a, a) * dot(v[on], v[on]))

    return Potential("linear", formula, parameters, build, scale)


def brun(on: str = "gamma") -> Potential:
    """Brun's field ``U = k/2 (v, I v)`` (needs the inertia tensor ``I``)."""
    k = sp.Symbol("k", real=True)
    return Potential(
        "brun", f"U = k/2 ({on}, I {on})",
        (Parameter("k", (k,), f"strength of Brun's field k/2 ({on}, I {on})", "1/s^2"),),
        build=lambda v: k / 2 * dot(v[on], v["I"] * v[on]),
        scale=lambda v: sp.Abs(k) / 2 * dot(v[on], v["I"] * v[on]),
    )


def quadratic(on: str = "gamma") -> Potential:
    """``U = ½ (v, K v)`` with a symmetric matrix K."""
    K = symmetric_matrix_symbols("K")
    return Potential(
        "quadratic", f"U = 1/2 ({on}, K {on})",
        (Parameter("K", upper_triangle(K), f"symmetric matrix of the quadratic potential 1/2 ({on}, K {on})",
                   "kg m^2/s^2", shape="symmetric_matrix"),),
        build=lambda v: dot(v[on], K * v[on]) / 2,
        scale=lambda v: sp.sqrt(sum(e**2 for e in K)) * dot(v[on], v[on]) / 2,
    )


def harmonic(on: str = "x") -> Potential:
    """``U = k/2 (v, v)``: an isotropic spring to the origin."""
    k = sp.Symbol("k", real=True)
    return Potential(
        "harmonic", f"U = k/2 ({on}, {on})",
        (Parameter("k", (k,), f"stiffness of the isotropic potential k/2 ({on}, {on})", "kg/s^2"),),
        build=lambda v: k / 2 * dot(v[on], v[on]),
        scale=lambda v: sp.Abs(k) / 2 * dot(v[on], v[on]),
    )


#: The request name of a potential the user writes as an expression.
EXPRESSION = "expression"
#: Longest expression of a potential (characters), as for the symbolic requests.
MAX_EXPRESSION_LENGTH = 2000
#: Most parameters an expression potential may declare.
MAX_EXPRESSION_PARAMETERS = 20


def potential_symbols(variables: tuple[str, ...]) -> list[str]:
    """The names an expression potential may use for the state vectors ``variables``: their components
    ``gamma1, gamma2, gamma3`` ..."""
    return [f"{v}{i}" for v in variables for i in (1, 2, 3)]


@lru_cache(maxsize=128)
def expression(text: str, parameters: tuple[str, ...], variables: tuple[str, ...]) -> Potential:
    """A potential the user writes: ``U`` as text in the components of the state vectors
    ``variables`` (e.g. ``gamma1 .. gamma3``) and the scalar ``parameters`` (their values come with
    the request), parsed by :func:`nonholonomic.expressions.parse_expression` (never ``eval``).

    Cached by its text, parameter names and variables (at most 128), so that the same expression
    gives the same :class:`Potential`, the same system and the same compiled integrator.

    Raises
    ------
    ExpressionError
        The text is not an expression of those names (the reason and the character), or a parameter
        name is not admissible or takes a state component's name.
    """
    if len(parameters) > MAX_EXPRESSION_PARAMETERS:
        raise ExpressionError(f"at most {MAX_EXPRESSION_PARAMETERS} parameters")
    components = potential_symbols(variables)
    for name in parameters:
        if name in components:
            raise ExpressionError(f"parameter name {name!r} is a state component's name")
    symbols = declare_symbols([*components, *parameters])
    U = smooth_potential(parse_expression(text, symbols, max_length=MAX_EXPRESSION_LENGTH))
    by_vector = {v: [symbols[f"{v}{i}"] for i in (1, 2, 3)] for v in variables}

    def build(v: Variables) -> sp.Expr:
        return U.xreplace({s: v[name][i] for name, syms in by_vector.items() for i, s in enumerate(syms)})

    return Potential(
        EXPRESSION, f"U = {text}",
        tuple(Parameter(name, (symbols[name],), "parameter of the potential U", "as U needs") for name in parameters),
        build=build,
        scale=lambda v: sp.Abs(build(v)),
    )


def smooth_potential(U: sp.Expr, why: str = "the equations need U's gradient") -> sp.Expr:
    """``U`` as the integrator takes it: twice differentiable (no ``abs``, ``sign``), rational exponents,
    ``cot``, ``sec``, ``csc`` written with ``sin`` and ``cos`` (:mod:`nonholonomic.expressions.smoothness`).

    Raises
    ------
    ExpressionError
        For ``abs`` or ``sign`` (not differentiable: the field needs ∂U), and for a power whose
        exponent is not a rational number (``x**pi``, ``x**q``).
    """
    return integrable(differentiable(U, why))


def resolve(potentials: Mapping[str, Potential], potential: str | Potential) -> Potential:
    """A system's potential: a name of its ``POTENTIALS``, or one built by :func:`expression`."""
    return potential if isinstance(potential, Potential) else potentials[potential]


def catalog_of(*potentials: Potential) -> dict[str, Potential]:
    """A system's ``POTENTIALS`` dict from the potentials it accepts."""
    return {p.kind: p for p in potentials}
