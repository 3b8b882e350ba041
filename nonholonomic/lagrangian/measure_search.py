"""An invariant measure ρ(q) dq du of a user's Lagrangian system on its constraint manifold, sought and
proven symbolically: a density is reported only with its proof, its absence only with an obstruction.

The constraint manifold A(q) q̇ = 0 is parametrised by m = n − k of the velocities, u (those left after
solving the constraints for k dependent velocities whose k × k minor of A is regular at the sample
points, a constant minor preferred): q̇ = B(q) u. The reduced flow in (q, u) is

    q̇ = B(q) u,    u̇ = (q̈ of the Lagrange–d'Alembert equations)_independent at q̇ = B u,

and for L = T₂ − U its divergence is linear and homogeneous in u: div f = Σⱼ cⱼ(q) uⱼ. A density ρ(q)
(a function of the coordinates only) has div(ρ f) = ρ (div f + (∇ ln ρ, B u)) = 0 exactly when

    Xⱼ φ = −cⱼ   (j = 1..m),    φ = ln ρ,   Xⱼ = Σᵢ Bᵢⱼ ∂/∂qᵢ (the columns of B as vector fields).

The brackets give more first-order conditions, [X, Y] φ = X(Yφ) − Y(Xφ) (the nonholonomic directions
the columns of B do not span); they are added until the conditions determine g = ∇φ (n independent
rows at the sample points; Chow's condition). Then g is solved for and, being a gradient, must be
closed, ∂ᵢ gⱼ = ∂ⱼ gᵢ, and every further bracket condition must hold: a failure, shown non-zero at a
point with the parameters' values, proves that no measure ρ(q) dq du exists there (`none`). Otherwise
φ is integrated coordinate by coordinate and ``found`` needs div(ρ f)/ρ to vanish identically
(parameters symbolic; sin² + cos² = 1 by t = tan(q/2)) and pointwise at random states to
:data:`POINTWISE_TOLERANCE`. When the brackets do not span, ρ is sought independent of the missing
coordinates, and a failure is only `undecided`.

The existence of a measure ρ(q) dq du does not depend on the choice of u: another choice u' = T(q) u
multiplies ρ by |det T(q)|. For the nonholonomic particle (ż = y ẋ, u = (ẋ, ẏ)) the density is
√(1 + y²); without constraints it is det M (Liouville's measure dq dp = det M dq dq̇).
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, replace

import numpy as np
import sympy as sp
from sympy.integrals.rationaltools import ratint

from nonholonomic import bounded
from nonholonomic.lagrangian.checks import number, sample_points
from nonholonomic.lagrangian.equations import _solve, dependent_columns, derive, tidy
from nonholonomic.lagrangian.parse import LagrangianData
from nonholonomic.lagrangian.sampled_search import sampled_measure
from nonholonomic.rational_trig import rational_trig_is_zero
from nonholonomic.work_limits import MAX_INTEGRATE_OPS, operations, over

__all__ = ["POINTWISE_TOLERANCE", "MeasureVerdict", "implied_by_multiplier", "measure_verdict"]

#: Pointwise relative residual |Σᵢ ∂(ρ fᵢ)/∂xᵢ| / Σᵢ |∂(ρ fᵢ)/∂xᵢ| accepted for ``found``.
POINTWISE_TOLERANCE = 1e-12
#: Nested brackets tried before the conditions are declared not to determine ∇ ln ρ.
MAX_BRACKET_DEPTH = 3
#: A value at a sample point (50 significant digits, exact inputs) counts as non-zero above this.
NONZERO = 1e-25
#: Random states for the pointwise check.
POINTWISE_STATES = 6


@dataclass(frozen=True)
class MeasureVerdict:
    """The outcome of the search for an invariant measure ρ(q) dq du on the constraint manifold.

    Attributes
    ----------
    status : str
        ``"found"`` (``density`` proven invariant), ``"none"`` (an obstruction proven at the
        parameters' values) or ``"undecided"``.
    density : sympy.Expr or None
        ρ(q) (parameters symbolic) when found.
    velocities : tuple of sympy.Symbol
        u: the independent velocities, the coordinates of the measure besides q.
    dependent : tuple of (sympy.Symbol, sympy.Expr)
        The other velocities as functions of (q, u) (the constraints solved).
    reason : str
        What was proven, or why nothing was.
    residual : float or None
        The pointwise residual of div(ρ f) when found.
    seconds : float
        How long the search took.
    """

    status: str
    density: sp.Expr | None
    velocities: tuple[sp.Symbol, ...]
    dependent: tuple[tuple[sp.Symbol, sp.Expr], ...]
    reason: str
    residual: float | None = None
    seconds: float = 0.0


class _Failed(Exception):
    """A verdict reached inside the search (``none`` or ``undecided``)."""

    def __init__(self, status: str, reason: str) -> None:
        super().__init__(reason)
        self.status, self.reason = status, reason


def _exact_points(data: LagrangianData) -> list[dict[sp.Symbol, sp.Expr]]:
    """The sample points with exact (rational) coordinates and parameters' values."""
    return [{s: sp.Rational(float(x)) for s, x in point.items()} for point in sample_points(data)]


def _value(expr: sp.Expr, point: dict[sp.Symbol, sp.Expr]) -> complex | None:
    try:
        value = complex(sp.sympify(expr).xreplace(point).evalf(50))
    except (TypeError, ValueError, ZeroDivisionError, OverflowError):
        return None
    return value if np.isfinite(value.real) and np.isfinite(value.imag) else None


def _zero(expr: sp.Expr, data: LagrangianData, points: list[dict[sp.Symbol, sp.Expr]]) -> bool | None:
    """``expr ≡ 0``: True proven (cancelled, or rational in sin/cos after t = tan(q/2)); False when it is
    non-zero at a sample point (parameters' values); None when it looks zero but is not proven."""
    expr = tidy(expr)
    if expr == 0:
        return True
    angles = tuple(sorted({s for f in expr.atoms(sp.sin, sp.cos, sp.tan) for s in f.free_symbols if s in data.q},
                          key=str))
    if angles and rational_trig_is_zero(sp.numer(expr), angles) is True:
        return True
    values = [_value(expr, p) for p in points]
    if any(v is not None and abs(v) > NONZERO for v in values):
        return False
    return None


def _dependent_columns(data: LagrangianData) -> tuple[int, ...]:
    """:func:`~nonholonomic.lagrangian.equations.dependent_columns`, or an undecided verdict."""
    found = dependent_columns(data)
    if found is None:
        raise _Failed("undecided", "no k velocities can be solved for at every sample point (no k x k minor of A "
                                   "is regular at all of them)")
    return found


def _apply(field: sp.Matrix, expr: sp.Expr, q: tuple[sp.Symbol, ...]) -> sp.Expr:
    """The derivative of ``expr`` along the vector field ``field`` (components on ∂/∂qᵢ)."""
    return sum((field[i] * sp.diff(expr, qi) for i, qi in enumerate(q)), sp.Integer(0))


def _bracket(X: sp.Matrix, Y: sp.Matrix, q: tuple[sp.Symbol, ...]) -> sp.Matrix:
    """The Lie bracket [X, Y] of two vector fields (components on ∂/∂qᵢ)."""
    return sp.Matrix([tidy(_apply(X, Y[i], q) - _apply(Y, X[i], q)) for i in range(len(q))])


def _rank(rows: list[sp.Matrix], points: list[dict[sp.Symbol, sp.Expr]]) -> int:
    """The largest rank of the rows at the sample points."""
    best = 0
    for p in points:
        values = [[_value(e, p) for e in row] for row in rows]
        real = [[v.real for v in row if v is not None] for row in values]
        if any(len(r) != len(row) for r, row in zip(real, values)):  # an entry without a value here
            continue
        matrix = np.array(real, dtype=float)
        if matrix.size:
            s = np.linalg.svd(matrix, compute_uv=False)
            best = max(best, int(np.sum(s > 1e-10 * max(s[0], 1e-300))))
    return best


def _search(data: LagrangianData) -> tuple:
    """The verdict's fields; an undecided one with parameters is tried again at their exact values."""
    out = _search_symbolic(data)
    if out[0] != "undecided" or not data.parameters or "not linear" in out[4]:
        return out
    exact = {s: sp.nsimplify(value, rational=True) for s, value in data.parameter_values.items()}
    fixed = replace(data, L=data.L.xreplace(exact), constraints=tuple(f.xreplace(exact) for f in data.constraints),
                    A=sp.ImmutableMatrix(data.A.xreplace(exact)), parameters=(), values=())
    again = _search_symbolic(fixed)
    if again[0] == "undecided":
        return out
    values = ", ".join(f"{s} = {sp.sstr(value)}" for s, value in exact.items())
    reason = (f"{again[4]}; with the parameters' values substituted exactly ({values}): with the parameters "
              f"symbolic it was undecided ({out[4]})")
    return (*again[:4], reason, again[5], out[6] + again[6])


@dataclass(frozen=True)
class _Flow:
    """The user's flow on the constraint manifold in (q, u): q̇ = B(q) u and u̇; its divergence."""

    u: tuple[sp.Symbol, ...]
    dependent: tuple[tuple[sp.Symbol, sp.Expr], ...]
    B: sp.Matrix
    qdot: list[sp.Expr]
    field: tuple[sp.Expr, ...]
    div: sp.Expr


def _flow(data: LagrangianData) -> _Flow:
    """The reduced flow of ``data`` in (q, u), u the velocities left after solving the constraints."""
    q, v = data.q, data.v
    n, k = len(q), data.A.shape[0]
    float_points = sample_points(data)
    eqs = derive(data)
    dep = _dependent_columns(data)
    ind = tuple(j for j in range(n) if j not in dep)
    u = tuple(v[j] for j in ind)
    A = sp.Matrix(data.A)
    if k:
        solved = _solve(A.extract(list(range(k)), list(dep)), -A.extract(list(range(k)), list(ind)), float_points)
    else:
        solved = sp.zeros(0, len(ind))
    B = sp.zeros(n, len(ind))
    for col, j in enumerate(ind):
        B[j, col] = 1
    for row, j in enumerate(dep):
        for col in range(len(ind)):
            B[j, col] = tidy(solved[row, col])
    on_manifold = {v[j]: sp.Add(*(B[j, c] * u[c] for c in range(len(ind)))) for j in dep}
    dependent = tuple((v[j], on_manifold[v[j]]) for j in dep)
    qdot = [sp.Add(*(B[i, c] * u[c] for c in range(len(ind)))) for i in range(n)]
    udot = [tidy(eqs.qddot[j].xreplace(on_manifold)) for j in ind]
    field = (*qdot, *udot)
    div = tidy(sum((sp.diff(e, x) for e, x in zip(field, (*q, *u))), sp.Integer(0)))
    return _Flow(u, dependent, B, qdot, field, div)


def _search_symbolic(data: LagrangianData) -> tuple:
    """The verdict's fields (as :class:`MeasureVerdict`'s), parameters kept symbolic."""
    start = time.perf_counter()
    q = data.q
    points = _exact_points(data)
    float_points = sample_points(data)
    flow = _flow(data)
    u, dependent, B, qdot, field, div = flow.u, flow.dependent, flow.B, flow.qdot, flow.field, flow.div

    def fail(status: str, reason: str) -> tuple:
        return status, None, u, dependent, reason, None, time.perf_counter() - start

    c = [tidy(sp.diff(div, uj)) for uj in u]
    if any(cj.has(*u) for cj in c) or _zero(div - sum((cj * uj for cj, uj in zip(c, u)), sp.Integer(0)),
                                            data, points) is not True:
        return fail("undecided", "div f of the reduced flow is not linear and homogeneous in the velocities u "
                                 "(L not quadratic in them?): a density of q alone is not sought")
    try:
        g, note = _gradient(data, B, c, points, float_points)
        log_rho = _integrate(data, g, points)
    except _Failed as failed:
        return fail(failed.status, failed.reason)
    rho = sp.powsimp(sp.exp(log_rho), force=True)
    rho = sp.factor_terms(rho)
    ln_rho = sp.expand_log(sp.log(rho), force=True)
    bracket = div + sum((sp.diff(ln_rho, qi) * fi for qi, fi in zip(q, qdot)), sp.Integer(0))
    if _zero(bracket, data, points) is not True:
        return fail("undecided", f"the candidate rho = {sp.sstr(rho)} was not proven: div(rho f)/rho did not "
                                 "reduce to 0")
    residual = _pointwise(data, rho, field, (*q, *u))
    if not residual <= POINTWISE_TOLERANCE:
        return fail("undecided", f"the candidate rho = {sp.sstr(rho)}: pointwise residual {residual:.3g} above "
                                 f"{POINTWISE_TOLERANCE:g}")
    reason = (f"rho = {sp.sstr(rho)} in the coordinates (q, u), u = ({', '.join(map(str, u))}): div(rho f)/rho "
              f"vanishes identically{' (parameters symbolic)' if data.parameters else ''} and pointwise "
              f"(max relative residual {residual:.1e} at "
              f"{POINTWISE_STATES} random states){note}")
    return "found", rho, u, dependent, reason, residual, time.perf_counter() - start


def _gradient(data: LagrangianData, B: sp.Matrix, c: list[sp.Expr], points, float_points) -> tuple[sp.Matrix, str]:
    """g = ∇ ln ρ from the conditions Xⱼ φ = −cⱼ and their brackets; raises :class:`_Failed`."""
    q, n = data.q, len(data.q)
    fields = [(B[:, j], tidy(-c[j]), f"X{j + 1}") for j in range(B.shape[1])]
    rows = [f for f in fields if _rank([f[0].T], points) > 0]
    frontier = list(rows)
    base = list(rows)
    for _ in range(MAX_BRACKET_DEPTH):
        if _rank([r[0].T for r in rows], points) >= n or not frontier:
            break
        new: list[tuple[sp.Matrix, sp.Expr, str]] = []
        for (X, dX, nX), (Y, dY, nY) in itertools.product(base, frontier):
            if nX == nY:
                continue
            Z = _bracket(X, Y, q)
            if _rank([r[0].T for r in rows + new] + [Z.T], points) > _rank([r[0].T for r in rows + new], points):
                new.append((Z, tidy(_apply(X, dY, q) - _apply(Y, dX, q)), f"[{nX}, {nY}]"))
        rows += new
        frontier = new
    note = ""
    if _rank([r[0].T for r in rows], points) < n:
        assumed = []
        for i in reversed(range(n)):
            e = sp.Matrix([1 if j == i else 0 for j in range(n)])
            if _rank([r[0].T for r in rows] + [e.T], points) > _rank([r[0].T for r in rows], points):
                rows.append((e, sp.Integer(0), f"d/d{q[i]}"))
                assumed.append(str(q[i]))
        note = (f" (the brackets of the columns of B do not span: rho was sought independent of "
                f"{', '.join(reversed(assumed))})")
    chosen: list = []
    for r in rows:
        if _rank([x[0].T for x in chosen + [r]], points) > len(chosen):
            chosen.append(r)
        if len(chosen) == n:
            break
    R = sp.Matrix.vstack(*(r[0].T for r in chosen))
    g = _solve(R, sp.Matrix([r[1] for r in chosen]), float_points)
    status = "undecided" if note else "none"
    where = " at the parameters' values" if data.parameters else ""
    for X, d, name in rows:
        if any(X is x[0] for x in chosen):
            continue
        if _zero(sum((X[i] * g[i] for i in range(n)), sp.Integer(0)) - d, data, points) is False:
            raise _Failed(status, f"no invariant measure rho(q) dq du: the conditions on g = grad ln rho are "
                                  f"inconsistent: {name}(ln rho) as required differs from its value by the "
                                  f"conditions {', '.join(r[2] for r in chosen)}{where}{note}")
    for i, j in itertools.combinations(range(n), 2):
        curl = tidy(sp.diff(g[j], q[i]) - sp.diff(g[i], q[j]))
        verdict = _zero(curl, data, points)
        if verdict is False:
            if curl.has(sp.sin, sp.cos) and sp.count_ops(curl) <= 100:
                curl = sp.trigsimp(curl)  # for the reason text only
            shown = f" (the difference is {sp.sstr(curl)})" if len(sp.sstr(curl)) <= 200 else ""
            raise _Failed(status, f"no invariant measure rho(q) dq du: the conditions X_j(ln rho) = -c_j and their "
                                  f"brackets ({', '.join(r[2] for r in chosen)}) determine g = grad ln rho, and g is "
                                  f"not closed: d g_{q[j]}/d{q[i]} != d g_{q[i]}/d{q[j]}{where}{shown}{note}")
        if verdict is None:
            raise _Failed("undecided", f"closedness of grad ln rho (d/d{q[i]} vs d/d{q[j]}) not decided{note}")
    return g, note


def _rational_antiderivative(expr: sp.Expr, x: sp.Symbol) -> sp.Expr | None:
    """∫ expr dx when expr is a rational function of x, or R(sin x) cos x, or R(cos x) sin x (R rational):
    by :func:`sympy.integrals.rationaltools.ratint` (Hermite reduction and Lazard–Rioboo–Trager, a bounded algorithm),
    after the substitution s = sin x or c = cos x; None for any other integrand."""
    if expr.is_rational_function(x):
        return ratint(sp.cancel(expr), x)
    t = sp.Dummy("t")
    for f, df in ((sp.sin(x), sp.cos(x)), (sp.cos(x), -sp.sin(x))):
        candidate = sp.cancel(expr / df).subs(f, t)
        if f == sp.sin(x):
            candidate = candidate.subs(sp.cos(x) ** 2, 1 - t**2)
        else:
            candidate = candidate.subs(sp.sin(x) ** 2, 1 - t**2)
        if not candidate.has(x) and candidate.is_rational_function(t):
            return ratint(sp.cancel(candidate), t).subs(t, f)
    return None


def _antiderivative(expr: sp.Expr, x: sp.Symbol) -> sp.Expr:
    """∫ expr dx by a bounded algorithm (:func:`_rational_antiderivative`), else by sympy's ``integrate``
    (rule-based, ``manual``) when the integrand has at most :data:`MAX_INTEGRATE_OPS` operations: a limit on
    the work, not a clock (sympy's heuristic integrators have no bound: Veselova's ln ρ part took minutes).

    Raises
    ------
    _Failed
        Not integrated (the reason names what was tried, or the limit).
    """
    found = _rational_antiderivative(expr, x)
    if found is not None:
        return found
    why = over(operations(expr), MAX_INTEGRATE_OPS, "MAX_INTEGRATE_OPS", "sympy's integral")
    if why is not None:
        raise _Failed("undecided", f"grad ln rho is closed but its d/d{x} part is not a rational function of {x}, "
                                   f"sin({x}) or cos({x}), and {why}")
    term = sp.integrate(expr, x, manual=True)
    if term.has(sp.Integral):
        raise _Failed("undecided", f"grad ln rho is closed but its d/d{x} part could not be integrated")
    return term


def _integrate(data: LagrangianData, g: sp.Matrix, points) -> sp.Expr:
    """φ with ∇φ = g (g closed), integrated coordinate by coordinate (:func:`_antiderivative`) and checked."""
    q = data.q
    phi = sp.Integer(0)
    for i, qi in enumerate(q):
        rest = tidy(g[i] - sp.diff(phi, qi))
        if rest != 0:
            phi += _antiderivative(rest, qi)
    point = sample_points(data)[0]  # log|f| for a log f negative there: the same gradient, a real density

    def real_log(argument: sp.Expr) -> sp.Expr:
        value = number(argument, point)
        return sp.log(-argument) if value is not None and value < 0 else sp.log(argument)

    phi = phi.replace(sp.log, real_log)
    for i, qi in enumerate(q):
        if _zero(sp.diff(phi, qi) - g[i], data, points) is not True:
            raise _Failed("undecided", f"ln rho integrated from its gradient does not reproduce d/d{qi}")
    return phi


def _pointwise(data: LagrangianData, rho: sp.Expr, field: tuple[sp.Expr, ...], x: tuple[sp.Symbol, ...]) -> float:
    """max over random states of |Σᵢ ∂(ρ fᵢ)/∂xᵢ| / Σᵢ |∂(ρ fᵢ)/∂xᵢ| (parameters' values, 30 digits)."""
    rng = np.random.default_rng(20240705)
    pars = {s: sp.Float(val, 30) for s, val in data.parameter_values.items()}
    terms = [sp.diff(rho * f, xi).xreplace(pars) for f, xi in zip(field, x)]
    worst = 0.0
    for _ in range(POINTWISE_STATES):
        state = dict(zip(x, (sp.Float(float(r), 30) for r in rng.uniform(0.15, 0.85, len(x)))))
        values = [complex(t.xreplace(state).evalf(30)) for t in terms]
        scale = sum(abs(val) for val in values)
        worst = max(worst, abs(sum(values)) / scale if scale > 0 else 0.0)
    return float(worst)


def measure_verdict(data: LagrangianData) -> MeasureVerdict:
    """Whether the reduced flow of ``data`` on its constraint manifold has an invariant measure ρ(q) dq du.

    Parameters
    ----------
    data : LagrangianData
        From :func:`nonholonomic.lagrangian.lagrangian_data` (parsed and checked).

    Returns
    -------
    MeasureVerdict
        ``found`` only with the symbolic and pointwise proof; ``none`` only with an obstruction shown
        non-zero at the parameters' values; else ``undecided`` with the reason.
    """
    eqs = derive(data)
    if not eqs.closed_form:
        return _sampled(data, f"the equations of motion were eliminated without cancellation ({eqs.elimination})")
    outcome = bounded.run(("lagrangian.measure", data), _search, (data,))
    if outcome.status != "done":
        return MeasureVerdict("undecided", None, (), (), f"sympy could not decide: {outcome.message}", None,
                              outcome.seconds)
    return MeasureVerdict(*outcome.value)


def _implied(data: LagrangianData, N: sp.Expr, shape: tuple[int, ...], L_star: sp.Expr) -> tuple:
    """The verdict's fields for the density ``N det M* |det ∂q̇_s/∂u|`` (see :func:`implied_by_multiplier`)."""
    start = time.perf_counter()
    points = _exact_points(data)
    flow = _flow(data)
    shape_velocities = [data.v[i] for i in shape]
    mass = sp.Matrix(2, 2, lambda i, j: sp.diff(L_star, shape_velocities[i], shape_velocities[j]))
    on = dict(flow.dependent)
    in_u = [tidy(sp.sympify(s).xreplace(on)) for s in shape_velocities]
    jacobian = sp.Matrix(2, len(flow.u), lambda i, j: sp.diff(in_u[i], flow.u[j])).det() if len(flow.u) == 2 else 0
    if jacobian == 0:
        return ("undecided", None, flow.u, flow.dependent, "the shape velocities are not coordinates of the "
                "constraint manifold's velocities", None, time.perf_counter() - start)
    rho = tidy(N * mass.det() * jacobian)
    point = sample_points(data)[0]
    value = number(rho, point)
    if value is not None and value < 0:
        rho = -rho
    ln_rho = sp.expand_log(sp.log(rho), force=True)
    bracket = flow.div + sum((sp.diff(ln_rho, qi) * fi for qi, fi in zip(data.q, flow.qdot)), sp.Integer(0))
    how = (f"implied by Theorem 1's reducing multiplier N = {sp.sstr(N)}: rho = N det M* |det d(q_dot_shape)/du| "
           f"with M* = d2 L*/d q_dot_shape^2 (Theorem 1's proof read backwards)")
    if _zero(bracket, data, points) is not True:
        return ("undecided", None, flow.u, flow.dependent, f"{how}: div(rho f)/rho did not reduce to 0", None,
                time.perf_counter() - start)
    residual = _pointwise(data, rho, flow.field, (*data.q, *flow.u))
    if not residual <= POINTWISE_TOLERANCE:
        return ("undecided", None, flow.u, flow.dependent, f"{how}: pointwise residual {residual:.3g} above "
                f"{POINTWISE_TOLERANCE:g}", None, time.perf_counter() - start)
    reason = (f"rho = {sp.sstr(rho)} in the coordinates (q, u), u = ({', '.join(map(str, flow.u))}), {how}; "
              f"div(rho f)/rho vanishes identically and pointwise (max relative residual {residual:.1e} at "
              f"{POINTWISE_STATES} random states)")
    return "found", rho, flow.u, flow.dependent, reason, residual, time.perf_counter() - start


def implied_by_multiplier(data: LagrangianData, N: sp.Expr, shape: tuple[int, ...], L_star: sp.Expr) -> MeasureVerdict:
    """The invariant measure Theorem 1's reducing multiplier implies, proven as the search's are.

    Theorem 1's proof (eq. 2704-10): the reduced system in (q_s, P), P = ∂L*/∂q̇_s, has the invariant measure
    ρ(q) dP dq exactly when ∂ρ/∂q₁ = ρ A₂, ∂ρ/∂q₂ = −ρ A₁, the equations N solves; so N(q) dP dq is invariant. In
    (q_s, q̇_s), dP = det M* dq̇_s, M* = ∂²L*/∂q̇_s²; the cyclic coordinates' velocities are functions of
    (q_s, q̇_s), so N det M* dq dq̇_s is invariant for the user's flow on the constraint manifold, and in the
    search's coordinates (q, u) the density is N det M* |det ∂q̇_s/∂u|. Proven (div(ρ f)/ρ cancelled on the
    manifold) and checked pointwise before it is ``found``; else ``undecided`` with the reason.

    Parameters
    ----------
    data : the user's system.
    N : Theorem 1's reducing multiplier, in the user's coordinates.
    shape : indices of the shape coordinates q₁, q₂.
    L_star : the reduced Lagrangian L* (its velocity terms) in the user's symbols.
    """
    outcome = bounded.run(("lagrangian.implied_measure", data, N), _implied, (data, N, shape, L_star))
    if outcome.status != "done":
        return MeasureVerdict("undecided", None, (), (), f"sympy could not decide: {outcome.message}", None,
                              outcome.seconds)
    return MeasureVerdict(*outcome.value)


def _sampled_fields(data: LagrangianData, why: str) -> tuple:
    dependent = _dependent_columns(data)
    found = sampled_measure(data, dependent)
    u = tuple(data.v[j] for j in range(len(data.q)) if j not in dependent)
    reason = f"{why}: no closed form of div f, so an ansatz was fitted on sampled states instead: {found.reason}"
    if found.status == "found" and found.density is not None:
        point = sample_points(data)[0]
        density = found.density.replace(sp.Abs, lambda a: a if (number(a, point) or 1.0) > 0 else -a)
        return "found", density, u, found.dependent, reason, None, found.seconds
    return "undecided", None, u, found.dependent, reason, None, found.seconds


def _sampled(data: LagrangianData, why: str) -> MeasureVerdict:
    """The verdict of the sampled ansatz (:mod:`nonholonomic.lagrangian.sampled_search`) for a system without a
    closed form of its field (an Abs from sqrt(sin^2 ...) taken with the sign it has at the sample point: a
    density is defined up to a constant factor on each region where it does not vanish)."""
    outcome = bounded.run(("lagrangian.sampled_measure", data), _sampled_fields, (data, why))
    if outcome.status != "done":
        return MeasureVerdict("undecided", None, (), (), f"{why}; the sampled ansatz failed: {outcome.message}", None,
                              outcome.seconds)
    return MeasureVerdict(*outcome.value)
