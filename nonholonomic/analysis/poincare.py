"""Poincaré sections: the crossings of one trajectory with a surface ``S(state) = value``.

A surface is a user expression in the state components (``M1``, ``gamma3``, ``omega2`` ...,
parsed by the safe parser :func:`nonholonomic.expressions.parse_expression`, never ``eval``),
possibly using the system's parameters (``I1``, ``D`` ...). Derived components (the ball's
``omega = I_Q⁻¹ M``, paper eq. 2604-1) are substituted by their expressions in the state, so
every surface is a function of the integrated variables.

Method
------
The crossings are located by heyoka's non-terminal events (``nt_event``, ``nt_event_batch``)
on the event function ``S(x) − value``: heyoka computes the Taylor expansion of the event
function along with the state's and finds the roots of that polynomial inside every step, so a
crossing is found to machine precision without any extra step. The callback evaluates the dense
output (``update_d_output``) at the event time, as heyoka's own Poincaré-section tutorial does.
``value`` is a runtime parameter (the slot after the system's parameters), so one compiled
integrator serves every level; it is compiled once per (system, surface, direction, tolerance)
and process, and copied once per thread.

The event time reaches Python rounded to a double, so the dense-output state is off the exact
root by up to half an ulp of ``t`` (``|f|·ulp(t)/2``, ~1e-13 at t ~ 1000). One Newton step along
the flow, done for all crossings at once with the numpy kernels,
``δ = −(S(x) − value)/(∇S·f)``, ``x ← x + f(x) δ``, ``t ← t + δ``, ``τ ← τ + ρ δ``, moves each point
back onto the surface (``δ`` is accepted only while it is at the level of that rounding; a
nearly tangent crossing keeps its unrefined point and a warning says so).

``max_points`` stops the integration: the trajectory is propagated in segments (1 % of
``t_final``, but at least 256 and at most 20 000 steps, and not much beyond where the crossing
rate so far puts the ``max_points``-th crossing); after each one the crossings are counted and
``progress`` is asked whether to go on. No Python callback runs at every step.

The τ of a crossing is the integrated reduced time ``dτ = ρ dt`` (paper eq. 2604-5 for the ball).

Measures reported per section: the largest ``|S(x) − value|`` at the points relative to the
surface's scale (:func:`surface_scale_of`), and the largest relative drift of every first integral
at the points against the initial state, normalised as in :mod:`nonholonomic.evidence.integrals`.
"""

from __future__ import annotations

import copy
import math
import re
import threading
import time
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import heyoka as hy
import numpy as np
import sympy as sp

from nonholonomic.definition import MechanicalSystem
from nonholonomic.expressions import ExpressionError, integrable, parse_expression
from nonholonomic.integration import MACHINE_EPSILON, IntegrationCancelled, IntegrationError, ProgressCallback
from nonholonomic.kernels import VectorKernel
from nonholonomic.taylor import TaylorSystem, taylor_system

__all__ = [
    "DIRECTIONS",
    "MAX_POINTS_LIMIT",
    "Section",
    "SurfaceError",
    "default_coordinates",
    "parse_surface",
    "section",
    "section_batch",
    "surface_names",
    "surface_scale_of",
]

#: ``increasing``: S − value goes from negative to positive; ``decreasing``: the reverse; ``both``.
DIRECTIONS = ("increasing", "decreasing", "both")
#: Largest ``max_points`` accepted (the service may configure a lower one).
MAX_POINTS_LIMIT = 1_000_000
#: Propagation segments: at least this many steps each ...
SEGMENT_MIN_STEPS = 256
#: ... at most this many (bounds the time between two progress calls) ...
SEGMENT_MAX_STEPS = 20_000
#: ... and otherwise this fraction of ``t_final``.
SEGMENT_FRACTION = 0.01
#: The Newton correction of a crossing time is accepted up to this many ``eps·max(|t|, h_max)``.
NEWTON_BOUND = 64.0

_HEYOKA_DIRECTION = {
    "increasing": hy.event_direction.positive,
    "decreasing": hy.event_direction.negative,
    "both": hy.event_direction.any,
}
_NOT_SMOOTH = re.compile(r"\b(abs|sign)\s*\(")


