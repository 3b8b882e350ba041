"""Poincaré sections, the surface: a user's expression ``S(state)``, its checks and its numeric kernels.

A surface is a user expression in the state components (``M1``, ``gamma3``, ``omega2`` ...,
parsed by the safe parser :func:`nonholonomic.expressions.parse_expression`, never ``eval``),
possibly using the system's parameters (``I1``, ``D`` ...). Derived components (the ball's
``omega = I_Q⁻¹ M``, paper eq. 2604-1) are substituted by their expressions in the state, so
every surface is a function of the integrated variables. A refused request field raises
:class:`SurfaceError`.

One heyoka compiled function (the Newton step onto the surface, the flow, ``S``, the derived
vectors, the first integrals and their scales, translated as the integrator's right-hand side is)
serves the post-processing of :mod:`.result`, all the points in one call;
the surface's scale is :func:`surface_scale_of`. Part of :mod:`.poincare` (the front door), where
every name is importable.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from functools import lru_cache

import heyoka as hy
import numpy as np
import sympy as sp

from nonholonomic.definition import MechanicalSystem
from nonholonomic.expressions import ExpressionError, integrable, parse_expression
from nonholonomic.numerics.taylor import TaylorSystem, taylor_system
from nonholonomic.refusals import RefusedField

_NOT_SMOOTH = re.compile(r"\b(abs|sign)\s*\(")


class SurfaceError(RefusedField):
    """A refused field of a section request (:class:`nonholonomic.refusals.RefusedField`): ``"surface"``,
    ``"value"``, ``"direction"``, ``"coordinates"``, ``"coordinates[i]"``, ``"max_points"``, ``"t_final"``,
    ``"tolerance"``, ``"initial_state"`` or ``"parameters"``; ``position`` points into the surface's text."""


# --------------------------------------------------------------------------------------------------
# Surfaces: names, parsing, numeric kernels
# --------------------------------------------------------------------------------------------------

@lru_cache(maxsize=64)
def _surface_names(system: MechanicalSystem) -> tuple[tuple[str, sp.Expr], ...]:
    names: dict[str, sp.Expr] = {str(s): s for s in system.state_symbols}
    for vec in system.derived:
        for i, expr in enumerate(vec.expression):
            names.setdefault(f"{vec.name}{i + 1}", expr)
    return tuple(names.items())


def surface_names(system: MechanicalSystem) -> dict[str, sp.Expr]:
    """Component name → its expression in the state, for every name a surface or a coordinate may use.

    The state components (``M1`` ... ``gamma3`` for the ball) map to their own symbols; the
    components of derived vectors map to their expressions (``omega1`` → the first row of
    ``I_Q⁻¹ M``, paper eq. 2604-1). Parameters are not components (a surface may still use them,
    see :func:`parse_surface`).
    """
    return dict(_surface_names(system))


def default_coordinates(system: MechanicalSystem) -> tuple[str, str]:
    """The two coordinates a section shows by default: ``gamma1, gamma2`` where the state has γ,
    else the first two components of the first state vector."""
    vec = next((v for v in system.state if v.name == "gamma"), system.state[0])
    return str(vec.symbols[0]), str(vec.symbols[1])


def _heyoka_ready(expr: sp.Expr) -> sp.Expr:
    """Rewrite what heyoka's ``from_sympy`` lacks: cot, sec, csc and Euler's number."""
    expr = expr.replace(sp.cot, lambda a: 1 / sp.tan(a)).replace(sp.sec, lambda a: 1 / sp.cos(a))
    expr = expr.replace(sp.csc, lambda a: 1 / sp.sin(a))
    return expr.xreplace({sp.E: sp.Float(sp.E.evalf(40), 40)})


