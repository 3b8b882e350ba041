"""First integrals linear and quadratic in the velocities of a user's Lagrangian system, sought in a finite
ansatz on its constraint manifold and each proven symbolically.

On the manifold q̇ = B̃(q) u / Δ(q) (u the independent velocities, chosen as in
:mod:`nonholonomic.lagrangian.measure_search`; Δ the determinant of the k × k minor of A solved for the others,
1 when constant) the ansatz is F = Σ_μ b_μ(q) u^μ / Δ^|μ| over the monomials u^μ of degree ≤ 2, each b_μ in
the span of products, of total degree ≤ D, of powers of the coordinates appearing polynomially and of
1, cos θ, sin θ, sin²θ, sin θ cos θ (degrees 0, 1, 1, 2, 2) of those appearing inside sin/cos; a cyclic
coordinate gets both kinds when that fits. The ansatz is the first of :data:`DEGREES` (cyclic sin/cos with,
then without) whose linear systems have at most :data:`MAX_UNKNOWNS` unknowns; constants are left out.

dF/dt along the reduced flow is a polynomial in u with coefficients linear in the unknowns. At random
integer points (sin, cos rational: 2s/(1+s²), (1−s²)/(1+s²)), the parameters exact rationals of their
values, that is an exact linear system over ℚ; its null space, in reduced row echelon form with the
quadratic terms leading, is computed modulo three primes and lifted (Chinese remainders, rational
reconstruction). Every integral listed is then proven: the numerator of dF/dt, a polynomial in
(q, sin, cos, u), reduces to 0 modulo sin² + cos² = 1. A flow even in u (no gyroscopic terms) has its odd
and even integrals sought apart. The energy is listed first (found in the ansatz, or added from L); an
integral that is a combination of 1, the energy and products of those listed is only counted
(``omitted``). An integral missing from the list is not in the ansatz: that does not mean none exists.
"""

from __future__ import annotations

import functools
import itertools
import math
import time
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np
import sympy as sp
from sympy.polys.matrices import DomainMatrix
from sympy.polys.rings import PolyElement

from nonholonomic import bounded
from nonholonomic.lagrangian.equations import derive
from nonholonomic.lagrangian.measure_search import _dependent_columns, _Failed
from nonholonomic.lagrangian.parse import LagrangianData
from nonholonomic.lagrangian.sampled_search import sampled_integrals

__all__ = ["MAX_PROOF_TERMS", "NOT_EXHAUSTIVE", "Integral", "IntegralSearch", "integral_search"]

#: Terms of a candidate's numerator past which its symbolic proof is not tried (it stays listed as unproven:
#: dF/dt vanishes at the sample points modulo three primes); a measure of the proof's work, not a clock.
MAX_PROOF_TERMS = 2000
#: Most unknowns of one linear system (the ansatz is made smaller until it fits).
MAX_UNKNOWNS = 600
#: Total degrees of the coefficient functions tried, largest first.
DEGREES = (4, 3, 2, 1)
#: Primes ≡ 3 (mod 4) below 2³¹: 1 + s² never vanishes, products fit in int64.
PRIMES = (2147483647, 2147483587, 2147483579)
#: Rows of the linear system per unknown.
ROW_FACTOR = 1.5
#: Products of at most this many integrals listed make a further one not worth listing.
MAX_FACTORS = 6
#: What a short list means.
NOT_EXHAUSTIVE = "an integral missing from this list is not in the ansatz; that does not mean none exists"
#: The proof of an integral found.
PROVEN = ("proven: the numerator of dF/dt on the constraint manifold, a polynomial in (q, sin, cos, u), reduces to 0 "
          "modulo sin^2 + cos^2 = 1 (parameters at their values)")