class SurfaceError(ValueError):
    """A refused field of a section request.

    Attributes
    ----------
    field : the request field: ``"surface"``, ``"value"``, ``"direction"``, ``"coordinates"``,
        ``"coordinates[i]"``, ``"max_points"``, ``"t_final"``, ``"tolerance"``, ``"initial_state"``,
        ``"parameters"``.
    reason : why, in words (for an unknown name it lists the allowed ones).
    position : 0-based character offset in the surface's text, when there is one.
    """

    def __init__(self, field: str, reason: str, position: int | None = None) -> None:
        self.field, self.reason, self.position = field, reason, position
        where = f" (at position {position})" if position is not None else ""
        super().__init__(f"{field}: {reason}{where}")


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


def _vectorize(exprs: Sequence[sp.Expr], args: Sequence[sp.Symbol]) -> VectorKernel:
    """``f(X, p) -> (n, len(exprs))`` like :func:`nonholonomic.kernels.vectorize`, writing the columns
    into one array (no per-column broadcast: the post-processing of a short section stays cheap)."""
    fn = sp.lambdify(list(args), list(exprs), modules="numpy", cse=True)
    width = len(exprs)

    def evaluate(X: np.ndarray, p: np.ndarray) -> np.ndarray:
        out = np.empty((len(X), width))
        for j, column in enumerate(fn(*X.T, *p)):
            out[:, j] = column
        return out

    return evaluate


@dataclass(frozen=True, eq=False)
class _SurfaceKernels:
    """The numpy kernels of one (system, surface), each one ``lambdify`` with common subexpressions.

    ``newton(X, p)`` columns: ``S``, ``∇S`` (n), ``f`` (n), then ``ρ`` if the system has a reduced time.
    ``report(X, p)`` columns: ``S``, ``∇S`` (n), the derived vectors' components, the integrals, their
    scales. ``vector_of[i]`` is the state vector holding component ``i``; ``slices`` the vectors' columns.
    """

    n: int
    newton: VectorKernel
    report: VectorKernel
    derived: tuple[tuple[str, slice], ...]
    integrals: slice
    integral_scales: slice
    vector_of: np.ndarray
    slices: tuple[slice, ...]


