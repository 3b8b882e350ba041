"""Numeric (numpy) kernels generated from a :class:`~nonholonomic.definition.MechanicalSystem`.

Every function takes states as an array of shape ``(n, dim)`` (rows are phase points, columns the
flattened state symbols) and the parameter vector in the order of ``system.parameter_symbols``.
Kernels are compiled once per system and process (``lru_cache``), and remembered across processes
when a memo is installed (:mod:`nonholonomic.memo`: lambdify's common subexpression elimination is
most of a worker's warm-up).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import cached_property, lru_cache
from typing import TypeVar

import numpy as np
import sympy as sp

from nonholonomic import memo
from nonholonomic.definition import MechanicalSystem
from nonholonomic.expressions.smoothness import kink_arguments
from nonholonomic.numerics.numpy_function import lambdify_numpy

VectorKernel = Callable[[np.ndarray, np.ndarray], np.ndarray]
T = TypeVar("T")


class Kernel:
    """``f(X, p) -> (n, k)``: ``k`` expressions at ``n`` phase points (picklable when its function is)."""

    __slots__ = ("fn",)

    def __init__(self, fn: Callable[..., list[object]]) -> None:
        self.fn = fn

    def __call__(self, X: np.ndarray, p: np.ndarray) -> np.ndarray:
        X = np.atleast_2d(np.asarray(X, dtype=float))
        n = X.shape[0]
        out = self.fn(*X.T, *np.asarray(p, dtype=float))
        return np.stack([np.broadcast_to(np.asarray(o, dtype=float), (n,)) for o in out], axis=1)


def vectorize(exprs: Sequence[sp.Expr], args: Sequence[sp.Symbol]) -> VectorKernel:
    """Compile ``exprs`` into ``f(X, p) -> (n, len(exprs))`` with ``X`` of shape ``(n, len(state))``.

    ``args`` are the state symbols followed by the parameter symbols.
    """
    return Kernel(lambdify_numpy(args, exprs))


class NumericSystem:
    """The numpy kernels of one system, each compiled on first use (the API only ever needs
    ``constraints``; a worker needs them all)."""

    def __init__(self, system: MechanicalSystem) -> None:
        self.system = system
        self._args = system.state_symbols + system.parameter_symbols

    @cached_property
    def _definition_key(self) -> str | None:
        """The memo's key of the system's definition (pickled once per process)."""
        return memo.key_of("definition-of", self.system) if memo.installed() else None

    def _kernel(self, name: str, compile_kernel: Callable[[], T]) -> T:
        """``compile_kernel()``, remembered across processes as the kernel ``name`` of this definition."""
        if self._definition_key is None:
            return compile_kernel()
        return memo.remember("kernel", (self._definition_key, name), compile_kernel)

    @cached_property
    def rhs(self) -> VectorKernel:
        return self._kernel("rhs", lambda: vectorize(self.system.rhs, self._args))

    @cached_property
    def integrals(self) -> VectorKernel:
        exprs = [i.expression for i in self.system.integrals] or [sp.Integer(0)]
        return self._kernel("integrals", lambda: vectorize(exprs, self._args))

    @cached_property
    def integral_scales(self) -> VectorKernel:
        exprs = [i.scale for i in self.system.integrals] or [sp.Integer(1)]
        return self._kernel("integral_scales", lambda: vectorize(exprs, self._args))

    @cached_property
    def derived(self) -> dict[str, VectorKernel]:
        return self._kernel("derived", lambda: {d.name: vectorize(d.expression, self._args)
                                                for d in self.system.derived})

    @cached_property
    def density(self) -> VectorKernel:
        """``ρ`` of the invariant measure (1 where none is claimed)."""
        return self._kernel("density", lambda: vectorize([_claimed(self.system.measure.density)], self._args))

    @cached_property
    def time_density(self) -> VectorKernel:
        """``dτ/dt`` of the reduced time (only for systems that have one)."""
        reduced_time = self.system.reduced_time
        if reduced_time is None:
            raise AttributeError(f"{self.system.kind} has no reduced time")
        return self._kernel("time_density", lambda: vectorize([reduced_time.density], self._args))

    @cached_property
    def time_density_kinks(self) -> VectorKernel | None:
        """The arguments g at whose zeros ``dτ/dt`` may fail to be analytic (:func:`kink_arguments`), then their
        time derivatives (∇g, f), as columns; None if there are none."""
        system = self.system
        if system.reduced_time is None:
            raise AttributeError(f"{system.kind} has no reduced time")
        arguments = kink_arguments(system.reduced_time.density)
        rates = [sum(sp.diff(g, x) * f for x, f in zip(system.state_symbols, system.rhs)) for g in arguments]
        return self._kernel("time_density_kinks", lambda: vectorize([*arguments, *rates], self._args)) \
            if arguments else None

    @cached_property
    def constraint_scales(self) -> VectorKernel:
        exprs = [c.scale for c in self.system.constraints] or [sp.Integer(1)]
        return self._kernel("constraint_scales", lambda: vectorize(exprs, self._args))

    @cached_property
    def projections(self) -> list[VectorKernel | None]:
        """Per constraint: the kernel giving its projected vector, or None if it has no projection."""
        return self._kernel("projections", lambda: [
            vectorize(c.projection.expression, self._args) if c.projection else None
            for c in self.system.constraints])

    @cached_property
    def divergence_terms(self) -> VectorKernel:
        """Columns ``∂(ρ f_i)/∂x_i``: their sum is ``div(ρ f)``, their absolute sum its natural scale."""
        density = _claimed(self.system.measure.density)
        return self._kernel("divergence_terms", lambda: vectorize(divergence_terms(self.system, density), self._args))

    @cached_property
    def constraints(self) -> VectorKernel:
        exprs = [c.expression for c in self.system.constraints] or [sp.Integer(0)]
        return self._kernel("constraints", lambda: vectorize(exprs, self._args))

    def compile_all(self) -> None:
        """Compile every kernel now (a worker's warm-up)."""
        for name, attr in type(self).__dict__.items():
            if (isinstance(attr, cached_property) and not name.startswith("_")
                    and (name not in ("time_density", "time_density_kinks") or self.system.reduced_time)):
                getattr(self, name)

    def rhs_single(self, y: np.ndarray, p: np.ndarray) -> np.ndarray:
        """``f(y)`` for one phase point (shape ``(dim,)``)."""
        return self.rhs(y[None, :], p)[0]


def _claimed(density: sp.Expr | None) -> sp.Expr:
    return sp.Integer(1) if density is None else density


def divergence_terms(system: MechanicalSystem, density: sp.Expr) -> list[sp.Expr]:
    """``[∂(ρ f_i)/∂x_i for each state coordinate]``, by symbolic differentiation."""
    return [sp.diff(density * f, x) for f, x in zip(system.rhs, system.state_symbols)]


@lru_cache(maxsize=64)
def numeric(system: MechanicalSystem) -> NumericSystem:
    """The numpy kernels of ``system`` (one object per system and process)."""
    return NumericSystem(system)


def parameter_vector(system: MechanicalSystem, values: dict[str, object]) -> np.ndarray:
    """Flatten named parameter groups (``{"inertia": [..], "D": .., "B": [[..]]}``) in the system's order.

    Raises
    ------
    KeyError
        If a group is missing.
    ValueError
        If a group has the wrong shape or value (the message starts with the group's name).
    """
    out: list[float] = []
    for par in system.parameters:
        if par.name not in values:
            raise KeyError(par.name)
        try:
            out.extend(par.flatten(values[par.name]))
        except ValueError as exc:
            raise ValueError(f"{par.name}: {exc}") from None
    return np.asarray(out, dtype=float)


def state_vector(system: MechanicalSystem, values: dict[str, Sequence[float]], p: np.ndarray) -> np.ndarray:
    """Flatten named state vectors, converting alternative inputs (e.g. ``omega`` → ``M``).

    Raises
    ------
    KeyError
        If a state vector is given neither directly nor through an alternative.
    """
    names = {v.name for v in system.state}
    direct = {k: np.asarray(v, dtype=float) for k, v in values.items() if k in names}
    for alt in system.alternative_inputs:
        if alt.name in values and alt.replaces not in direct:
            # Every other state vector must be known to evaluate the conversion.
            known = {s: float(x) for vec in system.state if vec.name in direct
                     for s, x in zip(vec.symbols, direct[vec.name])}
            known.update({s: float(x) for s, x in zip(alt.symbols, values[alt.name])})
            known.update({s: float(x) for s, x in zip(system.parameter_symbols, p)})
            direct[alt.replaces] = np.array([float(e.subs(known)) for e in alt.expression])
    missing = [v.name for v in system.state if v.name not in direct]
    if missing:
        raise KeyError(", ".join(missing))
    return np.concatenate([direct[v.name] for v in system.state])