@dataclass(frozen=True)
class Integral:
    """An integral found: F(q, q̇) in the user's symbols (only the independent velocities appear, so it is
    a function of the full state too), its degree in the velocities (0: a function of q), a formula text
    and a proof (``proven: ...`` or ``unproven: ...``)."""

    name: str
    degree: int
    expression: sp.Expr
    formula: str
    proof: str

    @property
    def proven(self) -> bool:
        """Whether dF/dt ≡ 0 on the constraint manifold was shown symbolically."""
        return self.proof.startswith("proven")


@dataclass(frozen=True)
class IntegralSearch:
    """The outcome of :func:`integral_search`: ``status`` ``done`` (the ansatz searched, all listed proven),
    ``partial`` (some unproven: a proof past :data:`MAX_PROOF_TERMS`, or a failed lift) or ``undecided`` (not searched);
    the integrals (the energy first); u; what was searched (``ansatz``, ``basis`` of the coefficient functions,
    ``degrees`` in u); ``omitted``, the integrals of the ansatz not listed as combinations of 1, the energy
    and products of those listed; ``reason``, which says that absence means "not in this ansatz"."""

    status: str
    integrals: tuple[Integral, ...]
    velocities: tuple[sp.Symbol, ...]
    ansatz: str
    basis: tuple[sp.Expr, ...]
    degrees: tuple[int, ...]
    omitted: int
    reason: str
    seconds: float = 0.0