@lru_cache(maxsize=64)
def _surface_kernels(system: MechanicalSystem, expr: sp.Expr) -> _SurfaceKernels:
    args = system.state_symbols + system.parameter_symbols
    n = system.dimension
    slices, vector_of, start = [], [], 0
    for k, vec in enumerate(system.state):
        slices.append(slice(start, start + len(vec.symbols)))
        vector_of += [k] * len(vec.symbols)
        start += len(vec.symbols)
    head = [expr] + [sp.diff(expr, s) for s in system.state_symbols]
    tau = [system.reduced_time.density] if system.reduced_time is not None else []
    derived, column, components = [], 1 + n, []
    for vec in system.derived:
        derived.append((vec.name, slice(column, column + len(vec.expression))))
        components += list(vec.expression)
        column += len(vec.expression)
    k = len(system.integrals)
    report = head + components + [i.expression for i in system.integrals] + [i.scale for i in system.integrals]
    return _SurfaceKernels(n=n, newton=_vectorize(head + list(system.rhs) + tau, args), report=_vectorize(report, args),
                           derived=tuple(derived), integrals=slice(column, column + k),
                           integral_scales=slice(column + k, column + 2 * k), vector_of=np.asarray(vector_of),
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


def _scale(kernels: _SurfaceKernels, points: np.ndarray, gradient: np.ndarray, value: float) -> float:
    scale = abs(value)
    if len(points):
        norms = np.stack([np.linalg.norm(points[:, s], axis=1) for s in kernels.slices], axis=1)
        natural = float(np.max(np.sum(np.abs(gradient) * norms[:, kernels.vector_of], axis=1)))
        if math.isfinite(natural):
            scale = max(scale, natural)
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
    kernels = _surface_kernels(system, expr)
    points = np.asarray(points, dtype=float).reshape(-1, system.dimension)
    gradient = kernels.report(points, p)[:, 1:1 + kernels.n] if len(points) else np.empty((0, kernels.n))
    return _scale(kernels, points, gradient, value)


# --------------------------------------------------------------------------------------------------
# The result
# --------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Section:
    """The crossings of one trajectory with the surface ``S = value``, in time order.

    Attributes
    ----------
    surface : the surface's text as requested; value, direction : as requested.
    t : crossing times, shape ``(count,)``.
    tau : the reduced time τ at the crossings (None for systems without one).
    points : every state vector and derived vector by name (``M``, ``gamma``, ``omega`` for the
        ball), each of shape ``(count, 3)``.
    coordinate_names, coordinates : the two chosen components, ``coordinates`` of shape ``(count, 2)``.
    surface_residual_max : ``max |S(x) − value| / surface_scale`` at the points (0 without points).
    surface_scale : see :func:`surface_scale_of`.
    integral_drift_max : per first integral of the system, ``max |I(x) − I(x0)| / max(|I(x0)|, scale)``
        over the points, ``scale`` the integral's natural size (largest over x0 and the points), as in
        :mod:`nonholonomic.evidence.integrals`.
    stopped_early : True when ``max_points`` crossings were recorded and the integration stopped
        before ``t_final``.
    warnings : what the caller should know (max_points reached, no crossing, tangent crossings).
    steps : accepted Taylor steps; wall_time_s : integration and post-processing time (for a
        member of :func:`section_batch`, its share of its batch's time). Compilation is not counted.
    t_final : the requested end time; tolerance : heyoka's tolerance.
    """

    surface: str
    value: float
    direction: str
    t: np.ndarray
    tau: np.ndarray | None
    points: dict[str, np.ndarray]
    coordinate_names: tuple[str, str]
    coordinates: np.ndarray
    surface_residual_max: float
    surface_scale: float
    integral_drift_max: dict[str, float]
    stopped_early: bool
    warnings: tuple[str, ...]
    steps: int
    wall_time_s: float
    t_final: float = 0.0
    tolerance: float = MACHINE_EPSILON

    @property
    def count(self) -> int:
        """Number of crossings."""
        return int(len(self.t))


# --------------------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Request:
    prep: _Prepared
    value: float
    direction: str
    coordinates: tuple[str, str]
    max_points: int
    t_final: float
    tolerance: float

    @property
    def system(self) -> MechanicalSystem:
        return self.prep.system

    @property
    def text(self) -> str:
        return self.prep.text

    @property
    def expr(self) -> sp.Expr:
        return self.prep.expr


def _validate(system: MechanicalSystem, surface: str, value: float, direction: str,
              coordinates: Sequence[str] | None, max_points: int, t_final: float,
              tolerance: float | None) -> _Request:
    if not isinstance(surface, str):
        raise SurfaceError("surface", f"must be a string, got {type(surface).__name__}")
    prep = _prepare(system, surface)
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise SurfaceError("value", f"must be a number, got {value!r}") from None
    if not math.isfinite(value):
        raise SurfaceError("value", f"must be finite, got {value!r}")
    if direction not in DIRECTIONS:
        raise SurfaceError("direction", f"must be one of {', '.join(DIRECTIONS)}; got {direction!r}")
    names = prep.names
    coords = prep.default_coordinates if coordinates is None else coordinates
    if isinstance(coords, str) or not isinstance(coords, Sequence) or len(coords) != 2:
        raise SurfaceError("coordinates", f"must be a list of two component names, got {coords!r}")
    for i, name in enumerate(coords):
        if not isinstance(name, str) or name not in names:
            raise SurfaceError(f"coordinates[{i}]", f"unknown component {name!r}; allowed: {', '.join(names)}")
    if coords[0] == coords[1]:
        raise SurfaceError("coordinates[1]", f"the two coordinates must differ (both are {coords[0]!r})")
    if isinstance(max_points, bool) or not isinstance(max_points, (int, np.integer)):
        raise SurfaceError("max_points", f"must be an integer, got {max_points!r}")
    if not 1 <= max_points <= MAX_POINTS_LIMIT:
        raise SurfaceError("max_points", f"must be between 1 and {MAX_POINTS_LIMIT}, got {max_points}")
    try:
        t_final = float(t_final)
    except (TypeError, ValueError):
        raise SurfaceError("t_final", f"must be a number, got {t_final!r}") from None
    if not (math.isfinite(t_final) and t_final > 0):
        raise SurfaceError("t_final", f"must be finite and > 0, got {t_final!r}")
    tol = MACHINE_EPSILON if tolerance is None else float(tolerance)
    if not (math.isfinite(tol) and 0 < tol < 1):
        raise SurfaceError("tolerance", f"must be in (0, 1), got {tolerance!r}")
    return _Request(prep, value, direction, (coords[0], coords[1]), int(max_points), t_final, tol)


def _check_arrays(system: MechanicalSystem, parameters: np.ndarray, states: np.ndarray) -> None:
    n_par = len(system.parameter_symbols)
    if parameters.shape[-1] != n_par:
        raise SurfaceError("parameters", f"needs {n_par} values per member, got shape {parameters.shape}")
    if states.shape[-1] != system.dimension:
        raise SurfaceError("initial_state", f"needs {system.dimension} components, got shape {states.shape}")
    if not np.all(np.isfinite(parameters)):
        raise SurfaceError("parameters", "non-finite value")
    if not np.all(np.isfinite(states)):
        raise SurfaceError("initial_state", "non-finite component")


# --------------------------------------------------------------------------------------------------
# Compiled integrators with the event (once per process, copied once per thread)
# --------------------------------------------------------------------------------------------------

class _Crossings:
    """nt_event callback of the scalar integrator: the dense-output state at each crossing."""

    def __init__(self) -> None:
        self.reset(0, 0)

    def reset(self, n_vars: int, capacity: int) -> None:
        size = min(capacity, 256)
        self.t, self.x = np.empty(size), np.empty((size, n_vars))
        self.count, self.seen, self.capacity = 0, 0, capacity

    def _grow(self) -> None:
        size = min(2 * len(self.t) + 1, self.capacity)
        self.t = np.resize(self.t, size)
        self.x = np.concatenate([self.x, np.empty((size - len(self.x), self.x.shape[1]))])

    def __call__(self, ta: hy.taylor_adaptive, t: float, d_sgn: int) -> None:
        self.seen += 1
        k = self.count
        if k >= self.capacity:
            return
        if k == len(self.t):
            self._grow()
        ta.update_d_output(t)
        self.t[k] = t
        self.x[k] = ta.d_output
        self.count = k + 1


class _BatchCrossings:
    """nt_event_batch callback: one :class:`_Crossings` per lane (capacity 0 for padding lanes)."""

    def __init__(self, batch: int) -> None:
        self.lanes = [_Crossings() for _ in range(batch)]

    def reset(self, n_vars: int, capacities: Sequence[int]) -> None:
        for lane, capacity in zip(self.lanes, capacities):
            lane.reset(n_vars, capacity)

    def __call__(self, ta: hy.taylor_adaptive_batch, t: float, d_sgn: int, idx: int) -> None:
        lane = self.lanes[idx]
        lane.seen += 1
        k = lane.count
        if k >= lane.capacity:
            return
        if k == len(lane.t):
            lane._grow()
        times = np.array(ta.time)  # a copy: the other lanes' times stay untouched
        times[idx] = t
        ta.update_d_output(times)
        lane.t[k] = t
        lane.x[k] = ta.d_output[:, idx]
        lane.count = k + 1


@lru_cache(maxsize=16)
def _template(system: MechanicalSystem, expr: sp.Expr, direction: str, tolerance: float,
              batch: int) -> hy.taylor_adaptive | hy.taylor_adaptive_batch:
    """Compile the integrator of ``system`` with the event ``S − par[n_pars]`` (``batch = 0``: scalar)."""
    ts = taylor_system(system)
    event = ts.expression(_heyoka_ready(expr)) - hy.par[ts.n_pars]
    n_vars = len(ts.variables)
    if batch == 0:
        return hy.taylor_adaptive(ts.equations, [0.0] * n_vars, pars=[0.0] * (ts.n_pars + 1), tol=tolerance,
                                  nt_events=[hy.nt_event(event, _Crossings(), direction=_HEYOKA_DIRECTION[direction])])
    return hy.taylor_adaptive_batch(
        ts.equations, np.zeros((n_vars, batch)), pars=np.zeros((ts.n_pars + 1, batch)), tol=tolerance,
        nt_events=[hy.nt_event_batch(event, _BatchCrossings(batch), direction=_HEYOKA_DIRECTION[direction])])


_per_thread = threading.local()
_PER_THREAD_CAPACITY = 8


def _integrator(prep: _Prepared, direction: str, tolerance: float, batch: int = 0
                ) -> tuple[hy.taylor_adaptive | hy.taylor_adaptive_batch, _Crossings | _BatchCrossings]:
    """This thread's copy of the compiled integrator and its event callback (a small LRU per thread)."""
    cache: OrderedDict = _per_thread.__dict__.setdefault("cache", OrderedDict())
    key = (id(prep), direction, tolerance, batch)
    entry = cache.get(key)
    if entry is not None and entry[0] is prep:
        cache.move_to_end(key)
    else:
        ta = copy.deepcopy(_template(prep.system, prep.expr, direction, tolerance, batch))
        entry = cache[key] = (prep, ta, ta.nt_events[0].callback)
        while len(cache) > _PER_THREAD_CAPACITY:
            cache.popitem(last=False)
    return entry[1], entry[2]


def _next_segment(t_final: float, t_now: float, steps: float, crossings: int, remaining: int) -> float:
    """Length of the next propagation segment (see the module docstring)."""
    mean_h = t_now / steps if steps > 0 else t_final
    seg = min(max(SEGMENT_FRACTION * t_final, SEGMENT_MIN_STEPS * mean_h), SEGMENT_MAX_STEPS * mean_h)
    if crossings > 0:  # do not run far past the max_points-th crossing
        seg = min(seg, max(1.25 * remaining * t_now / crossings, SEGMENT_MIN_STEPS * mean_h / 4))
    return seg


_GOOD = (hy.taylor_outcome.time_limit, hy.taylor_outcome.success)


#: A piece of SEGMENT_MAX_STEPS steps that gains less than this many ``eps·max(|t|, 1)`` per step has stalled.
STALL_STEP_ULPS = 1024.0


def _stalled_at(before: float, after: float) -> bool:
    """Whether a piece of :data:`SEGMENT_MAX_STEPS` steps from ``before`` to ``after`` stalled: steps at the
    rounding of ``t`` (an event function not finite or not smooth where the orbit is: heyoka's steps
    shrink to nothing and never get past it)."""
    return after - before <= SEGMENT_MAX_STEPS * STALL_STEP_ULPS * MACHINE_EPSILON * max(abs(after), 1.0)


def _stalled(t: float) -> str:
    return (f"heyoka's steps shrank to nothing at t = {t:g}: the surface is not finite or not smooth where the "
            "orbit meets it (e.g. sqrt or a fractional power at 0), so its crossings cannot be located")


def _propagate(ta: hy.taylor_adaptive, t_next: float, t_final: float,
               progress: ProgressCallback | None) -> tuple[hy.taylor_outcome, float, int]:
    """``propagate_until(t_next)`` in pieces of at most :data:`SEGMENT_MAX_STEPS` steps, asking ``progress``
    between them (a cancellation or a time limit acts within one piece). Returns the outcome, the largest
    step and the steps taken. An event function that is not finite at the orbit makes heyoka take empty
    steps forever: a piece that gains (next to) no time raises :class:`IntegrationError`."""
    steps, max_h = 0, 0.0
    while True:
        before = ta.time
        outcome, _, piece_max_h, nsteps, _, _ = ta.propagate_until(t_next, max_steps=SEGMENT_MAX_STEPS)
        steps += nsteps
        if math.isfinite(piece_max_h):
            max_h = max(max_h, abs(piece_max_h))
        if outcome != hy.taylor_outcome.step_limit:
            return outcome, max_h, steps
        if _stalled_at(before, ta.time):
            raise IntegrationError(_stalled(ta.time))
        if progress is not None and not progress(min(ta.time / t_final, 1.0)):
            raise IntegrationCancelled(f"cancelled at t = {ta.time:g}")


# --------------------------------------------------------------------------------------------------
# Post-processing: Newton step onto the surface, points, coordinates, residual, drift
# --------------------------------------------------------------------------------------------------

def _finish(req: _Request, p: np.ndarray, y0: np.ndarray, t: np.ndarray, raw: np.ndarray, max_h: float,
            stopped_early: bool, steps: int, start: float, wall_share: float = 1.0) -> Section:
    system = req.system
    n = system.dimension
    kernels = req.prep.kernels
    order = np.argsort(t, kind="stable")
    t, raw = t[order], raw[order]
    x = raw[:, :n].copy()
    tau = raw[:, n].copy() if system.reduced_time is not None else None
    warnings: list[str] = []

    if len(t):
        # One Newton step along the flow: undo the rounding of the event time to a double.
        columns = kernels.newton(x, p)
        f = columns[:, 1 + n:1 + 2 * n]
        g = columns[:, 0] - req.value
        dg = np.sum(columns[:, 1:1 + n] * f, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            delta = -g / dg
        bound = NEWTON_BOUND * MACHINE_EPSILON * np.maximum(np.abs(t), max_h)
        ok = np.isfinite(delta) & (np.abs(delta) <= bound)
        delta = np.where(ok, delta, 0.0)
        if tau is not None:
            tau = tau + columns[:, 1 + 2 * n] * delta
        x = x + f * delta[:, None]
        t = t + delta
        if not np.all(ok):
            warnings.append(f"{int(np.sum(~ok))} crossing(s) nearly tangent to the surface (dS/dt ~ 0): their "
                            "points are the integrator's event points, not refined onto the surface")
    else:
        warnings.append(f"no crossing of {req.text!r} = {req.value:g} ({req.direction}) in 0 <= t <= "
                        f"{req.t_final:g}")
    if stopped_early:
        warnings.append(f"max_points = {req.max_points} reached at t = {t[-1]:.9g}; the integration stopped "
                        f"there instead of at t_final = {req.t_final:g}")

    # Everything reported, evaluated at the initial state (row 0) and the points in one kernel call.
    report = kernels.report(np.vstack([y0[None, :], x]), p)
    at_points = report[1:]
    points: dict[str, np.ndarray] = {vec.name: x[:, cols].copy() for vec, cols in zip(system.state, kernels.slices)}
    for name, cols in kernels.derived:
        points[name] = at_points[:, cols].copy()
    coordinates = np.stack([points[vec][:, i] for vec, i in (req.prep.locate[c] for c in req.coordinates)], axis=1)

    scale = _scale(kernels, x, at_points[:, 1:1 + n], req.value)
    residual = float(np.max(np.abs(at_points[:, 0] - req.value)) / scale) if len(t) else 0.0

    drift: dict[str, float] = {}
    if system.integrals:
        values = report[:, kernels.integrals]
        reference = np.maximum(np.abs(values[0]), np.max(np.abs(report[:, kernels.integral_scales]), axis=0))
        reference = np.where(reference > 0, reference, 1.0)
        rel = np.max(np.abs(values - values[0]), axis=0) / reference
        drift = {claim.name: float(rel[i]) for i, claim in enumerate(system.integrals)}

    return Section(
        surface=req.text, value=req.value, direction=req.direction, t=t, tau=tau, points=points,
        coordinate_names=req.coordinates, coordinates=coordinates, surface_residual_max=residual,
        surface_scale=scale, integral_drift_max=drift, stopped_early=stopped_early, warnings=tuple(warnings),
        steps=int(steps), wall_time_s=(time.perf_counter() - start) * wall_share, t_final=req.t_final,
        tolerance=req.tolerance,
    )


# --------------------------------------------------------------------------------------------------
# Entry points
# --------------------------------------------------------------------------------------------------

def section(
    system: MechanicalSystem,
    parameters: np.ndarray,
    initial_state: np.ndarray,
    t_final: float,
    surface: str,
    *,
    value: float = 0.0,
    direction: str = "increasing",
    coordinates: Sequence[str] | None = None,
    max_points: int = 10_000,
    tolerance: float | None = None,
    progress: ProgressCallback | None = None,
) -> Section:
    """The Poincaré section of the trajectory from ``initial_state`` on ``surface = value`` for 0 ≤ t ≤ ``t_final``.

    Parameters
    ----------
    system : the symbolic definition (e.g. ``get_system("chaplygin_ball", "zero")``).
    parameters : in the order of ``system.parameter_symbols``.
    initial_state : in the order of ``system.state_symbols``.
    t_final : end time (> 0).
    surface : expression text (see :func:`parse_surface`), e.g. ``"gamma3"``.
    value : the level of the section.
    direction : one of :data:`DIRECTIONS`.
    coordinates : two component names (state or derived) to report as ``coordinates``; default
        :func:`default_coordinates`.
    max_points : stop integrating once this many crossings are recorded (≤ :data:`MAX_POINTS_LIMIT`);
        the section then has ``stopped_early`` and a warning, it is not an error.
    tolerance : heyoka's tolerance (default machine epsilon).
    progress : called with the fraction of ``t_final`` reached after each propagation segment;
        returning False cancels (:class:`IntegrationCancelled`).

    Raises
    ------
    SurfaceError
        A refused field (``.field``, ``.reason``, ``.position``); a :class:`ValueError`.
    IntegrationError
        The integration failed before ``t_final`` (non-finite state ...).
    IntegrationCancelled
    """
    req = _validate(system, surface, value, direction, coordinates, max_points, t_final, tolerance)
    p = np.asarray(parameters, dtype=float)
    y0 = np.asarray(initial_state, dtype=float)
    if p.ndim != 1:
        raise SurfaceError("parameters", f"must be one vector, got shape {p.shape}")
    if y0.ndim != 1:
        raise SurfaceError("initial_state", f"must be one vector, got shape {y0.shape}")
    _check_arrays(system, p, y0)
    ta, crossings = _integrator(req.prep, req.direction, req.tolerance)
    ts = req.prep.ts
    n_vars = len(ts.variables)

    start = time.perf_counter()
    ta.time = 0.0
    ta.state[:] = ts.initial(y0)
    ta.pars[: ts.n_pars] = ts.runtime_parameters(p)
    ta.pars[ts.n_pars] = req.value
    crossings.reset(n_vars, req.max_points)
    steps, max_h, t_now = 0, 0.0, 0.0
    stopped_early = False
    seg = SEGMENT_FRACTION * req.t_final
    while True:
        t_next = req.t_final if t_now + 1.001 * seg >= req.t_final else t_now + seg
        outcome, seg_max_h, nsteps = _propagate(ta, t_next, req.t_final, progress)
        steps += nsteps
        max_h = max(max_h, abs(seg_max_h)) if math.isfinite(seg_max_h) else max_h
        if outcome != hy.taylor_outcome.time_limit:
            raise IntegrationError(f"heyoka stopped between t = {t_now:g} and {t_next:g} with outcome "
                                   f"{outcome.name}")
        t_now = t_next
        if crossings.count >= req.max_points and (t_now < req.t_final or crossings.seen > crossings.count):
            stopped_early = True
        done = stopped_early or t_now >= req.t_final
        if progress is not None and not progress(t_now / req.t_final) and not done:
            raise IntegrationCancelled(f"cancelled at t = {t_now:g}")
        if done:
            break
        seg = _next_segment(req.t_final, t_now, steps, crossings.seen, req.max_points - crossings.count)
    count = crossings.count
    return _finish(req, p, y0, crossings.t[:count].copy(), crossings.x[:count].copy(), max_h, stopped_early,
                   steps, start)


def section_batch(
    system: MechanicalSystem,
    parameters: np.ndarray,
    initial_states: np.ndarray,
    t_final: float,
    surface: str,
    *,
    value: float = 0.0,
    direction: str = "increasing",
    coordinates: Sequence[str] | None = None,
    max_points: int = 10_000,
    tolerance: float | None = None,
    progress: ProgressCallback | None = None,
) -> list[Section | IntegrationError]:
    """:func:`section` for many members at once with heyoka's batch mode.

    Members are integrated ``hy.recommended_simd_size()`` at a time (``taylor_adaptive_batch`` with
    an ``nt_event_batch``; the last batch is padded with copies of a member whose results are
    dropped). Each member gets its own :class:`Section` or, if its integration fails, the
    :class:`IntegrationError` in its place: heyoka halts every lane when one fails, so the failed
    lane is replaced by a copy of a healthy one (discarded) and the others resume where they were;
    their results are those of an uninterrupted run. A member reaching ``max_points`` stops
    recording; its lane runs on until the batch ends (its steps are not counted).

    Parameters
    ----------
    parameters : shape ``(n_members, n_parameters)``, or one vector shared by every member.
    initial_states : shape ``(n_members, dimension)``.
    progress : called with the fraction of the whole work done after each segment of each batch.
    Other parameters as for :func:`section`.

    Returns
    -------
    list of Section or IntegrationError, one per member in order. ``wall_time_s`` of a member is its
    share of its batch's wall time.

    Raises
    ------
    SurfaceError, IntegrationCancelled
    """
    req = _validate(system, surface, value, direction, coordinates, max_points, t_final, tolerance)
    Y = np.asarray(initial_states, dtype=float)
    if Y.ndim != 2 or len(Y) == 0:
        raise SurfaceError("initial_state", f"must have shape (n_members, {system.dimension}), got {Y.shape}")
    P = np.asarray(parameters, dtype=float)
    if P.ndim == 1:
        P = np.broadcast_to(P, (len(Y), len(P)))
    if P.ndim != 2 or len(P) != len(Y):
        raise SurfaceError("parameters", f"must have shape ({len(Y)}, n_parameters), got {P.shape}")
    _check_arrays(system, P, Y)
    batch = hy.recommended_simd_size()
    ta, recorder = _integrator(req.prep, req.direction, req.tolerance, batch)
    n_groups = -(-len(Y) // batch)
    results: list[Section | IntegrationError] = []
    for g in range(n_groups):
        members = list(range(g * batch, min((g + 1) * batch, len(Y))))
        lane_progress = None if progress is None else (
            lambda fraction, g=g: progress((g + fraction) / n_groups))
        results.extend(_run_batch(req, ta, recorder, P[members], Y[members], lane_progress))
    return results


def _run_batch(req: _Request, ta: hy.taylor_adaptive_batch, recorder: _BatchCrossings, P: np.ndarray,
               Y: np.ndarray, progress: ProgressCallback | None) -> list[Section | IntegrationError]:
    """Integrate up to one batch of members (``len(Y) <= batch``)."""
    ts = req.prep.ts
    batch = ta.batch_size
    real = len(Y)
    lanes = list(range(real)) + [real - 1] * (batch - real)  # padding lanes copy the last member
    n_vars = len(ts.variables)

    start = time.perf_counter()
    ta.set_time(np.zeros(batch))
    ta.state[:] = np.stack([ts.initial(Y[m]) for m in lanes], axis=1)
    pars = np.empty((ts.n_pars + 1, batch))
    pars[: ts.n_pars] = ts.runtime_parameters(P[lanes].T)
    pars[ts.n_pars] = req.value
    ta.pars[:] = pars
    recorder.reset(n_vars, [req.max_points if i < real else 0 for i in range(batch)])
    failed: dict[int, IntegrationError] = {}
    early_at: dict[int, bool] = {}
    steps = np.zeros(batch, dtype=np.int64)
    max_h = np.zeros(batch)
    t_now = 0.0
    seg = SEGMENT_FRACTION * req.t_final

    def active(i: int) -> bool:
        return i < real and i not in failed and i not in early_at

    while any(active(i) for i in range(batch)):
        t_next = req.t_final if t_now + 1.001 * seg >= req.t_final else t_now + seg
        while True:  # until every lane reaches t_next; a failing lane is replaced and the rest resume
            before = np.array(ta.time)
            ta.propagate_until(t_next, max_steps=SEGMENT_MAX_STEPS)  # bounded: progress is asked in between
            bad, going = [], False
            for i, (outcome, _, lane_max_h, nsteps) in enumerate(ta.propagate_res):
                if active(i):
                    steps[i] += nsteps
                    if math.isfinite(lane_max_h):
                        max_h[i] = max(max_h[i], abs(lane_max_h))
                if outcome == hy.taylor_outcome.step_limit and _stalled_at(float(before[i]), float(ta.time[i])):
                    bad.append((i, _stalled(float(ta.time[i]))))
                elif outcome == hy.taylor_outcome.step_limit:
                    going = True
                elif outcome not in _GOOD:
                    bad.append((i, f"heyoka stopped between t = {t_now:g} and {t_next:g} with outcome {outcome.name}"))
            if going and not bad and progress is not None and not progress(float(np.min(ta.time)) / req.t_final):
                raise IntegrationCancelled(f"cancelled at t = {float(np.min(ta.time)):g}")
            if not bad:
                if going:
                    continue
                break
            times_hi, times_lo = (np.array(a) for a in ta.dtime)
            for i, reason in bad:
                if active(i):
                    failed[i] = IntegrationError(reason)
                recorder.lanes[i].capacity = 0  # from now on a dummy lane: its crossings are dropped
            healthy = [i for i in range(batch) if i not in {b for b, _ in bad}]
            if not healthy:
                break
            donor = healthy[0]
            state, lane_pars = np.array(ta.state), np.array(ta.pars)
            for i, _ in bad:
                times_hi[i], times_lo[i] = times_hi[donor], times_lo[donor]
                state[:, i], lane_pars[:, i] = state[:, donor], lane_pars[:, donor]
            ta.set_dtime(times_hi, times_lo)
            ta.state[:] = state
            ta.pars[:] = lane_pars
        if not any(active(i) for i in range(batch)):
            break
        t_now = t_next
        for i in range(real):
            lane = recorder.lanes[i]
            if active(i) and lane.count >= req.max_points and (t_now < req.t_final or lane.seen > lane.count):
                early_at[i] = True
                lane.capacity = lane.count  # stop recording
        done = t_now >= req.t_final or not any(active(i) for i in range(batch))
        if progress is not None and not progress(t_now / req.t_final) and not done:
            raise IntegrationCancelled(f"cancelled at t = {t_now:g}")
        if done:
            break
        alive = [i for i in range(batch) if active(i)]
        if alive:
            seen = min(recorder.lanes[i].seen for i in alive)
            remaining = max(req.max_points - recorder.lanes[i].count for i in alive)
            seg = _next_segment(req.t_final, t_now, float(np.mean(steps[alive])), seen, remaining)

    share = 1.0 / real
    out: list[Section | IntegrationError] = []
    for i in range(real):
        if i in failed:
            out.append(failed[i])
            continue
        lane = recorder.lanes[i]
        out.append(_finish(req, P[i], Y[i], lane.t[: lane.count].copy(), lane.x[: lane.count].copy(), max_h[i],
                           i in early_at, int(steps[i]), start, share))
    return out
