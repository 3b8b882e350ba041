"""The symbolic definition of a mechanical system: the one place each system is written down.

A system module (e.g. :mod:`nonholonomic.systems.chaplygin_ball`) builds one
:class:`MechanicalSystem` per potential from sympy expressions. Everything numeric (the heyoka
integrator, the integrals along a trajectory, the measure checks) is derived from it by
:mod:`nonholonomic.numerics.kernels`; nothing is written twice.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

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


def symmetric_matrix_symbols(name: str) -> sp.Matrix:
    """A symmetric 3×3 matrix of six real symbols ``name11, name12, name13, name22, name23, name33``."""
    sym = {(i, j): sp.Symbol(f"{name}{i + 1}{j + 1}", real=True) for i in range(3) for j in range(i, 3)}
    return sp.Matrix(3, 3, lambda i, j: sym[(min(i, j), max(i, j))])


def upper_triangle(matrix: sp.Matrix) -> tuple[sp.Symbol, ...]:
    """The six independent entries of a symmetric matrix, in the order 11, 12, 13, 22, 23, 33."""
    return tuple(matrix[i, j] for i in range(3) for j in range(i, 3))


#: Admissible magnitudes of a parameter's components: beyond them the equations' products and powers
#: overflow or lose every digit in double precision (e.g. D = 1e308, or inertia 1e-308 beside 1e308).
MAX_PARAMETER_MAGNITUDE = 1e12
#: The smallest admissible value of a strictly positive parameter (``> 0``).
MIN_POSITIVE_PARAMETER = 1e-12


@dataclass(frozen=True)
class Parameter:
    """A named group of parameters, as a request spells it (``inertia``, ``D``, ``a``, ``B`` ...).

    Parameters
    ----------
    name : request name of the group.
    symbols : the sympy symbols, in order (one for a scalar, three for a vector, the six entries
        11, 12, 13, 22, 23, 33 for a symmetric matrix).
    meaning : what it is, in the paper's words.
    unit : unit in the SI-consistent convention of the catalog.
    minimum : lower bound (of every component); ``None`` for any finite number.
    strict : whether the bound excludes the minimum itself (``> minimum``).
    shape : ``"scalar"``, ``"vector"`` or ``"symmetric_matrix"`` (given as 3 numbers for a diagonal
        matrix or as a 3×3 nested list).
    positive_definite : for a symmetric matrix, whether it must be positive definite.
    transform : for a symmetric matrix, a map applied to the request's (checked) matrix before its
        entries become the symbols' values, when the equations are simpler in another matrix: the
        quadric's ``B`` is requested, its inverse ``B⁻¹`` is what the equations use.
    transform_formula : what ``transform`` computes, for the catalog (e.g. ``"B^-1"``).
    """

    name: str
    symbols: tuple[sp.Symbol, ...]
    meaning: str
    unit: str
    minimum: float | None = None
    strict: bool = False
    shape: str = ""
    positive_definite: bool = False
    transform: Callable[[Any], Any] | None = None
    transform_formula: str = ""

    def __post_init__(self) -> None:
        if not self.shape:
            object.__setattr__(self, "shape", "scalar" if len(self.symbols) == 1 else "vector")

    @property
    def admissible(self) -> str:
        """Human-readable admissible range, e.g. ``"> 0"``."""
        parts = []
        if self.shape == "symmetric_matrix":
            parts.append("symmetric 3x3 matrix, or 3 numbers for a diagonal one")
            if self.positive_definite:
                parts.append("positive definite")
        top = f"{MAX_PARAMETER_MAGNITUDE:g}"
        if self.minimum is None:
            parts.append(f"-{top} .. {top}")
        elif self.strict and self.minimum == 0:
            parts.append(f"> 0: {MIN_POSITIVE_PARAMETER:g} .. {top}")
        else:
            parts.append(f"{'>' if self.strict else '>='} {self.minimum:g}, at most {top}")
        return "; ".join(parts)

    @property
    def is_vector(self) -> bool:
        return self.shape == "vector"

    def flatten(self, value: object) -> list[float]:
        """The parameter's symbol values from a request value.

        Raises
        ------
        ValueError
            With the reason, if the value has the wrong shape, is not symmetric or not positive
            definite, or breaks the bound.
        """
        import numpy as np  # local: definitions stay importable without numpy's cost in mind

        array = np.asarray(value, dtype=float)
        if self.shape == "symmetric_matrix":
            if array.shape == (3,):
                array = np.diag(array)
            if array.shape != (3, 3):
                raise ValueError("needs 3 numbers (a diagonal matrix) or a 3x3 matrix")
            if not np.allclose(array, array.T, rtol=1e-12, atol=1e-12 * float(np.max(np.abs(array), initial=0))):
                raise ValueError("matrix is not symmetric")
            if self.positive_definite and not np.all(np.linalg.eigvalsh(array) > 0):
                raise ValueError(f"matrix is not positive definite (eigenvalues {np.linalg.eigvalsh(array).tolist()})")
            if self.transform is not None:
                array = np.asarray(self.transform(array), dtype=float)
                array = (array + array.T) / 2
            values = [float(array[i, j]) for i in range(3) for j in range(i, 3)]
        else:
            values = np.atleast_1d(array).tolist()
            if len(values) != len(self.symbols):
                raise ValueError(f"needs {len(self.symbols)} component(s), got {len(values)}")
        if not all(np.isfinite(values)):
            raise ValueError("non-finite number")
        large = [v for v in np.atleast_1d(array).ravel().tolist() if abs(v) > MAX_PARAMETER_MAGNITUDE]
        if large:
            raise ValueError(f"must be {self.admissible}, got {large[0]:g}")
        if self.strict and self.minimum == 0 and self.shape != "symmetric_matrix":
            tiny = [v for v in values if 0 < v < MIN_POSITIVE_PARAMETER]
            if tiny:
                raise ValueError(f"must be {self.admissible}, got {tiny[0]:g}")
        if self.minimum is not None and self.shape != "symmetric_matrix":
            bad = [v for v in values if (v <= self.minimum if self.strict else v < self.minimum)]
            if bad:
                raise ValueError(f"must be {self.admissible}, got {bad[0]:g}")
        return values


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
class Projection:
    """How to move a state onto a constraint: replace the vector ``vector`` by ``expression``.

    ``steps`` > 1 makes it an iteration (Newton's steps onto a curved surface): it is applied again
    until the constraint holds, at most ``steps`` times.
    """

    vector: str
    expression: tuple[sp.Expr, ...]
    formula: str
    steps: int = 1


@dataclass(frozen=True)
class StateConstraint:
    """A relation the initial state must satisfy: ``|expression − value| ≤ tolerance · max(1, scale)``.

    ``projection`` (optional) moves a state onto the relation; constraints are projected in the
    order the system lists them.
    """

    field: str
    expression: sp.Expr
    value: float
    formula: str
    equation: str
    tolerance: float = 1e-9
    scale: sp.Expr = sp.Integer(1)
    projection: Projection | None = None


@dataclass(frozen=True)
class InvariantMeasure:
    """A claimed invariant measure ``density · d(state)``: ``div(density · f) = 0``.

    ``density`` None: no measure is claimed (a user's generalized Chaplygin system for which Theorem 1
    finds none); ``formula`` says why.

    ``on_manifold``: the claim holds on an invariant manifold of the state only (a Lagrangian system's
    constraint manifold A(q) q̇ = 0), given as substitutions ``symbol → expression`` that solve its
    equations; ``div(density · f)`` vanishes identically after them (and pointwise at states on it).

    ``verified``: how the density was established when no symbolic proof is tried (a system without a closed
    form of its field: a randomized identity test at high precision,
    :mod:`nonholonomic.lagrangian.sampled_search`); the symbolic check then reports it instead of a proof.
    """

    density: sp.Expr | None
    formula: str
    equation: str
    on_manifold: tuple[tuple[sp.Symbol, sp.Expr], ...] = ()
    verified: str | None = None


@dataclass(frozen=True)
class ReducedTime:
    """The time substitution ``dτ = density · dt`` of the paper's Hamiltonization.

    ``regular``: the density is analytic and positive wherever the state is admissible (the paper's kinds:
    their parameters' bounds make it so), and τ' = N is integrated beside the state. Otherwise (a reducing
    multiplier Theorem 1 found for a user's system, such as √(1 − sin θ)·√(1 + sin θ) = |cos θ|) τ is
    integrated by quadrature along the dense output, where N's zeros, sign changes and kinks are located
    (:mod:`nonholonomic.numerics.reduced_time`).
    """

    density: sp.Expr
    formula: str
    equation: str
    unit: str
    regular: bool = True


@dataclass(frozen=True)
class MechanicalSystem:
    """One system with one potential, defined symbolically.

    ``rhs`` lists ``d/dt`` of every state symbol in the order of ``state`` (flattened), with all
    constraint multipliers already eliminated. ``reduced_time`` is None for systems the paper
    gives no time substitution for.
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
    reduced_time: ReducedTime | None
    potential_formula: str
    derived: tuple[DerivedVector, ...] = ()
    alternative_inputs: tuple[AlternativeInput, ...] = ()
    constraints: tuple[StateConstraint, ...] = ()
    notes: tuple[str, ...] = field(default=())
    hamiltonian_form: Any = field(default=None, compare=False)
    """A Hamiltonian form after a time substitution that comes with the definition (Theorem 1's for a
    user's generalized Chaplygin system), a :class:`nonholonomic.hamiltonization.forms.HamiltonianForm`."""
    structure: Any = field(default=None, compare=False)
    """What a structure search found for a user's system (a JSON-able mapping: the measure verdict, the
    integrals in an ansatz, the Hamiltonization), shown with the job's result; None for the paper's kinds."""

    @property
    def state_symbols(self) -> tuple[sp.Symbol, ...]:
        """All state symbols, flattened in the order of ``state``."""
        return tuple(s for v in self.state for s in v.symbols)

    @property
    def taylor_time_density(self) -> sp.Expr | None:
        """N when τ' = N is integrated beside the state by the Taylor integrator (a regular reduced time),
        else None (no reduced time, or τ by quadrature)."""
        reduced = self.reduced_time
        return reduced.density if reduced is not None and reduced.regular else None

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
