"""The equations of motion of a user's Lagrangian system with constraints linear and homogeneous in the
velocities: the Lagrange–d'Alembert equations with the multipliers eliminated.

Lagrange–d'Alembert principle (the general form behind the paper's reduced 2-DOF eq. (2704-7); e.g.
Neimark & Fufaev, *Dynamics of nonholonomic systems*, ch. III; Bloch, *Nonholonomic mechanics and
control*, §5.2): for L(q, q̇, t) and constraints A(q, t) q̇ = 0 (k rows, n coordinates),

    d/dt ∂L/∂q̇ − ∂L/∂q = Aᵀ λ,    A(q, t) q̇ = 0.

With L at most quadratic in q̇, d/dt ∂L/∂q̇ = M q̈ + (∂²L/∂q̇∂q) q̇ + ∂²L/∂q̇∂t, so

    M(q) q̈ + h(q, q̇, t) = Aᵀ λ,    M = ∂²L/∂q̇∂q̇,    h = (∂²L/∂q̇∂q) q̇ + ∂²L/∂q̇∂t − ∂L/∂q,

and the constraint, differentiated along the motion, A q̈ + Ȧ q̇ = 0 (Ȧ = Σⱼ ∂A/∂qⱼ q̇ⱼ + ∂A/∂t).
Eliminating the multipliers::

    λ = (A M⁻¹ Aᵀ)⁻¹ (A M⁻¹ h − Ȧ q̇),    q̈ = M⁻¹ (Aᵀ λ − h).

The differentiated constraint is what holds the motion on A q̇ = 0: the flow keeps A q̇ constant, so it
stays zero from initial data on the constraint. The constraint forces Aᵀλ do no work on the motion
(q̇ᵀAᵀλ = 0), so E = (q̇, ∂L/∂q̇) − L is an integral when L has no explicit t (dE/dt = −∂L/∂t).

M⁻¹ is never formed: M is solved once for the k + 1 right-hand sides Aᵀ and h by Gaussian elimination in
exact rational-function arithmetic, sin and cos of a coordinate as generators with sin² + cos² = 1
(:mod:`nonholonomic.lagrangian.fractions`: every entry one reduced fraction after every step); an
expression that does not fit it falls back to LU on expression trees, each entry cancelled (``tidy``);
a system too large for either (a rattleback, Chaplygin's sphere) is eliminated without cancellation
(:func:`_plain_solve`: correct and small as a DAG, but no closed form for the structure searches).
Which path is taken is decided by deterministic measures of the work, never by a clock: the operations of
M, h and A (:data:`FRACTIONS_MAX_OPS`) and the terms an entry reaches during the exact elimination
(:data:`~nonholonomic.lagrangian.fractions.MAX_FRACTION_TERMS`); the same system takes the same path on
every machine. The derivation runs under :func:`nonholonomic.bounded.run` (shared, cached, a safety cap).
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import sympy as sp

from nonholonomic import bounded
from nonholonomic.lagrangian.checks import mass_matrix, number, numeric_matrix, sample_points
from nonholonomic.lagrangian.parse import LagrangianData

#: M, h and A with more operations than this are eliminated without cancellation (the Suslov problem in Euler
#: angles has 310, a rattleback with a paraboloid bottom 2400: a single gcd of its fractions takes minutes).
FRACTIONS_MAX_OPS = 1000
#: An energy larger than this (sympy operations) is only expanded, not cancelled.
TIDY_ENERGY_MAX_OPS = 300
#: An entry larger than this (sympy operations) is only brought together, not cancelled.
CANCEL_MAX_OPS = 4000


class DerivationError(RuntimeError):
    """Sympy failed on the symbolic derivation (the reason says where)."""


@dataclass(frozen=True)
class EquationsOfMotion:
    """The Lagrange–d'Alembert equations of a user's system, solved for q̈ and λ.

    Attributes
    ----------
    q, qdot : tuple of sympy.Symbol
        The state (q, q̇): coordinates and velocities.
    t : sympy.Symbol
        The time (appears in the expressions only if L or the constraints use it).
    parameters : tuple of sympy.Symbol
        The parameters, in the user's order; ``values`` are their values.
    values : tuple of float
    qddot : tuple of sympy.Expr
        q̈ = M⁻¹(Aᵀλ − h) as functions of (q, q̇, t, parameters).
    multipliers : tuple of sympy.Expr
        λ = (A M⁻¹ Aᵀ)⁻¹ (A M⁻¹ h − Ȧ q̇), one per constraint.
    energy : sympy.Expr or None
        E = (q̇, ∂L/∂q̇) − L, an integral when L has no explicit t (else None).
    L : sympy.Expr
        The Lagrangian.
    mass_matrix : sympy.ImmutableMatrix
        M = ∂²L/∂q̇∂q̇.
    A : sympy.ImmutableMatrix
        The constraint matrix A(q, t), k × n.
    constraints : tuple of sympy.Expr
        The constraint functions A q̇ (each = 0 on the motion).
    seconds : float
        How long the derivation took (a timing field).
    closed_form : bool
        Whether q̈ is a cancelled closed form (else the plain elimination's DAG).
    elimination : str
        Why the plain elimination was taken (a deterministic size measure), or "" for a closed form.
    """

    q: tuple[sp.Symbol, ...]
    qdot: tuple[sp.Symbol, ...]
    t: sp.Symbol
    parameters: tuple[sp.Symbol, ...]
    values: tuple[float, ...]
    qddot: tuple[sp.Expr, ...]
    multipliers: tuple[sp.Expr, ...]
    energy: sp.Expr | None
    L: sp.Expr
    mass_matrix: sp.ImmutableMatrix
    A: sp.ImmutableMatrix
    constraints: tuple[sp.Expr, ...]
    seconds: float
    closed_form: bool = True
    """False when the elimination ran without cancellation (:func:`_plain_solve`): q̈ is correct but no
    closed form the structure searches could work on."""
    elimination: str = ""

    @property
    def state(self) -> tuple[sp.Symbol, ...]:
        """``(q, q̇)``."""
        return (*self.q, *self.qdot)

    @property
    def rhs(self) -> tuple[sp.Expr, ...]:
        """The first-order field ``d(q, q̇)/dt = (q̇, q̈)``."""
        return (*self.qdot, *self.qddot)

    @property
    def time_dependent(self) -> bool:
        """Whether the field depends on t explicitly."""
        return any(e.has(self.t) for e in self.qddot)


def _pythagoras(expr: sp.Expr) -> sp.Expr:
    """A polynomial ``expr`` with cos²x written 1 − sin²x for every angle x whose sine and cosine both
    appear (its normal form modulo sin²x + cos²x − 1: degree ≤ 1 in cos x)."""
    for x in sorted({f.args[0] for f in expr.atoms(sp.sin)} & {f.args[0] for f in expr.atoms(sp.cos)},
                    key=sp.default_sort_key):
        s, c = sp.Dummy("s"), sp.Dummy("c")
        poly = sp.expand(expr.xreplace({sp.sin(x): s, sp.cos(x): c}))
        if poly.has(x):  # x elsewhere (sin(2x), x itself): leave as is
            continue
        powers = sp.collect(poly, c, evaluate=False)
        if max((sp.degree(p, c) for p in powers), default=0) < 2:
            continue
        rest = sp.expand(sp.Add(*(coefficient * (1 - s**2)**(int(sp.degree(p, c)) // 2) * c**(int(sp.degree(p, c)) % 2)
                                  for p, coefficient in powers.items())))
        expr = rest.xreplace({s: sp.sin(x), c: sp.cos(x)})
    return expr


def tidy(expr: sp.Expr) -> sp.Expr:
    """``expr`` as one fraction with common factors cancelled (``cancel``), sin² + cos² = 1 used in its
    numerator and denominator; only brought together (``together``) when it has more than
    :data:`CANCEL_MAX_OPS` operations."""
    if expr == 0:
        return sp.Integer(0)
    together = sp.together(expr)
    if sp.count_ops(together) > CANCEL_MAX_OPS:
        return together
    num, den = sp.fraction(sp.cancel(together))
    if num.has(sp.sin) or den.has(sp.sin):
        num, den = _pythagoras(num), _pythagoras(den)
        return sp.cancel(num / den)
    return num / den


def _zero_test(points: list[dict[sp.Symbol, float]], scales: list[float]):
    """Whether a pivot candidate (a function of q, t and the parameters) vanishes: structurally after
    :func:`tidy`, or numerically at every sample point, relative to the matrix's largest entry there
    (an identity such as sin² + cos² − 1 that ``cancel`` does not see must not become a pivot)."""
    def is_zero(expr: sp.Expr) -> bool:
        expr = tidy(expr)
        if expr == 0:
            return True
        values = [number(expr, point) for point in points]
        return bool(values) and all(value is not None and abs(value) <= 1e-12 * scale
                                    for value, scale in zip(values, scales))

    return is_zero


def _solve(M: sp.Matrix, B: sp.Matrix, points: list[dict[sp.Symbol, float]]) -> sp.Matrix:
    """``M⁻¹ B`` by LU with row pivoting (as ``sympy.Matrix.LUsolve``), tidying every entry."""
    n = M.shape[0]
    numeric = [numeric_matrix(M, point) for point in points]
    usable = [(p, float(np.max(np.abs(m)))) for p, m in zip(points, numeric) if m is not None]
    is_zero = _zero_test([p for p, _ in usable], [s for _, s in usable])
    lu, perm = M.LUdecomposition_Simple(iszerofunc=is_zero, simpfunc=tidy)
    b = B.permute_rows(perm).as_mutable()
    for i in range(n):  # forward: unit lower triangle
        for j in range(i):
            scale = lu[i, j]
            b.zip_row_op(i, j, lambda x, y, scale=scale: tidy(x - scale * y))
    for i in reversed(range(n)):  # backward: upper triangle
        for j in range(i + 1, n):
            scale = lu[i, j]
            b.zip_row_op(i, j, lambda x, y, scale=scale: tidy(x - scale * y))
        pivot = lu[i, i]
        b.row_op(i, lambda x, _, pivot=pivot: tidy(x / pivot))
    return b


@lru_cache(maxsize=64)
def dynamics_terms(data: LagrangianData) -> tuple[sp.ImmutableMatrix, tuple[sp.Expr, ...], sp.ImmutableMatrix,
                                                  tuple[sp.Expr, ...]]:
    """M, h, A and Ȧ q̇ (each constraint differentiated along the motion at fixed q̇); cached per system."""
    q, v, t, L = data.q, data.v, data.t, data.L
    M = mass_matrix(data)
    p = [sp.diff(L, vi) for vi in v]
    h = [sum((sp.diff(p[i], qj) * vj for qj, vj in zip(q, v)), sp.Integer(0)) + sp.diff(p[i], t) - sp.diff(L, q[i])
         for i in range(len(q))]
    Adot_v = [sum((sp.diff(f, qj) * vj for qj, vj in zip(q, v)), sp.Integer(0)) + sp.diff(f, t)
              for f in data.constraints]
    return sp.ImmutableMatrix(M), tuple(h), sp.ImmutableMatrix(data.A), tuple(Adot_v)


def _derive_in_fractions(data: LagrangianData) -> tuple[tuple[sp.Expr, ...], tuple[sp.Expr, ...]] | None:
    """q̈ and λ in exact rational-function arithmetic (:mod:`nonholonomic.lagrangian.fractions`); None when
    an expression does not fit it (a constant such as pi, a function of a function); raises
    :class:`~nonholonomic.lagrangian.fractions.TooLarge` for a system too large for it
    (:data:`FRACTIONS_MAX_OPS`, or an entry past :data:`~nonholonomic.lagrangian.fractions.MAX_FRACTION_TERMS`)."""
    from nonholonomic.lagrangian.fractions import TooLarge, fractions_for

    M, h, A, Adot_v = dynamics_terms(data)
    n, k = len(data.q), A.shape[0]
    exprs = [*M, *h, *A, *Adot_v]
    ops = sum(sp.count_ops(e) for e in (*M, *h, *A))
    if ops > FRACTIONS_MAX_OPS:  # one gcd of such fractions can take minutes
        raise TooLarge(f"M, h and A have {ops:,} operations > max {FRACTIONS_MAX_OPS:,} (FRACTIONS_MAX_OPS)")
    try:
        F = fractions_for(exprs, data.q, (*data.v, data.t, *data.parameters), sample_points(data))
        Mf = [[F.element(M[i, j]) for j in range(n)] for i in range(n)]
        hf = [F.element(e) for e in h]
        Af = [[F.element(A[a, i]) for i in range(n)] for a in range(k)]
        Adf = [F.element(e) for e in Adot_v]
    except (sp.polys.polyerrors.PolynomialError, sp.polys.polyerrors.CoercionFailed, ValueError, TypeError):
        return None
    X = F.solve(Mf, [[*(Af[a][i] for a in range(k)), hf[i]] for i in range(n)])  # (M⁻¹Aᵀ | M⁻¹h)
    W, u = [row[:k] for row in X], [row[k] for row in X]
    if k:
        zero = F.field.zero
        S = [[F.reduce(sum((Af[a][i] * W[i][b] for i in range(n)), zero)) for b in range(k)] for a in range(k)]
        rhs = [[F.reduce(sum((Af[a][i] * u[i] for i in range(n)), zero) - Adf[a])] for a in range(k)]
        lam = [row[0] for row in F.solve(S, rhs)]
        qddot = [F.reduce(sum((W[i][a] * lam[a] for a in range(k)), zero) - u[i]) for i in range(n)]
    else:
        lam, qddot = [], [-x for x in u]
    return tuple(F.expr(e) for e in qddot), tuple(F.expr(e) for e in lam)


def _plain_solve(M: list[list[sp.Expr]], B: list[list[sp.Expr]]) -> list[list[sp.Expr]]:
    """``M⁻¹ B`` by Gaussian elimination without any cancellation (no pivoting: M and A M⁻¹ Aᵀ are
    positive definite for a kinetic energy, their leading minors never vanish). The entries share their
    subexpressions: a tree that grows with n, a DAG of O(n³) operations that heyoka's decomposition and
    ``cse`` keep small."""
    m = len(M)
    M, B = [row[:] for row in M], [row[:] for row in B]
    for c in range(m):
        for r in range(c + 1, m):
            if M[r][c] == 0:
                continue
            factor = M[r][c] / M[c][c]
            M[r] = [M[r][j] - factor * M[c][j] for j in range(m)]
            B[r] = [B[r][j] - factor * B[c][j] for j in range(len(B[r]))]
    X: list[list[sp.Expr]] = [[] for _ in range(m)]
    for r in reversed(range(m)):
        row = B[r][:]
        for j in range(r + 1, m):
            if M[r][j] != 0:
                row = [row[t] - M[r][j] * X[j][t] for t in range(len(row))]
        X[r] = [x / M[r][r] for x in row]
    return X


def plain_field(data: LagrangianData) -> tuple[sp.Expr, ...]:
    """q̈ = M⁻¹(Aᵀλ − h), λ = (A M⁻¹ Aᵀ)⁻¹(A M⁻¹ h − Ȧ q̇), by :func:`_plain_solve` on the whole n × n system:
    no cancellation, no choice of dependent velocities, so it is built in milliseconds for any system (the
    rattleback: 0.07 s against 1.3 s for :func:`_derive_plain`'s projection). The same field as
    :func:`derive`'s everywhere (it keeps A q̇ constant), but a large DAG: what a request is checked against
    (:func:`nonholonomic.systems.lagrangian.outline`), not what a job compiles."""
    M, h, A, Adot_v = dynamics_terms(data)
    n, k = len(data.q), A.shape[0]
    X = _plain_solve([[M[i, j] for j in range(n)] for i in range(n)],
                     [[*(A[a, i] for a in range(k)), h[i]] for i in range(n)])  # (M⁻¹Aᵀ | M⁻¹h)
    W, u = [row[:k] for row in X], [row[k] for row in X]
    if not k:
        return tuple(-x for x in u)
    S = [[sp.Add(*(A[a, i] * W[i][b] for i in range(n))) for b in range(k)] for a in range(k)]
    rhs = [[sp.Add(*(A[a, i] * u[i] for i in range(n))) - Adot_v[a]] for a in range(k)]
    lam = [row[0] for row in _plain_solve(S, rhs)]
    return tuple(sp.Add(*(W[i][a] * lam[a] for a in range(k))) - u[i] for i in range(n))


def dependent_columns(data: LagrangianData) -> tuple[int, ...] | None:
    """k columns of A to solve the constraints for (the dependent velocities), their minor regular at every
    sample point: a constant minor first, then the shortest, then the latest columns (the first velocities
    stay independent); None when no minor is regular at all of them."""
    n, k = len(data.q), data.A.shape[0]
    points = sample_points(data)
    candidates = []
    for columns in itertools.combinations(range(n), k):
        minor = tidy(sp.Matrix(data.A).extract(list(range(k)), list(columns)).det()) if k else sp.Integer(1)
        values = [number(minor, p) for p in points]
        if all(v is not None and abs(v) > 1e-10 for v in values):
            candidates.append((not minor.is_number, sp.count_ops(minor), tuple(-c for c in reversed(columns)),
                               columns))
    return min(candidates)[-1] if candidates else None


def _derive_plain(data: LagrangianData) -> tuple[tuple[sp.Expr, ...], tuple[sp.Expr, ...]]:
    """q̈ by the elimination without cancellation (:func:`_plain_solve`), projected onto the constraints:
    for systems whose exact elimination is too slow (a rattleback's curved bottom). With the constraints
    solved for k velocities, q̇_D = −A_D⁻¹ A_I u, and q̈ = B u̇ + c (c_D = −A_D⁻¹ Ȧ q̇, c_I = 0), the
    Lagrange–d'Alembert equations projected on the kernel of A (Bᵀ Aᵀ = 0 removes λ) are
    Bᵀ M B u̇ = −Bᵀ (h + M c): an m × m solve instead of n × n and k × k. d/dt (A q̇) = 0 everywhere, as on
    the other paths; the field is the same on the constraint manifold. Correct and small as a DAG, but no
    closed form, so the structure searches do not run on it; no multipliers."""
    M, h, A, Adot_v = dynamics_terms(data)
    n, k = len(data.q), A.shape[0]
    if not k:
        return tuple(-row[0] for row in _plain_solve([[M[i, j] for j in range(n)] for i in range(n)],
                                                     [[e] for e in h])), ()
    found = dependent_columns(data)
    if found is None:
        raise DerivationError("no k velocities can be solved for at every sample point")
    dep = list(found)
    ind = [j for j in range(n) if j not in dep]
    m = len(ind)
    AD = A.extract(list(range(k)), dep)
    gram = AD * AD.T  # A_D⁻¹ = A_Dᵀ (A_D A_Dᵀ)⁻¹: a positive definite solve needs no pivot (A_D's own may vanish)
    y = _plain_solve([[gram[a, b] for b in range(k)] for a in range(k)],
                     [[*(-A[a, j] for j in ind), -Adot_v[a]] for a in range(k)])
    solved = [[sp.Add(*(AD[a, r] * y[a][col] for a in range(k))) for col in range(m + 1)] for r in range(k)]
    B = [[sp.Integer(1 if j == ind[b] else 0) for b in range(m)] for j in range(n)]
    c = [sp.Integer(0)] * n
    for r, j in enumerate(dep):
        B[j], c[j] = solved[r][:m], solved[r][m]
    Mc = [sp.Add(*(M[i, j] * c[j] for j in dep)) for i in range(n)]
    MB = [[sp.Add(*(M[i, j] * B[j][b] for j in range(n) if B[j][b] != 0)) for b in range(m)] for i in range(n)]
    R = [[sp.Add(*(B[i][a] * MB[i][b] for i in range(n) if B[i][a] != 0)) for b in range(m)] for a in range(m)]
    rhs = [[-sp.Add(*(B[i][a] * (h[i] + Mc[i]) for i in range(n) if B[i][a] != 0))] for a in range(m)]
    u_dot = [row[0] for row in _plain_solve(R, rhs)]
    return tuple(sp.Add(*(B[j][b] * u_dot[b] for b in range(m) if B[j][b] != 0)) + c[j] for j in range(n)), ()


def _derive(data: LagrangianData) -> tuple[tuple[sp.Expr, ...], tuple[sp.Expr, ...], float, bool, str]:
    from nonholonomic.lagrangian.fractions import TooLarge

    start = time.perf_counter()
    try:
        exact = _derive_in_fractions(data)
    except TooLarge as exc:
        return (*_derive_plain(data), time.perf_counter() - start, False, str(exc))
    if exact is not None:
        return (*exact, time.perf_counter() - start, True, "")
    # an expression the fraction field cannot hold: expression trees, every entry cancelled (slower)
    M, h_list, A, Adot_list = dynamics_terms(data)
    k = A.shape[0]
    h = sp.Matrix([tidy(e) for e in h_list])
    Adot_v = sp.Matrix([tidy(e) for e in Adot_list])
    points = sample_points(data)
    X = _solve(M, A.T.row_join(h) if k else h, points)  # (M⁻¹Aᵀ | M⁻¹h)
    W, u = X[:, :k], X[:, k]
    if k:
        S = (A * W).applyfunc(tidy)  # A M⁻¹ Aᵀ
        lam = _solve(S, (A * u - Adot_v).applyfunc(tidy), points)
    else:
        lam = sp.zeros(0, 1)
    qddot = (W * lam - u).applyfunc(tidy) if k else (-u).applyfunc(tidy)
    return tuple(qddot), tuple(lam), time.perf_counter() - start, True, ""


def energy_of(data: LagrangianData) -> sp.Expr | None:
    """E = (q̇, ∂L/∂q̇) − L, or None when L depends on t explicitly (then dE/dt = −∂L/∂t)."""
    if data.L.has(data.t):
        return None
    energy = sum((vi * sp.diff(data.L, vi) for vi in data.v), sp.Integer(0)) - data.L
    return tidy(energy) if sp.count_ops(energy) <= TIDY_ENERGY_MAX_OPS else sp.expand(energy)


@lru_cache(maxsize=64)
def derive(data: LagrangianData) -> EquationsOfMotion:
    """The Lagrange–d'Alembert equations of ``data`` with the multipliers eliminated.

    Parameters
    ----------
    data : LagrangianData
        From :func:`nonholonomic.lagrangian.parse.parse_system` (checked: M regular, A of full rank).

    Returns
    -------
    EquationsOfMotion

    Raises
    ------
    DerivationError
        When sympy fails.
    nonholonomic.bounded.SafetyCapExceeded
        Still running after the safety cap (a failure of the job, not a verdict).
    """
    outcome = bounded.run(("lagrangian.derive", data), _derive, (data,))
    if outcome.status != "done":
        raise DerivationError(f"the equations of motion could not be derived: {outcome.message}")
    qddot, lam, seconds, closed_form, elimination = outcome.value
    return EquationsOfMotion(
        q=data.q, qdot=data.v, t=data.t, parameters=data.parameters, values=data.values, qddot=qddot,
        multipliers=lam, energy=energy_of(data), L=data.L, mass_matrix=sp.ImmutableMatrix(mass_matrix(data)),
        A=data.A, constraints=data.constraints, seconds=seconds, closed_form=closed_form,
        elimination=elimination)