class _System:
    """The reduced flow as polynomials over ℚ in (q, cos/sin of the angles, q̇), parameters at their values:
    q̇ᵢ = qdot[i]/Δ and u̇ⱼ = udot[j]/(Δ² den)."""

    def __init__(self, data: LagrangianData) -> None:
        if data.L.has(data.t) or any(f.has(data.t) for f in data.constraints):
            raise _Failed("undecided", "L or a constraint depends on t explicitly: integrals F(q, q_dot) not sought")
        eqs = derive(data)
        self.exact = {s: sp.nsimplify(x, rational=True) for s, x in data.parameter_values.items()}
        q, v, n, k = data.q, data.v, len(data.q), data.A.shape[0]
        raw = [self._trig(e) for e in (data.L, *data.constraints, *eqs.qddot)]
        args = {f.args[0] for e in raw for f in e.atoms(sp.sin, sp.cos)}
        if not args <= set(q) or any(f.has(*q) for e in raw for f in e.atoms(sp.Function) - e.atoms(sp.sin, sp.cos)):
            raise _Failed("undecided", "the ansatz needs L and the constraints rational in the coordinates and in "
                                       "sin and cos of single coordinates")
        used = set().union(*(e.free_symbols for e in raw[:1 + k]))
        self.powers = [i for i in range(n) if q[i] not in args]
        angles = [i for i in range(n) if q[i] in args or q[i] not in used]  # cyclic ones too
        pairs = {i: (sp.Dummy(f"cos_{q[i]}"), sp.Dummy(f"sin_{q[i]}")) for i in angles}
        self.back = {x: f(q[i]) for i, cs in pairs.items() for x, f in zip(cs, (sp.cos, sp.sin))}
        self.to = {f(q[i]): x for i, cs in pairs.items() for x, f in zip(cs, (sp.cos, sp.sin))}
        self.R, *gens = sp.ring([*q, *itertools.chain(*pairs.values()), *v], sp.QQ, sp.lex)
        self.q, self.n, self.gq, self.gv = q, n, gens[:n], gens[len(gens) - n:]
        self.trig = {i: tuple(gens[n + 2 * a: n + 2 * a + 2]) for a, i in enumerate(angles)}  # (C, S)
        self.circle = [C**2 + S**2 - 1 for C, S in self.trig.values()]  # C² leading (lex): a Gröbner basis
        self.dep = _dependent_columns(data)
        self.ind = tuple(j for j in range(n) if j not in self.dep)
        self.u, self.gu = tuple(v[j] for j in self.ind), [self.gv[j] for j in self.ind]
        rows = [[self.poly(f)[0].diff(self.gv[j]) for j in range(n)] for f in data.constraints]  # denominators cleared
        minor = DomainMatrix([[r[j] for j in self.dep] for r in rows], (k, k), self.R.to_domain())
        if k:
            adjugate, delta = minor.adj_det()  # adj(minor), det(minor)
            adj = adjugate.to_list()
        else:
            adj, delta = [], self.R.one
        self.qdot = [delta * self.gv[j] if j in self.ind else self.R.zero for j in range(n)]
        for b, j in enumerate(self.dep):  # Δ q̇_dep = −adj(minor) A_ind u
            self.qdot[j] = -sum((adj[b][a] * rows[a][i] * self.gv[i] for a in range(k) for i in self.ind), self.R.zero)
        if delta.is_ground:
            self.qdot, delta = [f.quo_ground(delta.LC) for f in self.qdot], self.R.one
        self.delta, self.ddelta = delta, [self.d(delta, i) for i in range(n)]
        fractions = [self.poly(eqs.qddot[j]) for j in self.ind]
        self.den = functools.reduce(lambda a, b: a.lcm(b), (d for _, d in fractions), self.R.one)
        self.udot = [self.restrict(num) * self.den.exquo(d) for num, d in fractions]
        self.reversible = all(sum(m[len(m) - n:]) % 2 == 0 for f in self.udot for m in f.monoms())
        energy = self.poly(eqs.energy) if eqs.energy is not None else None
        self.E = (self.restrict(energy[0]), delta**2 * energy[1]) if energy else None  # E = E[0] / E[1]

    def _trig(self, expr: sp.Expr) -> sp.Expr:
        e = sp.sympify(expr).xreplace(self.exact)
        for f, g in ((sp.tan, lambda x: sp.sin(x) / sp.cos(x)), (sp.cot, lambda x: sp.cos(x) / sp.sin(x)),
                     (sp.sec, lambda x: 1 / sp.cos(x)), (sp.csc, lambda x: 1 / sp.sin(x))):
            e = e.replace(f, g)
        return sp.expand_trig(e) if any(not f.args[0].is_Symbol for f in e.atoms(sp.sin, sp.cos)) else e

    def poly(self, expr: sp.Expr) -> tuple:
        """``expr`` (parameters at their values) as (numerator, denominator) in the ring."""
        num, den = sp.fraction(sp.together(self._trig(expr).xreplace(self.to)))
        try:
            return self.R(sp.expand(num)), self.R(sp.expand(den))
        except (ValueError, TypeError, sp.polys.polyerrors.CoercionFailed):
            raise _Failed("undecided", f"not rational in the coordinates, sin and cos: {sp.sstr(expr)[:80]}") from None

    def d(self, f, i: int):
        """∂f/∂qᵢ, sin qᵢ and cos qᵢ being the generators S, C (∂S = C, ∂C = −S)."""
        C, S = self.trig.get(i, (None, None))
        return f.diff(self.gq[i]) + (C * f.diff(S) - S * f.diff(C) if C is not None else 0)

    def restrict(self, f: PolyElement) -> PolyElement:
        """Δ² f(q, q̇ = qdot/Δ) for f of degree ≤ 2 in q̇."""
        parts: dict[int, list] = {}
        for m, c in f.terms():
            parts.setdefault(sum(m[len(m) - self.n:]), []).append((m, c))
        if max(parts, default=0) > 2:
            raise _Failed("undecided", "an expression of degree > 2 in the velocities")
        subs = list(zip(self.gv, self.qdot))
        return sum((self.R.from_terms(t).compose(subs) * self.delta ** (2 - d) for d, t in parts.items()), self.R.zero)

    def basis(self, degree: int, cyclic_trig: bool) -> list:
        """The coefficient functions (monomials in q, C, S) of total degree ≤ ``degree``, by degree."""
        factors = []
        for i in range(self.n):
            C, S = self.trig[i] if i in self.trig and (cyclic_trig or i not in self.powers) else (None, None)
            factors.append([(e, self.gq[i] ** e) for e in range(degree + 1 if i in self.powers else 1)]
                           + ([(1, C), (1, S), (2, S**2), (2, S * C)] if C is not None else []))
        out = [(sum(d for d, _ in c), math.prod((f for _, f in c), start=self.R.one))
               for c in itertools.product(*factors) if sum(d for d, _ in c) <= degree]
        return [f for _, f in sorted(out, key=lambda x: x[0])]

    def proven(self, N, Phi) -> bool:
        """Whether F = N/Φ (Φ a function of q) has dF/dt ≡ 0 on the manifold, modulo sin² + cos² = 1."""
        def along(f):
            return sum((self.d(f, i) * self.qdot[i] for i in range(self.n)), self.R.zero)

        ud = sum((N.diff(g) * f for g, f in zip(self.gu, self.udot)), self.R.zero)
        return self.normal((along(N) * self.delta * self.den + ud) * Phi - N * along(Phi) * self.delta * self.den) == 0

    def normal(self, f):
        """f with cos² = 1 − sin²: its normal form modulo the circles."""
        return f.rem(self.circle) if self.circle else f

    def expr(self, f) -> sp.Expr:
        return f.as_expr().xreplace(self.back)