@lru_cache(maxsize=256)
def _parse_surface(system: MechanicalSystem, text: str) -> sp.Expr:
    names = _surface_names(system)
    symbols: dict[str, sp.Symbol] = {}
    placeholders: dict[sp.Symbol, sp.Expr] = {}
    for name, expr in names:
        if isinstance(expr, sp.Symbol) and str(expr) == name:
            symbols[name] = expr
        else:
            placeholder = sp.Dummy(name, real=True)
            symbols[name] = placeholder
            placeholders[placeholder] = expr
    for par in system.parameter_symbols:
        symbols.setdefault(str(par), par)
    try:
        raw = parse_expression(text, symbols)
    except ExpressionError as err:
        reason = err.reason.replace("; declared: ", "; allowed names: ", 1)
        raise SurfaceError("surface", reason, err.position) from None
    expr = raw.xreplace(placeholders)
    components = ", ".join(name for name, _ in names)
    if not expr.free_symbols & set(system.state_symbols):
        raise SurfaceError("surface", f"{text.strip()!r} is not a function of the state; a surface must depend "
                                      f"on at least one of {components}")
    if expr.has(sp.Abs, sp.sign):
        match = _NOT_SMOOTH.search(text)
        raise SurfaceError("surface", "a surface must be a smooth function of the state (abs and sign are not "
                                      "smooth; e.g. write gamma3, not abs(gamma3))",
                           match.start() if match else None)
    try:
        integrable(expr)  # heyoka's translation takes rational exponents only (x**pi would recurse)
    except ExpressionError as err:
        raise SurfaceError("surface", err.reason) from None
    try:
        taylor_system(system).expression(_heyoka_ready(expr))
    except (TypeError, ValueError) as exc:  # pragma: no cover - every parser function is translatable
        raise SurfaceError("surface", f"cannot be compiled for the integrator: {exc}") from None
    return expr


def parse_surface(system: MechanicalSystem, text: str) -> sp.Expr:
    """The surface's expression in the state (and parameter) symbols of ``system``.

    Parameters
    ----------
    system : the symbolic definition.
    text : e.g. ``"gamma3"``, ``"omega1 - 0.1"``, ``"M1*gamma1 + M2*gamma2"``, ``"I1*omega1 - M1"``.
        Names: the components of :func:`surface_names` (state and derived vectors) and the system's
        parameters (``I1``, ``D``, ``a1`` ...); the functions and constants of the safe parser.

    Returns
    -------
    sympy.Expr
        With the derived components replaced by their expressions in the state.

    Raises
    ------
    SurfaceError
        ``field="surface"``: a parse error or an unknown name (with its ``position``; the reason
        lists the allowed names), an expression depending on no state component (``"1"``,
        ``"pi"``, ``"I1"``), or a non-smooth one (``abs``, ``sign``).
    """
    if not isinstance(text, str):
        raise SurfaceError("surface", f"must be a string, got {type(text).__name__}")
    return _parse_surface(system, text)


@dataclass(frozen=True, eq=False)
class _SurfaceKernels:
    """One heyoka compiled function of the state for one (system, surface): :meth:`evaluate` gives, at
    many points in one call, one row per quantity: the Newton step onto the surface
    ``δ = (value − S) / (dS/dt)`` (``dS/dt = ∇S·f``), the flow ``f`` (n), ``ρ`` if the system has a
    reduced time, ``S − value``, the derived vectors' components, the integrals, their scales and the
    surface's natural scale ``Σ_i |∂S/∂x_i| · |v(i)|`` (see :func:`surface_scale_of`). The parameters
    are the system's runtime parameter vector (:meth:`~nonholonomic.numerics.taylor.TaylorSystem.runtime_parameters`),
    then ``value``; the expressions are the symbolic ones, translated as the integrator's right-hand
    side is (:mod:`nonholonomic.numerics.taylor`). ``slices`` are the state vectors' columns.
    """

    n: int
    has_tau: bool
    cfunc: hy.cfunc
    derived: tuple[tuple[str, slice], ...]
    integrals: slice
    integral_scales: slice
    natural_scale: int
    slices: tuple[slice, ...]

    #: Row of δ.
    delta = 0

    @property
    def flow(self) -> slice:
        return slice(1, 1 + self.n)

    @property
    def density(self) -> int:
        """Row of ρ (systems with a reduced time)."""
        return 1 + self.n

    @property
    def residual(self) -> int:
        """Row of ``S − value``."""
        return 1 + self.n + self.has_tau

    def evaluate(self, X: np.ndarray, runtime: np.ndarray, value: float) -> np.ndarray:
        """Every row at the states ``X`` (one per row; parameters: ``runtime``, then ``value``)."""
        pars = np.empty((self.cfunc.nparams, len(X)))
        pars[:-1] = runtime[: self.cfunc.nparams - 1, None]
        pars[-1] = value
        return self.cfunc(np.ascontiguousarray(X.T), pars=pars)


