"""Structure of a system too large for the exact elimination (issue 33, item 4): an invariant measure ρ(q) dq du
and the integrals linear in the velocities, each fitted as an ansatz on sampled states of the constraint
manifold and verified by a randomized identity test at high precision.

The field is the plain elimination's (no closed form: Chaplygin's sphere's exact elimination has entries of 1,651
terms), compiled to numpy and mpmath. On the manifold q̇ = B(q) u (the constraints solved for the dependent
velocities as :mod:`~nonholonomic.lagrangian.measure_search` does), at :data:`SAMPLES` fixed random states:

* **measure**: ρ = P^r with P = Σ a_k b_k(q) over products of 1, sin, cos, sin², sin cos, sin³, sin² cos, sin⁴,
  sin³ cos of each angle (and powers ≤ 2 of the other coordinates), the coordinates the field does not depend on
  left out; div(ρ f) = 0 is P div f + r (∇P, q̇) = 0, linear in a for each r of :data:`EXPONENTS`. div f comes from
  complex-step derivatives (exact to rounding);
* **integrals**: F = Σ_j Σ_k c_jk b_k(q) u_j over products of 1, sin, cos, sin², sin cos of every angle;
  dF/dt = 0 is linear in c.

The null space of each linear system (singular values below :data:`NULL_TOLERANCE` of the largest) is put in
reduced row echelon form and its entries made rational (denominators ≤ :data:`MAX_DENOMINATOR`, the parameters
at their values). A candidate is kept only if it vanishes, with the field evaluated anew at :data:`VERIFY_DIGITS`
digits (the derivatives by a complex step of 10^-60), at :data:`VERIFY_POINTS` other random states to within
10^-35 of its terms: a randomized identity test. The claim it supports is stated as such (an analytic function
vanishing at random points is zero but with negligible probability), not as a symbolic proof; the job then checks
the measure and each integral along its trajectory like any other. A candidate not in the ansatz is not found:
the verdict is then ``undecided``, saying what was searched.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from fractions import Fraction
from functools import lru_cache
from typing import Any

import mpmath
import numpy as np
import sympy as sp

from nonholonomic.lagrangian.equations import derive, tidy
from nonholonomic.lagrangian.parse import LagrangianData
from nonholonomic.lagrangian.regular_forms import dependent_velocities
from nonholonomic.numerics.precision import working_digits

__all__ = ["SampledIntegrals", "SampledMeasure", "sampled_integrals", "sampled_measure"]

#: ρ = P^r G^s is sought for these (r, s), in this order (G = det(Bᵀ M B), the kinetic matrix in u).
FORMS = tuple((Fraction(r), Fraction(s)) for r, s in (
    (1, 0), (-1, 0), (2, 0), (-2, 0), ("1/2", 0), ("-1/2", 0), (1, "-1/2"), (1, "1/2"), (1, -1), (1, 1)))
#: States the linear systems are fitted on (at least 1.5 per unknown).
SAMPLES = 400
#: A singular value below this fraction of the largest spans the null space.
NULL_TOLERANCE = 1e-9
#: Largest denominator of a coefficient made rational.
MAX_DENOMINATOR = 10**6
#: States of the randomized identity test, and its working precision.
VERIFY_POINTS = 8
VERIFY_DIGITS = 80
#: A residual at most this fraction of its terms' size counts as zero in the identity test.
VERIFY_ZERO = 1e-35
#: Most unknowns of one linear system.
MAX_UNKNOWNS = 600


def _angles(data: LagrangianData) -> set[sp.Symbol]:
    """The coordinates inside sin/cos of L or a constraint."""
    exprs = (data.L, *data.constraints)
    return {s for e in exprs for f in e.atoms(sp.sin, sp.cos) for s in f.free_symbols if s in data.q}


def _factors(x: sp.Symbol, angle: bool, degree: int) -> list[sp.Expr]:
    """1, sin, cos, sin², sin cos, ... up to ``degree`` for an angle (cos² written 1 − sin²), else 1, x, ..."""
    if not angle:
        return [x**d for d in range(degree + 1)]
    s, c = sp.sin(x), sp.cos(x)
    return [sp.Integer(1)] + [s**d * c**e for d in range(degree + 1) for e in (0, 1) if 0 < d + e <= degree]


def _basis(coordinates: list[tuple[sp.Symbol, bool]], degree: int) -> list[sp.Expr]:
    terms: list[sp.Expr] = [sp.Integer(1)]
    for x, angle in coordinates:
        terms = [t * f for t in terms for f in _factors(x, angle, degree)]
    return terms


class _Manifold:
    """The user's flow on the constraint manifold in (q, u), numerically (numpy, complex-step-able) and at high
    precision (mpmath); u the velocities left after solving the constraints for ``dependent``."""

    def __init__(self, data: LagrangianData, dependent: tuple[int, ...]) -> None:
        self.data = data
        n = len(data.q)
        self.dep, self.ind = list(dependent), [j for j in range(n) if j not in dependent]
        self.p = [float(v) for v in data.values]
        self.p_fractions = [Fraction(str(sp.nsimplify(v, rational=True))) for v in data.values]
        args = [*data.q, *data.v, *data.parameters]
        qddot = list(derive(data).qddot)
        self._qddot = sp.lambdify(args, qddot, modules="numpy", cse=True)
        self._qddot_mp = sp.lambdify(args, qddot, modules="mpmath", cse=True)
        A = sp.Matrix(data.A)
        self._A = sp.lambdify([*data.q, *data.parameters], list(A), modules="numpy")
        mass = list(sp.hessian(data.L, data.v))
        self._M = sp.lambdify([*data.q, *data.parameters], mass, modules="numpy")
        self._M_mp = sp.lambdify([*data.q, *data.parameters], mass, modules="mpmath")
        self._A_mp = sp.lambdify([*data.q, *data.parameters], A, modules="mpmath")

    def velocities(self, q: np.ndarray, u: np.ndarray) -> np.ndarray:
        """q̇ at rows of (q, u) (complex allowed)."""
        n, k = q.shape[1], len(self.dep)
        v = np.zeros((len(q), n), dtype=np.result_type(q, u))
        v[:, self.ind] = u
        if k:
            entries = [np.broadcast_to(np.asarray(e, dtype=v.dtype), (len(q),)) for e in self._A(*q.T, *self.p)]
            A = np.stack(entries, axis=1).reshape(len(q), k, n)
            rhs = -np.einsum("sij,sj->si", A[:, :, self.ind], u)
            v[:, self.dep] = np.linalg.solve(A[:, :, self.dep], rhs[..., None])[..., 0]
        return v

    def on_manifold(self) -> tuple[tuple[sp.Symbol, sp.Expr], ...]:
        """The dependent velocities as functions of (q, u), symbolically."""
        return dependent_velocities(self.data, self.dep)

    def kinetic_determinant_symbolic(self) -> sp.Expr:
        """det(Bᵀ M B) as an expression of q."""
        data = self.data
        on = dict(self.on_manifold())
        velocities = [on.get(v, v) for v in data.v]
        u = [data.v[j] for j in self.ind]
        B = sp.Matrix(len(data.v), len(u), lambda i, j: sp.diff(velocities[i], u[j]))
        return tidy(sp.expand((B.T * sp.hessian(data.L, data.v) * B).det()))

    def kinetic_determinant(self, q: np.ndarray) -> np.ndarray:
        """det(Bᵀ M B) at rows of q: the kinetic energy's matrix in u on the manifold (complex allowed)."""
        n, m = q.shape[1], len(self.ind)
        columns = np.stack([self.velocities(q, np.broadcast_to(np.eye(m, dtype=q.dtype)[c], (len(q), m)))
                            for c in range(m)], axis=2)  # B: (rows, n, m)
        M = np.stack([np.broadcast_to(np.asarray(e, dtype=q.dtype), (len(q),)) for e in self._M(*q.T, *self.p)],
                     axis=1).reshape(len(q), n, n)
        return np.linalg.det(np.einsum("sim,sij,sjk->smk", columns, M, columns))

    def log_kinetic_rate(self, q: np.ndarray, qdot: np.ndarray, h: float = 1e-30) -> np.ndarray:
        """d/dt ln det(Bᵀ M B) along q̇, by a complex step in the direction q̇."""
        return (np.log(self.kinetic_determinant(q + 1j * h * qdot)).imag) / h

    def log_kinetic_rate_mp(self, q: list, qdot: list) -> Any:
        h = mpmath.mpf(10) ** -60
        qs = [x + 1j * h * v for x, v in zip(q, qdot)]
        n, m = len(q), len(self.ind)
        columns = []
        for c in range(m):
            v, _ = self.field_mp(qs, [mpmath.mpf(1 if j == c else 0) for j in range(m)], velocities_only=True)
            columns.append(v)
        M = self._M_mp(*qs, *self.p_exact())
        K = mpmath.matrix(m, m)
        for a in range(m):
            for b in range(m):
                K[a, b] = sum(columns[a][i] * M[i * n + j] * columns[b][j] for i in range(n) for j in range(n))
        return mpmath.im(mpmath.log(mpmath.det(K))) / h

    def field(self, q: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(q̇, u̇) at rows of (q, u)."""
        v = self.velocities(q, u)
        acc = np.array([np.broadcast_to(a, (len(q),)) for a in self._qddot(*q.T, *v.T, *self.p)]).T
        return v, acc[:, self.ind]

    def divergence(self, q: np.ndarray, u: np.ndarray, h: float = 1e-30) -> np.ndarray:
        """div f in (q, u) by complex steps (no cancellation: exact to rounding)."""
        total = np.zeros(len(q))
        n = q.shape[1]
        for i in range(n + len(self.ind)):
            dq, du = np.zeros(q.shape, complex), np.zeros(u.shape, complex)
            (dq if i < n else du)[:, i if i < n else i - n] = 1j * h
            qdot, udot = self.field(q + dq, u + du)
            total += (qdot[:, i] if i < n else udot[:, i - n]).imag / h
        return total

    def p_exact(self) -> list:
        """The parameters' values as exact rationals, at mpmath's current precision."""
        return [mpmath.mpf(f.numerator) / f.denominator for f in self.p_fractions]

    def field_mp(self, q: list, u: list, velocities_only: bool = False) -> tuple[list, list]:
        """(q̇, u̇) at one state at mpmath's precision (complex allowed); u̇ empty with ``velocities_only``."""
        n = len(q)
        v: list = [mpmath.mpf(0)] * n
        for j, x in zip(self.ind, u):
            v[j] = x
        if self.dep:
            A = self._A_mp(*q, *self.p_exact())
            AD = mpmath.matrix([[A[a, j] for j in self.dep] for a in range(len(self.dep))])
            rhs = mpmath.matrix([-sum(A[a, j] * v[j] for j in self.ind) for a in range(len(self.dep))])
            solved = mpmath.lu_solve(AD, rhs)
            for r, j in enumerate(self.dep):
                v[j] = solved[r]
        if velocities_only:
            return v, []
        acc = self._qddot_mp(*q, *v, *self.p_exact())
        return v, [acc[j] for j in self.ind]

    def divergence_mp(self, q: list, u: list) -> Any:
        h = mpmath.mpf(10) ** -60
        total = mpmath.mpf(0)
        n = len(q)
        for i in range(n + len(u)):
            qs = [x + (1j * h if j == i else 0) for j, x in enumerate(q)]
            us = [x + (1j * h if n + j == i else 0) for j, x in enumerate(u)]
            qdot, udot = self.field_mp(qs, us)
            total += mpmath.im(qdot[i] if i < n else udot[i - n]) / h
        return total


@lru_cache(maxsize=8)
def _manifold(data: LagrangianData, dependent: tuple[int, ...]) -> _Manifold:
    """The compiled flow on the manifold, once for both searches (compiling the rattleback's takes seconds)."""
    return _Manifold(data, dependent)


def _table(fn: Any, q: np.ndarray) -> np.ndarray:
    """The outputs of a lambdified list at rows of q, shape (rows, outputs) (constant outputs broadcast)."""
    return np.stack([np.broadcast_to(np.asarray(e, dtype=float), (len(q),)) for e in fn(*q.T)], axis=1)


def _states(data: LagrangianData, manifold: _Manifold, angles: set[sp.Symbol], count: int,
            seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    q = np.column_stack([rng.uniform(0.3, 2.8, count) if x in angles else rng.uniform(-1.0, 1.0, count)
                         for x in data.q])
    u = rng.normal(size=(count, len(manifold.ind)))
    return q, u


def _null_space(rows: np.ndarray, size: np.ndarray) -> np.ndarray:
    """A basis of the null space (rows), empty if none, by SVD with each column scaled by ``size``: the size of
    its basis function at the states (not of the column, which is ~0 for a basis function that solves alone)."""
    scale = np.linalg.norm(size, axis=0)
    scale[scale == 0] = 1.0
    _, s, vt = np.linalg.svd(rows / scale, full_matrices=True)
    rank = int(np.sum(s > NULL_TOLERANCE * s[0])) if len(s) else 0
    return vt[rank:] / scale


def _rational_rows(null: np.ndarray) -> list[list[Fraction]] | None:
    """The null space in reduced row echelon form with rational entries, or None if they are not rational."""
    M = null.copy()
    pivots: list[int] = []
    r = 0
    for c in range(M.shape[1]):
        if r == len(M):
            break
        i = r + int(np.argmax(np.abs(M[r:, c])))
        if abs(M[i, c]) < 1e-8 * np.max(np.abs(M)):
            continue
        M[[r, i]] = M[[i, r]]
        M[r] /= M[r, c]
        for j in range(len(M)):
            if j != r:
                M[j] -= M[j, c] * M[r]
        pivots.append(c)
        r += 1
    out = []
    for row in M[:r]:
        exact = [Fraction(float(x)).limit_denominator(MAX_DENOMINATOR) if abs(x) > 1e-9 else Fraction(0) for x in row]
        if max(abs(float(e) - x) for e, x in zip(exact, row)) > 1e-7:
            return None
        out.append(exact)
    return out


def _verify(residual_at: Any, data: LagrangianData, manifold: _Manifold, angles: set[sp.Symbol]) -> float:
    """max over :data:`VERIFY_POINTS` random rational states of |residual| / its scale, at VERIFY_DIGITS digits."""
    rng = np.random.default_rng(20261129)
    worst = 0.0
    with working_digits(VERIFY_DIGITS):
        for _ in range(VERIFY_POINTS):
            q = [mpmath.mpf(int(rng.integers(300, 2800))) / 1000 if x in angles
                 else mpmath.mpf(int(rng.integers(-1000, 1000))) / 1000 for x in data.q]
            u = [mpmath.mpf(int(rng.integers(-1000, 1000))) / 500 for _ in manifold.ind]
            value, size = residual_at(q, u)
            worst = max(worst, float(abs(value) / size) if size else float(abs(value)))
    return worst


@dataclass(frozen=True)
class SampledMeasure:
    """``found`` (``density`` verified), or ``undecided`` with what was searched; ``dependent`` the dependent
    velocities as functions of (q, u); ``reason`` the evidence."""

    status: str
    density: sp.Expr | None
    dependent: tuple[tuple[sp.Symbol, sp.Expr], ...]
    reason: str
    seconds: float


def _symbolic(basis: list[sp.Expr], coefficients: list[Fraction]) -> sp.Expr:
    return sp.Add(*(sp.Rational(c.numerator, c.denominator) * b for c, b in zip(coefficients, basis) if c))


def sampled_measure(data: LagrangianData, dependent: tuple[int, ...]) -> SampledMeasure:
    """ρ(q) dq du on the constraint manifold, u the velocities besides ``dependent`` (module doc)."""
    start = time.perf_counter()
    manifold = _manifold(data, dependent)
    angles = _angles(data)
    q, u = _states(data, manifold, angles, SAMPLES, 20261128)
    with np.errstate(all="ignore"):
        qdot, _ = manifold.field(q, u)
        div = manifold.divergence(q.astype(complex), u.astype(complex))
        rate = manifold.log_kinetic_rate(q.astype(complex), qdot.real)
    finite = np.isfinite(div) & np.isfinite(rate) & np.all(np.isfinite(qdot), axis=1)
    q, u, qdot, div, rate = q[finite], u[finite], qdot[finite], div[finite], rate[finite]
    forms = ", ".join(f"({r}, {s})" for r, s in FORMS)
    tried = []
    for variables, degree in _measure_ansatzes(data, manifold, q, u, angles):
        basis = _basis([(x, x in angles) for x in variables], degree)
        if len(basis) > MAX_UNKNOWNS or len(q) < 1.5 * len(basis):
            continue
        names = ", ".join(map(str, variables)) or "none"
        tried.append(f"P in the span of {len(basis)} products of powers, sin and cos of degree <= {degree} of "
                     f"({names})")
        values = _table(sp.lambdify(list(data.q), basis, modules="numpy"), q)
        gradient = _table(sp.lambdify(list(data.q), [sp.diff(b, x) for b in basis for x in data.q],
                                      modules="numpy"), q).reshape(len(q), len(basis), len(data.q))
        along = np.einsum("skn,sn->sk", gradient, qdot.real)
        for r, s in FORMS:
            null = _null_space(values * (div + float(s) * rate)[:, None] + float(r) * along, values)
            exact = _rational_rows(null) if len(null) else None
            if exact is None:
                continue
            P = _symbolic(basis, exact[0])
            worst = _verify(_measure_residual(manifold, P, r, s), data, manifold, angles)
            if worst > VERIFY_ZERO:
                continue
            point = {x: 1.0 for x in data.q}
            if complex(P.evalf(subs=point)).real < 0:
                P = -P
            G = manifold.kinetic_determinant_symbolic() if s else sp.Integer(1)
            density = P ** sp.Rational(r.numerator, r.denominator) * G ** sp.Rational(s.numerator, s.denominator)
            return SampledMeasure("found", density, manifold.on_manifold(), (
                f"rho = P^r G^s = {sp.sstr(density)} (r = {r}, s = {s}, G = det(B^T M B) the kinetic matrix in u): "
                f"the null space of div(rho f) = 0 with {tried[-1]}, fitted at {len(q)} states, made rational (the "
                f"parameters' values substituted exactly) and verified by a randomized identity test: "
                f"|P (div f + s dG/dt / G) + r (grad P, q_dot)| <= {worst:.1e} of its terms at {VERIFY_POINTS} "
                f"random states, {VERIFY_DIGITS} digits, "
                "derivatives by complex steps (no closed form of the field for a symbolic proof)"),
                time.perf_counter() - start)
    return SampledMeasure("undecided", None, (), (
        f"no density rho = P^r G^s, (r, s) in ({forms}), with " + "; nor with ".join(tried)
        + f", fitted at {len(q)} states where the field is finite (a density outside the ansatz is not excluded)"),
        time.perf_counter() - start)


def _measure_ansatzes(data: LagrangianData, manifold: _Manifold, q: np.ndarray, u: np.ndarray,
                      angles: set[sp.Symbol]) -> list[tuple[list[sp.Symbol], int]]:
    """The coordinates ρ is sought as a function of, and the degree: first those u̇ depends on (degree 4 for
    at most two of them), then those the field depends on (degree 2)."""
    _, udot = manifold.field(q, u)
    acc, field = [], []
    for i, x in enumerate(data.q):
        step = np.zeros(q.shape, complex)
        step[:, i] = 1e-30j
        qdot_c, udot_c = manifold.field(q + step, u.astype(complex))
        if np.max(np.abs(udot_c.imag)) > 1e-42 * (1 + np.max(np.abs(udot))):
            acc.append(x)
        if np.max(np.abs(qdot_c.imag)) > 1e-42 * (1 + np.max(np.abs(u))) or x in acc:
            field.append(x)
    out = [(acc, 4 if len(acc) <= 2 else 2)]
    if field != acc:
        out.append((field, 2))
    return out


def _measure_residual(manifold: _Manifold, P: sp.Expr, r: Fraction, s: Fraction) -> Any:
    data = manifold.data
    P_at = sp.lambdify(list(data.q), P, modules="mpmath")
    grad_at = sp.lambdify(list(data.q), [sp.diff(P, x) for x in data.q], modules="mpmath")

    def residual(qs: list, us: list) -> tuple:
        qdot_mp, _ = manifold.field_mp(qs, us)
        value = P_at(*qs)
        terms = [value * manifold.divergence_mp(qs, us),
                 *(mpmath.mpf(r.numerator) / r.denominator * g * v for g, v in zip(grad_at(*qs), qdot_mp))]
        if s:
            terms.append(value * mpmath.mpf(s.numerator) / s.denominator * manifold.log_kinetic_rate_mp(qs, qdot_mp))
        return sum(terms), sum(abs(t) for t in terms)

    return residual


@dataclass(frozen=True)
class SampledIntegrals:
    """The integrals linear in u found and verified (expressions in the user's velocity symbols), what was
    searched, and the seconds."""

    integrals: tuple[tuple[sp.Expr, str], ...]
    searched: str
    seconds: float


def sampled_integrals(data: LagrangianData, dependent: tuple[int, ...]) -> SampledIntegrals:
    """The integrals F = Σ b_j(q) u_j of the module doc, each with its evidence."""
    start = time.perf_counter()
    manifold = _manifold(data, dependent)
    angles = _angles(data)
    coordinates = [(x, True) for x in data.q if x in angles]
    basis = _basis(coordinates, 2)
    m = len(manifold.ind)
    unknowns = len(basis) * m
    u_symbols = [data.v[j] for j in manifold.ind]
    searched = (f"F = sum_j b_j(q) u_j, u = ({', '.join(map(str, u_symbols))}), b_j in the span of {len(basis)} "
                f"products of 1, sin, cos, sin^2, sin cos of ({', '.join(str(x) for x, _ in coordinates)})")
    if unknowns > MAX_UNKNOWNS:
        return SampledIntegrals((), f"not sought: {unknowns} unknowns > max {MAX_UNKNOWNS}",
                                time.perf_counter() - start)
    count = max(SAMPLES, int(1.5 * unknowns) + 50)
    q, u = _states(data, manifold, angles, count, 20261127)
    with np.errstate(all="ignore"):
        qdot, udot = manifold.field(q, u)
    finite = np.all(np.isfinite(qdot), axis=1) & np.all(np.isfinite(udot), axis=1)
    q, u, qdot, udot = q[finite], u[finite], qdot[finite], udot[finite]
    if len(q) < 1.5 * unknowns:
        return SampledIntegrals((), f"{searched}: not sought, the field is finite at only {len(q)} of {count} sampled "
                                "states", time.perf_counter() - start)
    values = _table(sp.lambdify(list(data.q), basis, modules="numpy"), q)
    gradient = _table(sp.lambdify(list(data.q), [sp.diff(b, x) for b in basis for x in data.q], modules="numpy"),
                      q).reshape(len(q), len(basis), len(data.q))
    along = np.einsum("skn,sn->sk", gradient, qdot)
    rows = np.concatenate([along * u[:, j:j + 1] + values * udot[:, j:j + 1] for j in range(m)], axis=1)
    null = _null_space(rows, np.concatenate([values * u[:, j:j + 1] for j in range(m)], axis=1))
    if not len(null):
        return SampledIntegrals((), searched, time.perf_counter() - start)
    exact = _rational_rows(null)
    if exact is None:
        return SampledIntegrals((), searched + "; the null space found is not rational at the parameters' values",
                                time.perf_counter() - start)
    found = []
    for row in exact:
        F = sp.Add(*(_symbolic(basis, row[j * len(basis):(j + 1) * len(basis)]) * u_symbols[j] for j in range(m)))
        coefficient_exprs = [sp.diff(F, s) for s in u_symbols]
        b_at = sp.lambdify(list(data.q), coefficient_exprs, modules="mpmath")
        grad_at = sp.lambdify(list(data.q), [[sp.diff(c, x) for x in data.q] for c in coefficient_exprs],
                              modules="mpmath")

        def residual(qs: list, us: list, b_at: Any = b_at, grad_at: Any = grad_at) -> tuple:
            qdot_mp, udot_mp = manifold.field_mp(qs, us)
            grads = grad_at(*qs)
            terms = [sum(g * v for g, v in zip(grads[j], qdot_mp)) * us[j] for j in range(m)]
            terms += [b * a for b, a in zip(b_at(*qs), udot_mp)]
            return sum(terms), sum(abs(t) for t in terms)

        worst = _verify(residual, data, manifold, angles)
        if worst <= VERIFY_ZERO:
            found.append((F, f"proven by a randomized identity test: dF/dt on the constraint manifold is <= "
                             f"{worst:.1e} of its terms at {VERIFY_POINTS} random states, {VERIFY_DIGITS} digits "
                             "(found as the null space of the sampled ansatz, made rational at the parameters' "
                             "values; no closed form of the field for a symbolic proof)"))
    return SampledIntegrals(tuple(found), searched, time.perf_counter() - start)