def _inv(a: np.ndarray, p: int) -> np.ndarray:
    out, base, e = np.ones_like(a), a % p, p - 2
    while e:
        out, base, e = (out * base % p if e & 1 else out), base * base % p, e >> 1
    return out


class _Modular:
    """Polynomials of :class:`_System` at K integer points modulo a prime p (arrays of length K); u is 0
    unless given."""

    def __init__(self, sys: _System, p: int, draws: np.ndarray, u: np.ndarray | None = None) -> None:
        self.sys, self.p, self.K = sys, p, draws.shape[1]
        self.cache: dict[tuple[int, int], np.ndarray] = {}
        vals = {g: x % p for g, x in zip(sys.gu, u if u is not None else [])}
        for i in range(sys.n):
            x = vals[sys.gq[i]] = draws[i] % p
            if i in sys.trig:
                w = _inv((1 + x * x) % p, p)
                vals[sys.trig[i][0]], vals[sys.trig[i][1]] = (1 - x * x) % p * w % p, 2 * x % p * w % p
        self.vals = [vals.get(g, np.zeros(self.K, np.int64)) for g in sys.R.gens]

    def power(self, g: int, e: int) -> np.ndarray:
        if (g, e) not in self.cache:
            self.cache[g, e] = self.vals[g] if e == 1 else self.power(g, e - 1) * self.vals[g] % self.p
        return self.cache[g, e]

    def __call__(self, f, skip: int = 0) -> np.ndarray:
        """f at the points, the exponents of the last ``skip`` generators ignored."""
        p, out = self.p, np.zeros(self.K, np.int64)
        for m, c in f.terms():
            t = np.full(self.K, int(c.numerator) % p * pow(int(c.denominator), -1, p) % p, np.int64)
            for g, e in enumerate(m[:len(m) - skip]):
                t = t * self.power(g, e) % p if e else t
            out = (out + t) % p
        return out


def _rref(M: np.ndarray, p: int) -> tuple[np.ndarray, list[int]]:
    """The reduced row echelon form of M modulo p and its pivot columns."""
    M, pivots, r = M % p, [], 0
    for c in range(M.shape[1]):
        nz = np.nonzero(M[r:, c])[0] if r < M.shape[0] else np.empty(0, dtype=np.intp)
        if len(nz):
            M[[r, r + nz[0]]] = M[[r + nz[0], r]]
            M[r, c:] = M[r, c:] * pow(int(M[r, c]), -1, p) % p
            f = M[:, c].copy()
            f[r] = 0
            rows = np.nonzero(f)[0]
            M[rows, c:] = (M[rows, c:] - f[rows, None] * M[r, c:] % p) % p
            pivots.append(c)
            r += 1
    return M[:r], pivots