@lru_cache(maxsize=64)
def _surface_kernels(system: MechanicalSystem, expr: sp.Expr) -> _SurfaceKernels:
    ts = taylor_system(system)
    density = system.taylor_time_density  # τ at the crossings only where the integrator carries it
    n, has_tau = system.dimension, density is not None
    slices, norm_of, start = [], [], 0
    for vec in system.state:
        slices.append(slice(start, start + len(vec.symbols)))
        norm_of += [sp.sqrt(sum(s**2 for s in vec.symbols))] * len(vec.symbols)
        start += len(vec.symbols)
    gradient = [sp.diff(expr, s) for s in system.state_symbols]
    rows = [expr, sum(d * f for d, f in zip(gradient, system.rhs))] + list(system.rhs)
    rows += [density] if density is not None else []  # has_tau
    derived = []
    for derived_vec in system.derived:
        derived.append((derived_vec.name, slice(len(rows), len(rows) + len(derived_vec.expression))))
        rows += list(derived_vec.expression)
    k, first = len(system.integrals), len(rows)
    rows += [i.expression for i in system.integrals] + [i.scale for i in system.integrals]
    rows.append(sum(sp.Abs(d) * norm for d, norm in zip(gradient, norm_of)))
    S, slope, *rest = ts.expressions([_heyoka_ready(sp.sympify(r)) for r in rows])
    value = hy.par[ts.n_pars]
    # rows: δ, f, ρ, then S − value where S was (the rest keep their places)
    outputs = [(value - S) / slope, *rest[: n + has_tau], S - value, *rest[n + has_tau:]]
    return _SurfaceKernels(n=n, has_tau=has_tau, cfunc=hy.cfunc(outputs, list(ts.variables[:n])),
                           derived=tuple(derived), integrals=slice(first, first + k),
                           integral_scales=slice(first + k, first + 2 * k), natural_scale=len(rows) - 1,
                           slices=tuple(slices))


@dataclass(frozen=True, eq=False)
class _Prepared:
    """Everything one (system, surface text) needs, looked up once per call."""

    system: MechanicalSystem
    text: str
    expr: sp.Expr
    ts: TaylorSystem
    kernels: _SurfaceKernels
    names: tuple[str, ...]
    locate: dict[str, tuple[str, int]]  # component name -> (vector name, index)
    default_coordinates: tuple[str, str]


@lru_cache(maxsize=128)
def _prepare(system: MechanicalSystem, text: str) -> _Prepared:
    expr = parse_surface(system, text)
    locate = {str(sym): (vec.name, i) for vec in system.state for i, sym in enumerate(vec.symbols)}
    for vec in system.derived:
        for i in range(len(vec.expression)):
            locate.setdefault(f"{vec.name}{i + 1}", (vec.name, i))
    return _Prepared(system, text, expr, taylor_system(system), _surface_kernels(system, expr),
                     tuple(name for name, _ in _surface_names(system)), locate, default_coordinates(system))


def _scale(natural: np.ndarray, value: float) -> float:
    """``max(|value|, max(natural))``, 1 where that is 0 or not finite (``natural``: the natural scale's row)."""
    scale = abs(value)
    if len(natural):
        largest = float(natural.max())
        if math.isfinite(largest):
            scale = max(scale, largest)
    return scale if scale > 0 and math.isfinite(scale) else 1.0


def surface_scale_of(system: MechanicalSystem, expr: sp.Expr, points: np.ndarray, p: np.ndarray,
                     value: float) -> float:
    """The scale ``surface_residual_max`` is relative to.

    ``max(|value|, max over the points of Σ_i |∂S/∂x_i| · |v(i)|)``, where ``v(i)`` is the state
    vector holding component ``i`` (``|γ|`` for ``gamma3``): to first order, the change of S when
    every state vector is perturbed by its own size, i.e. the size S's rounding errors are measured
    against. 1 for ``S = gamma3`` on |γ| = 1; ``|M|`` for ``S = M1``. Falls back to 1 when that is 0
    (no points, or a surface with a vanishing gradient there).
    """
    points = np.asarray(points, dtype=float).reshape(-1, system.dimension)
    if not len(points):
        return _scale(np.empty(0), value)
    kernels = _surface_kernels(system, expr)
    runtime = taylor_system(system).runtime_parameters(np.asarray(p, dtype=float))
    return _scale(kernels.evaluate(points, runtime, value)[kernels.natural_scale], value)
