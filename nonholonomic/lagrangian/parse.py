"""A Lagrangian system written by the user: names and texts into sympy, and the refusals of what the
Lagrange–d'Alembert equations cannot take.

The input, as the API sends it::

    {"kind": "lagrangian", "coordinates": ["x", "y", "theta"],
     "L": "m/2*((x_dot - a*sin(theta)*theta_dot)**2 + (y_dot + a*cos(theta)*theta_dot)**2) + J/2*theta_dot**2",
     "constraints": ["-sin(theta)*x_dot + cos(theta)*y_dot"],
     "parameters": {"m": 1.3, "a": 0.4, "J": 0.25}}

The velocity of the coordinate ``q`` is written ``q_dot``; each constraint is an expression
``Σⱼ aⱼ(q, t) q̇ⱼ`` meaning ``= 0`` (linear and homogeneous in the velocities); the time ``t`` may appear
in L and in the constraints. Every text goes through the safe parser (:mod:`nonholonomic.expressions`,
never eval) with the limits of user potentials (:data:`~nonholonomic.potentials.MAX_EXPRESSION_LENGTH`,
:data:`~nonholonomic.potentials.MAX_EXPRESSION_PARAMETERS`).

What is refused here, with a :class:`DataError` naming the field (``coordinates``, ``L``,
``constraints``, ``constraints[i]`` (0-based), ``parameters``, ``parameters.<name>``): a reserved,
malformed or duplicate name; a text that is not an expression of the declared names; a constraint
that is not linear and homogeneous in the velocities; L not a polynomial of degree ≤ 2 in the
velocities; a parameter no expression uses; more constraints than coordinates − 1. The checks that
need numbers (the mass matrix, the rank of the constraints) are in :mod:`nonholonomic.lagrangian.checks`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import sympy as sp

from nonholonomic.expressions import ExpressionError, declare_symbols, parse_expression
from nonholonomic.potentials import MAX_EXPRESSION_LENGTH, MAX_EXPRESSION_PARAMETERS, smooth_potential
from nonholonomic.refusals import RefusedField
from nonholonomic.systems.generalized_chaplygin import velocity_degree

KIND = "lagrangian"
#: Suffix of a velocity's name: ``theta`` → ``theta_dot``.
VELOCITY_SUFFIX = "_dot"
#: Names a coordinate or parameter may not take (``t`` is the time, which L and constraints may use).
RESERVED = frozenset({"t", "tau", "N", "q", "q_dot", "qdot", "lam", "lambda_"})
#: Most coordinates (the symbolic elimination of the multipliers grows quickly with their number).
MAX_COORDINATES = 8
#: The fields of the input, in the order they are read.
FIELDS = ("kind", "coordinates", "L", "constraints", "parameters")


class DataError(RefusedField):
    """A field of the user's system that cannot be used (:class:`nonholonomic.refusals.RefusedField`).

    ``field`` is ``coordinates``, ``L``, ``constraints``, ``constraints[i]`` (0-based), ``parameters`` or
    ``parameters.<name>``.
    """


@dataclass(frozen=True)
class LagrangianData:
    """The user's system, parsed.

    Attributes
    ----------
    q, v : tuple of sympy.Symbol
        The coordinates q and their velocities q̇ (``<q>_dot``), real symbols.
    t : sympy.Symbol
        The time, which L and the constraints may use explicitly.
    L : sympy.Expr
        The Lagrangian L(q, q̇, t), a polynomial of degree ≤ 2 in q̇.
    constraints : tuple of sympy.Expr
        The constraint functions ``fᵢ = Σⱼ Aᵢⱼ(q, t) q̇ⱼ`` (each meaning fᵢ = 0).
    A : sympy.ImmutableMatrix
        The k × n matrix ``Aᵢⱼ = ∂fᵢ/∂q̇ⱼ``.
    parameters : tuple of sympy.Symbol
        The parameters, in the order given.
    values : tuple of float
        Their values (used for the checks at sample points; the equations stay symbolic in them).
    texts : tuple of (str, str)
        What the user wrote, by field (``L``, ``constraints[i]``).
    """

    q: tuple[sp.Symbol, ...]
    v: tuple[sp.Symbol, ...]
    t: sp.Symbol
    L: sp.Expr
    constraints: tuple[sp.Expr, ...]
    A: sp.ImmutableMatrix
    parameters: tuple[sp.Symbol, ...]
    values: tuple[float, ...]
    texts: tuple[tuple[str, str], ...]

    @property
    def parameter_values(self) -> dict[sp.Symbol, float]:
        """``{parameter symbol: value}``."""
        return dict(zip(self.parameters, self.values))

    def text(self, field: str) -> str:
        """What the user wrote for ``field`` (``L`` or ``constraints[i]``)."""
        return dict(self.texts)[field]


def velocity_name(coordinate: str) -> str:
    """``theta`` → ``theta_dot``."""
    return coordinate + VELOCITY_SUFFIX


def _names(field: str, names: object) -> tuple[str, ...]:
    what = "expressions" if field == "constraints" else "names"
    if isinstance(names, (str, bytes)) or not isinstance(names, Sequence):
        raise DataError(field, f"must be a list of {what}, got {type(names).__name__}")
    for i, name in enumerate(names):
        if not isinstance(name, str):
            raise DataError(f"{field}[{i}]", f"must be a string, got {type(name).__name__}")
    return tuple(names)


def declared(coordinates: tuple[str, ...], parameters: tuple[str, ...]) -> dict[str, sp.Symbol]:
    """The symbols of the coordinates, their velocities, the parameters and ``t``.

    Raises
    ------
    DataError
        Naming the field (``coordinates`` or ``parameters``) of a reserved, malformed or twice used name.
    """
    if not coordinates:
        raise DataError("coordinates", "give at least one coordinate")
    if len(coordinates) > MAX_COORDINATES:
        raise DataError("coordinates", f"at most {MAX_COORDINATES} coordinates")
    if len(parameters) > MAX_EXPRESSION_PARAMETERS:
        raise DataError("parameters", f"at most {MAX_EXPRESSION_PARAMETERS} parameters")
    velocities = {velocity_name(c) for c in coordinates}
    seen: set[str] = set()
    for field, names in (("coordinates", coordinates), ("parameters", parameters)):
        for name in names:
            if name in RESERVED:
                raise DataError(field, f"{name!r} is reserved here ({', '.join(sorted(RESERVED))}); choose another")
            if name.endswith(VELOCITY_SUFFIX) or name in velocities:
                raise DataError(field, f"{name!r} ends with {VELOCITY_SUFFIX!r}, which names the velocities; "
                                       "choose another")
            if name in seen:
                raise DataError(field, f"{name!r} is used twice among the coordinates and parameters")
            seen.add(name)
        try:
            declare_symbols([*names, *(velocity_name(c) for c in names if field == "coordinates")])
        except ExpressionError as exc:
            raise DataError(field, str(exc)) from None
    return declare_symbols(["t", *coordinates, *(velocity_name(c) for c in coordinates), *parameters])


def parse_text(field: str, text: object, symbols: Mapping[str, sp.Symbol]) -> sp.Expr:
    """``text`` of ``field`` parsed by the safe parser (never eval) and made smooth (twice differentiable,
    rational exponents).

    Raises
    ------
    DataError
        Naming ``field``, with the parser's reason and character.
    """
    if not isinstance(text, str):
        raise DataError(field, f"must be an expression as text, got {type(text).__name__}")
    try:
        return smooth_potential(parse_expression(text, symbols, max_length=MAX_EXPRESSION_LENGTH),
                                "the equations of motion differentiate it twice")
    except ExpressionError as exc:
        raise DataError(field, str(exc)) from None


def lagrangian_of(text: str, symbols: Mapping[str, sp.Symbol], v: tuple[sp.Symbol, ...]) -> sp.Expr:
    """L parsed; a polynomial of degree ≤ 2 in the velocities with a kinetic term."""
    L = parse_text("L", text, symbols)
    degree = velocity_degree(L, frozenset(v))
    if degree is None:
        raise DataError("L", "must be a polynomial of degree <= 2 in the velocities "
                             f"{', '.join(map(str, v))} (no velocity in a denominator, a root or a function)")
    if degree > 2:
        raise DataError("L", f"has degree {degree} in the velocities (as written); the Lagrange-d'Alembert "
                             "equations here need L at most quadratic in them")
    if degree < 2 or all(sp.diff(L, a, b) == 0 for a in v for b in v):
        raise DataError("L", "has no kinetic term: the mass matrix d2L/dq_dot2 is zero")
    return L


def constraint_of(field: str, text: str, symbols: Mapping[str, sp.Symbol],
                  v: tuple[sp.Symbol, ...]) -> tuple[sp.Expr, tuple[sp.Expr, ...], sp.Expr]:
    """A constraint parsed: ``(f, (a₁ .. aₙ), f₀)`` with f = Σ aⱼ q̇ⱼ + f₀, where aⱼ = ∂f/∂q̇ⱼ does not
    depend on the velocities and f₀ = f|_{q̇=0} (to be zero: checked at sample points, as f₀ may vanish
    only through an identity such as sin² + cos² = 1).

    Raises
    ------
    DataError
        Naming ``field``: not a polynomial in the velocities, of degree > 1 in them, or without them.
    """
    f = parse_text(field, text, symbols)
    vs = frozenset(v)
    degree = velocity_degree(f, vs)
    if degree is None:
        raise DataError(field, "must be linear and homogeneous in the velocities: a velocity appears in a "
                               "denominator, a root or a function")
    coefficients = tuple(sp.diff(f, vj) for vj in v)
    if degree > 1 and any(c.free_symbols & vs for c in coefficients):
        nonlinear = sorted({str(s) for c in coefficients for s in c.free_symbols & vs})
        raise DataError(field, f"must be linear and homogeneous in the velocities; it has degree {degree} in "
                               f"them (as written; products or powers of {', '.join(nonlinear)})")
    if all(c == 0 for c in coefficients):
        raise DataError(field, "has no velocity: a constraint is sum_j a_j(q) q_j_dot = 0 (a geometric "
                               "constraint g(q) = 0 is given by its derivative, or eliminated with a coordinate)")
    rest = f.xreplace({vj: 0 for vj in v})
    return sp.Add(*(c * vj for c, vj in zip(coefficients, v))) if rest != 0 else f, coefficients, rest


def _values(parameters: object) -> tuple[tuple[str, ...], tuple[float, ...]]:
    if not isinstance(parameters, Mapping):
        raise DataError("parameters", f"must be an object of name: number, got {type(parameters).__name__}")
    names, values = [], []
    for name, value in parameters.items():
        if not isinstance(name, str):
            raise DataError("parameters", "every name must be a string")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise DataError(f"parameters.{name}", f"must be a finite number, got {value!r}")
        names.append(name)
        values.append(float(value))
    return tuple(names), tuple(values)


@lru_cache(maxsize=128)
def lagrangian_data(coordinates: tuple[str, ...], L: str, constraints: tuple[str, ...] = (),
                    parameters: tuple[tuple[str, float], ...] = ()) -> LagrangianData:
    """The user's system parsed and checked (cached by its texts, names and values).

    Parameters
    ----------
    coordinates : tuple of str
        The generalized coordinates q; the velocities are ``<q>_dot``.
    L : str
        The Lagrangian L(q, q̇, t).
    constraints : tuple of str
        Each ``Σⱼ aⱼ(q, t) q̇ⱼ``, meaning ``= 0``.
    parameters : tuple of (str, float)
        The parameters' names and values.

    Returns
    -------
    LagrangianData

    Raises
    ------
    DataError
        Naming the field; see the module's docstring. The sample-point checks
        (:func:`nonholonomic.lagrangian.checks.check_sample_points`) are run too.
    """
    from nonholonomic.lagrangian.checks import check_sample_points

    names, values = _values(dict(parameters))
    if len(names) != len(parameters):
        raise DataError("parameters", "a parameter is given twice")
    coordinates = _names("coordinates", coordinates)
    constraints = _names("constraints", constraints) if constraints else ()
    symbols = declared(coordinates, names)
    q = tuple(symbols[c] for c in coordinates)
    v = tuple(symbols[velocity_name(c)] for c in coordinates)
    if len(constraints) > len(q) - 1:
        raise DataError("constraints", f"at most {len(q) - 1} (the number of coordinates - 1) constraints: "
                                       f"with {len(constraints)} for {len(q)} coordinates nothing can move")
    lagrangian = lagrangian_of(L, symbols, v)
    parsed = [constraint_of(f"constraints[{i}]", text, symbols, v) for i, text in enumerate(constraints)]
    used = lagrangian.free_symbols.union(*(f.free_symbols for f, _, _ in parsed))
    for name in names:
        if symbols[name] not in used:  # heyoka refuses a parameter value its system has no slot for
            raise DataError(f"parameters.{name}", "not used by L or the constraints: remove it, or use it")
    data = LagrangianData(
        q=q, v=v, t=symbols["t"], L=lagrangian, constraints=tuple(f for f, _, _ in parsed),
        A=sp.ImmutableMatrix(len(parsed), len(q), [a for _, row, _ in parsed for a in row]),
        parameters=tuple(symbols[name] for name in names), values=values,
        texts=(("L", L), *((f"constraints[{i}]", text) for i, text in enumerate(constraints))))
    check_sample_points(data, tuple(rest for _, _, rest in parsed))
    return data


def parse_system(spec: Mapping[str, Any]) -> LagrangianData:
    """The input as the API sends it (``kind``, ``coordinates``, ``L``, ``constraints``, ``parameters``),
    parsed and checked; see :func:`lagrangian_data`.

    Raises
    ------
    DataError
        Naming the field; an unknown field or a ``kind`` other than ``"lagrangian"`` too.
    """
    if not isinstance(spec, Mapping):
        raise DataError("system", f"must be an object, got {type(spec).__name__}")
    for key in spec:
        if key not in FIELDS:
            raise DataError(str(key), f"unknown field; a lagrangian system has {', '.join(FIELDS)}")
    if spec.get("kind", KIND) != KIND:
        raise DataError("kind", f"must be {KIND!r}")
    for key in ("coordinates", "L"):
        if key not in spec:
            raise DataError(key, "is required")
    coordinates = _names("coordinates", spec["coordinates"])
    if not isinstance(spec["L"], str):
        raise DataError("L", f"must be an expression as text, got {type(spec['L']).__name__}")
    constraints = _names("constraints", spec.get("constraints", ()))
    names, values = _values(spec.get("parameters", {}))
    return lagrangian_data(coordinates, spec["L"], constraints, tuple(zip(names, values)))