def _monomials(m: int, degrees) -> list[tuple[int, ...]]:
    return [e for d in degrees for e in itertools.product(range(d + 1), repeat=m) if sum(e) == d]


def _rows(mod: _Modular, basis: list, mus: list, kappas: list) -> np.ndarray:
    """The coefficients of the monomials u^κ in dF/dt at the points (rows), per unknown (μ, α) (columns)."""
    sys, p, K, n, m = mod.sys, mod.p, mod.K, mod.sys.n, len(mod.sys.gu)
    idelta = _inv(mod(sys.delta), p)
    B = [[mod(sys.qdot[i].diff(g)) * idelta % p for g in sys.gu] for i in range(n)]  # q̇ = B u
    dlog = [sum(mod(sys.ddelta[i]) * B[i][l] % p for i in range(n)) % p * idelta % p for l in range(m)]  # Δ̇/Δ
    scale = idelta * idelta % p * _inv(mod(sys.den), p) % p
    P = []  # u̇ⱼ = Σ_ν P[j][ν] u^ν
    for f in sys.udot:
        split: dict[tuple, list] = {}
        for mono, c in f.terms():
            split.setdefault(tuple(mono[len(mono) - n + j] for j in sys.ind), []).append((mono, c))
        P.append({nu: mod(sys.R.from_terms(t), skip=n) * scale % p for nu, t in split.items()})
    phi = np.array([mod(f) for f in basis])
    dphi = [np.array([mod(sys.d(f, i)) for f in basis]) for i in range(n)]
    D = [sum((dphi[i] * B[i][l] % p for i in range(n)), np.zeros_like(phi)) % p for l in range(m)]
    index, blocks = {kappa: a for a, kappa in enumerate(kappas)}, []
    for mu in mus:  # F ∋ φ u^μ / Δ^k: d/dt = (Σ_l (Dφ)_l u_l u^μ + φ ∂(u^μ)·u̇ − k φ u^μ Δ̇/Δ) / Δ^k
        acc, k = np.zeros((len(kappas), *phi.shape), np.int64), sum(mu)
        for l in range(m):
            kappa = tuple(e + (i == l) for i, e in enumerate(mu))
            if kappa in index:
                acc[index[kappa]] = (acc[index[kappa]] + D[l] - k * phi % p * dlog[l] % p) % p
        for j in (j for j in range(m) if mu[j]):
            for nu, val in P[j].items():
                row = index[tuple(e - (i == j) + nu[i] for i, e in enumerate(mu))]
                acc[row] = (acc[row] + mu[j] * phi % p * val % p) % p
        acc = acc * _inv(mod(sys.delta ** k), p) % p
        blocks.append(acc.transpose(0, 2, 1).reshape(len(kappas) * K, len(basis)))
    return np.hstack(blocks)


