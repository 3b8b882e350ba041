"""The symbolic definition of a mechanical system: the one place each system is written down.

A system module (e.g. :mod:`nonholonomic.systems.chaplygin_ball`) builds one
:class:`MechanicalSystem` per potential from sympy expressions. Everything numeric (the heyoka
integrator, the integrals along a trajectory, the measure checks) is derived from it by
:mod:`nonholonomic.kernels`; nothing is written twice.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import sympy as sp


def vector_symbols(name: str) -> sp.Matrix:
    """Three real symbols ``name1, name2, name3`` as a column vector."""
    return sp.Matrix(sp.symbols(f"{name}1:4", real=True))


def cross(a: sp.Matrix, b: sp.Matrix) -> sp.Matrix:
    """Vector product ``a × b`` of two 3-vectors."""
    return a.cross(b)


def dot(a: sp.Matrix, b: sp.Matrix) -> sp.Expr:
    """Scalar product ``(a, b)`` of two 3-vectors."""
    return a.dot(b)


def gradient(expr: sp.Expr, v: sp.Matrix) -> sp.Matrix:
    """``∂expr/∂v`` for a 3-vector of symbols ``v``."""
    return sp.Matrix([sp.diff(expr, vi) for vi in v])


@dataclass(frozen=True)
class Parameter:
    """A named group of parameters, as a request spells it (``inertia``, ``D``, ``a`` ...).

    Parameters
    ----------
    name : request name of the group.
    symbols : the sympy symbols, in order (one for a scalar, three for a vector).
    meaning : what it is, in the paper's words.
    unit : unit in the SI-consistent convention of the catalog.
    minimum : lower bound; ``None`` for any finite number.
    strict : whether the bound excludes the minimum itself (``> minimum``).
    """

    name: str
    symbols: tuple[sp.Symbol, ...]
    meaning: str
    unit: str
    minimum: float | None = None
    strict: bool = False

    @property
    def admissible(self) -> str:
        """Human-readable admissible range, e.g. ``"> 0"``."""
        if self.minimum is None:
            return "any finite number"
        return f"{'>' if self.strict else '>='} {self.minimum:g}"

    @property
    def is_vector(self) -> bool:
        return len(self.symbols) > 1


@dataclass(frozen=True)
class StateVector:
    """A 3-vector of the phase space (``M``, ``gamma`` ...)."""

    name: str
    symbols: tuple[sp.Symbol, ...]
    meaning: str
    unit: str


@dataclass(frozen=True)
class DerivedVector:
    """A vector computed from the state (``omega = I_Q⁻¹ M``), reported beside it."""

    name: str
    expression: tuple[sp.Expr, ...]
    formula: str
    meaning: str
    unit: str


@dataclass(frozen=True)
class AlternativeInput:
    """An initial-state vector a request may give instead of a state vector.

    ``replaces`` is the state vector's name; ``expression`` gives that vector in terms of
    ``symbols`` (the alternative's components) and the other state variables. Example: the
    ball's ``omega`` replaces ``M`` through ``M = I_Q omega``.
    """

    name: str
    replaces: str
    symbols: tuple[sp.Symbol, ...]
    expression: tuple[sp.Expr, ...]
    formula: str


@dataclass(frozen=True)
class FirstIntegral:
    """A quantity claimed constant along every trajectory.

    ``scale`` is a non-negative expression of the same size as the integral used to normalise its
    drift when the integral itself is near zero (e.g. ``|M||γ|`` for ``c = (M, γ)``).
    """

    name: str
    expression: sp.Expr
    scale: sp.Expr
    formula: str
    equation: str


@dataclass(frozen=True)
class StateConstraint:
    """A relation the initial state must satisfy: ``expression == value`` within ``tolerance``."""

    field: str
    expression: sp.Expr
    value: float
    formula: str
    equation: str
    tolerance: float = 1e-9


@dataclass(frozen=True)
class InvariantMeasure:
    """A claimed invariant measure ``density · d(state)``: ``div(density · f) = 0``."""

    density: sp.Expr
    formula: str
    equation: str


@dataclass(frozen=True)
class ReducedTime:
    """The time substitution ``dτ = density · dt`` of the paper's Hamiltonization."""

    density: sp.Expr
    formula: str
    equation: str
    unit: str


@dataclass(frozen=True)
class MechanicalSystem:
    """One system with one potential, defined symbolically.

    ``rhs`` lists ``d/dt`` of every state symbol in the order of ``state`` (flattened), with all
    constraint multipliers already eliminated.
    """

    kind: str
    potential: str
    title: str
    equation: str
    parameters: tuple[Parameter, ...]
    state: tuple[StateVector, ...]
    rhs: tuple[sp.Expr, ...]
    integrals: tuple[FirstIntegral, ...]
    measure: InvariantMeasure
    reduced_time: ReducedTime
    potential_formula: str
    derived: tuple[DerivedVector, ...] = ()
    alternative_inputs: tuple[AlternativeInput, ...] = ()
    constraints: tuple[StateConstraint, ...] = ()
    notes: tuple[str, ...] = field(default=())

    @property
    def state_symbols(self) -> tuple[sp.Symbol, ...]:
        """All state symbols, flattened in the order of ``state``."""
        return tuple(s for v in self.state for s in v.symbols)

    @property
    def parameter_symbols(self) -> tuple[sp.Symbol, ...]:
        """All parameter symbols, flattened in the order of ``parameters``."""
        return tuple(s for p in self.parameters for s in p.symbols)

    @property
    def dimension(self) -> int:
        return len(self.state_symbols)

    def __post_init__(self) -> None:
        if len(self.rhs) != self.dimension:
            raise ValueError(f"{self.kind}: rhs has {len(self.rhs)} entries for {self.dimension} states")