def _lift(residues: list[np.ndarray]) -> list[Fraction] | None:
    """Rationals from their residues modulo :data:`PRIMES` (CRT, rational reconstruction), or None."""
    P, out = math.prod(PRIMES), []
    for rs in zip(*residues):
        a = sum(int(r) * (P // p) * pow(P // p, -1, p) for r, p in zip(rs, PRIMES)) % P
        r0, r1, s0, s1, bound = P, a, 0, 1, math.isqrt(P // 2)
        while r1 > bound:
            t = r0 // r1
            r0, r1, s0, s1 = r1, r0 - t * r1, s1, s0 - t * s1
        if s1 == 0 or abs(s1) > bound:
            return None
        out.append(Fraction(r1, s1))
    return out


def _solve(sys: _System, basis: list, mus: list, kappas: list, seed: int) -> tuple[list, int]:
    """The null space of one linear system (columns: later ones lead) as (degree, leading basis function, N)
    (N None when a vector does not lift); and the number of unknowns."""
    columns = [(mu, a) for mu in mus for a in range(len(basis)) if sum(mu) or a]  # no constant
    keep = np.array([sum(mu) > 0 or a > 0 for mu in mus for a in range(len(basis))])
    draws = np.random.default_rng(seed).integers(1, 2**30, size=(sys.n, math.ceil(
        (ROW_FACTOR * len(columns) + 10) / len(kappas)) + 5))
    good = np.all([_Modular(sys, p, draws)(sys.delta * sys.den) != 0 for p in PRIMES], axis=0)
    results = [_rref(_rows(_Modular(sys, p, draws[:, good]), basis, mus, kappas)[:, keep], p) for p in PRIMES]
    if any(pivots != results[0][1] for _, pivots in results):
        raise _Failed("undecided", "the rank of the linear system differs between primes (unlucky points)")
    pivots, out = results[0][1], []
    def monomial(mu):
        return math.prod((g**e for g, e in zip(sys.gu, mu)), start=sys.R.one)

    for f in sorted(set(range(len(columns))) - set(pivots)):  # x_f = 1, x_pivots = −R[:, f]
        x = _lift([np.bincount([f, *pivots], [1, *(-R[:, f] % p)], len(columns)).astype(np.int64)
                   for (R, _), p in zip(results, PRIMES)])
        degree = sum(columns[f][0])
        N = x and sum((sys.R(sp.Rational(c.numerator, c.denominator)) * basis[a] * monomial(mu)
                       * sys.delta ** (degree - sum(mu)) for (mu, a), c in zip(columns, x) if c), sys.R.zero)
        out.append((degree, columns[f][1], N))
    return out, len(columns)


class _Span:
    """A growing span of vectors modulo p, in echelon form; ``add`` says whether x was independent."""

    def __init__(self, p: int, *vectors: np.ndarray) -> None:
        self.p = p
        self.rows: list[tuple[int, np.ndarray]] = []
        for x in vectors:
            self.add(x)

    def reduce(self, x: np.ndarray) -> np.ndarray:
        for c, row in self.rows:
            x = (x - x[c] * row % self.p) % self.p if x[c] else x
        return x

    def add(self, x: np.ndarray) -> bool:
        x = self.reduce(x % self.p)
        nz = np.nonzero(x)[0]
        self.rows += [(nz[0], x * pow(int(x[nz[0]]), -1, self.p) % self.p)] if nz.size else []
        return bool(nz.size)


def _present(sys: _System, found: list[tuple]) -> tuple[list, int, bool]:
    """Which to list (indices into ``found``, None for the energy), by degree 0, 1, the energy, 2: one in
    the span of 1 and the products (degree ≤ 2 in u, ≤ :data:`MAX_FACTORS` factors) of those kept before is
    only counted; and whether the energy is in the ansatz. Decided by values at random points mod p."""
    p, K, E = PRIMES[0], 64 + 8 * len(found), sys.E
    rng = np.random.default_rng(20240707)
    mod = _Modular(sys, p, rng.integers(1, 2**30, size=(sys.n, K)), rng.integers(1, 2**30, size=(len(sys.gu), K)))
    value: dict[int | None, Any] = {i: mod(N) * _inv(mod(Phi), p) % p for i, (_, N, Phi) in enumerate(found)}
    value[None] = mod(E[0]) * _inv(mod(E[1]), p) % p if E else None
    ones = np.ones(K, np.int64)
    energy_in = E is not None and not _Span(p, ones, *(value[i] for i in range(len(found)))).reduce(value[None]).any()
    ranked = sorted(range(len(found)), key=lambda i: found[i][0])
    order: list[int | None] = list(ranked)
    order[sum(found[i][0] < 2 for i in ranked):0] = [None] if E else []  # the energy before the quadratic ones
    span, omitted, work = _Span(p, ones), 0, 0
    kept: list[tuple[int | None, int]] = []
    for i in order:
        degree = found[i][0] if i is not None else 2
        if not span.add(value[i]) and i is not None:
            omitted += 1
            continue
        kept.append((i, degree))
        queue = [(degree, value[i], 1)]
        while queue and len(span.rows) < K // 2 and work < 2000:  # products with those kept
            d, y, factors = queue.pop()
            for j, d2 in ((j, d2) for j, d2 in kept if d + d2 <= 2 and factors < MAX_FACTORS):
                span.add(y * value[j] % p)
                work += 1
                queue.append((d + d2, y * value[j] % p, factors + 1))
    listed = sorted(kept, key=lambda k: (k[0] is not None, -k[1]))  # stable: simplest first per degree
    return [i for i, _ in listed], max(0, omitted - energy_in), energy_in


def _search(data: LagrangianData) -> tuple:
    start = time.perf_counter()
    sys = _System(data)
    m = len(sys.u)
    quad, lin, const = _monomials(m, (2,)), _monomials(m, (1,)), [(0,) * m]
    blocks = ([(const + quad, _monomials(m, (1, 3))), (lin, _monomials(m, (0, 2)))] if sys.reversible
              else [(const + lin + quad, _monomials(m, (0, 1, 2, 3)))])
    for degree, cyclic_trig in itertools.product(DEGREES, (True, False)):
        basis = sys.basis(degree, cyclic_trig)
        if max(len(mus) for mus, _ in blocks) * len(basis) - 1 <= MAX_UNKNOWNS:
            break
    found, unknowns, notes = [], 0, []
    for b, (mus, kappas) in enumerate(blocks):
        vectors, size = _solve(sys, basis, mus, kappas, seed=20240706 + b)
        found += [(d, a, N) for d, a, N in vectors if N is not None]
        unknowns += size
        missing = sum(N is None for _, _, N in vectors)
        notes += [f"{missing} null vector(s) not lifted to rationals"] if missing else []
    found = [(d, N, sys.delta**d) for d, _, N in sorted(found, key=lambda x: x[:2])]  # simplest first
    listed, omitted, energy_in = _present(sys, found)
    integrals, where = [], " (at the parameters' values)" if data.parameters else ""
    for index in listed:
        if index is not None:
            k, N, Phi = found[index]
        else:
            assert sys.E is not None  # the energy (index None) is listed only when there is one
            k, N, Phi = (2, *sys.E)
        if len(N.terms()) > MAX_PROOF_TERMS:
            proof = (f"unproven: the proof not tried: {len(N.terms()):,} terms > max {MAX_PROOF_TERMS:,} "
                     "(MAX_PROOF_TERMS); dF/dt vanishes at the sample points modulo three primes")
        elif sys.proven(N, Phi):
            proof = PROVEN
        else:
            notes.append("a lifted candidate failed its symbolic proof and is not listed")
            continue
        expr = sp.cancel(sys.expr(sys.normal(N)) / sys.expr(Phi))
        if index is None:
            integrals.append(Integral("energy", 2, expr, f"E = (q_dot, dL/dq_dot) - L = {sp.sstr(expr)} on the "
                                      f"constraint manifold{where}" + ("" if energy_in else
                                                                       "; not in the ansatz: added from L"), proof))
        else:
            name = f"F{len(integrals) + (sys.E is None)}"
            integrals.append(Integral(name, k, expr, f"{name} = {sp.sstr(expr)}{where}", proof))
    def names(idx):
        return "(" + ", ".join(str(sys.q[i]) for i in idx) + ")"

    trig = names(i for i in sys.trig if cyclic_trig or i not in sys.powers)
    ansatz = (f"F = sum over the monomials u^mu of degree <= 2 in u = {sys.u} of b_mu(q) u^mu / Delta^deg(mu), Delta = "
              f"{sp.sstr(sys.expr(sys.delta))}, each b_mu in the span of {len(basis)} functions of q: products, "
              f"of total degree <= {degree}, of powers of {names(sys.powers)} and of 1, cos, sin, sin^2, sin*cos "
              f"(degrees 0, 1, 1, 2, 2) of {trig}; the constant left out; {unknowns} unknowns"
              + (", odd and even parts apart (flow even in u)" if sys.reversible else ""))
    counts = [sum(i.degree == d and i.name != "energy" for i in integrals) for d in (0, 1, 2)]
    reason = (f"listed: {'the energy, ' if sys.E else ''}{counts[1]} linear and {counts[2]} other quadratic "
              f"integral(s){f', {counts[0]} function(s) of q' if counts[0] else ''}"
              + (f"; {omitted} more in the ansatz are combinations of 1, the energy and products of those listed"
                 if omitted else "") + (f" ({'; '.join(notes)})" if notes else "")
              + ("; searched at the parameters' values" if data.parameters else "") + f"; {NOT_EXHAUSTIVE}")
    status = "done" if all(i.proven for i in integrals) and not notes else "partial"
    return (status, tuple(integrals), sys.u, ansatz, tuple(sys.expr(f) for f in basis), (1, 2), omitted, reason,
            time.perf_counter() - start)


def integral_search(data: LagrangianData) -> IntegralSearch:
    """First integrals of ``data`` linear and quadratic in the velocities, in a finite ansatz (module doc).

    Parameters
    ----------
    data : LagrangianData
        From :func:`nonholonomic.lagrangian.lagrangian_data` (parsed and checked).

    The search runs to its end (:func:`nonholonomic.bounded.run`); its size is bounded by the ansatz
    (``MAX_UNKNOWNS``) and each proof by :data:`MAX_PROOF_TERMS`, never by a clock.

    Returns
    -------
    IntegralSearch
        The integrals (the energy first, each proven symbolically), what was searched, and that an
        integral missing from the list is only not in the ansatz.
    """
    eqs = derive(data)
    if not eqs.closed_form:
        sampled = bounded.run(("lagrangian.sampled_integrals", data), _sampled, (data, eqs.elimination))
        if sampled.status == "done":
            return sampled.value
        return IntegralSearch("undecided", (), (), "", (), (1,), 0, "the equations of motion were eliminated without "
                              f"cancellation ({eqs.elimination}) and the sampled ansatz failed: {sampled.message}; "
                              f"{NOT_EXHAUSTIVE}", sampled.seconds)
    outcome = bounded.run(("lagrangian.integrals", data), _search, (data,))
    if outcome.status == "done":
        return IntegralSearch(*outcome.value)
    message = outcome.message.split(": ", 1)[1] if outcome.message.startswith("_Failed") else outcome.message
    reason = f"not searched: {message}"
    return IntegralSearch("undecided", (), (), "", (), (1, 2), 0, f"{reason}; {NOT_EXHAUSTIVE}", outcome.seconds)


def _sampled(data: LagrangianData, elimination: str) -> IntegralSearch:
    """The integrals linear in the velocities of a system without a closed form of its field, fitted on sampled
    states (:func:`nonholonomic.lagrangian.sampled_search.sampled_integrals`), the energy first (from L)."""
    dependent = _dependent_columns(data)
    found = sampled_integrals(data, dependent)
    u = tuple(data.v[j] for j in range(len(data.q)) if j not in dependent)
    integrals = []
    energy = derive(data).energy
    if energy is not None:
        integrals.append(Integral("energy", 2, energy, "E = (q_dot, dL/dq_dot) - L (not in the ansatz: from L)",
                                  "proven: the constraint forces do no work (q_dot^T A^T lambda = 0 on the "
                                  "constraint manifold)"))
    for expression, proof in found.integrals:
        name = f"F{len(integrals)}"
        integrals.append(Integral(name, 1, expression, f"{name} = {sp.sstr(expression)}", proof))
    reason = (f"the equations of motion were eliminated without cancellation ({elimination}), so an ansatz linear in "
              f"the velocities was fitted on sampled states instead: {found.searched}; {len(found.integrals)} "
              f"found; {NOT_EXHAUSTIVE}")
    return IntegralSearch("done", tuple(integrals), u, found.searched, (), (1,), 0, reason, found.seconds)
