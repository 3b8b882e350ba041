"""The reducing multiplier of a generalized Chaplygin system with two degrees of freedom (Theorem 1).

Paper, section "Generalized Chaplygin systems", eq. (2704-7)–(2704-10) and Theorem 1. The system is

    d/dt ∂L/∂q̇₁ − ∂L/∂q₁ = q̇₂ S,   d/dt ∂L/∂q̇₂ − ∂L/∂q₂ = −q̇₁ S,   S = a₁(q) q̇₁ + a₂(q) q̇₂ + b(q)   (2704-7)

with L quadratic in the velocities, not necessarily homogeneous (Theorem 1):
L = ½ q̇ᵀG(q)q̇ + (w(q), q̇) − V(q), det G ≠ 0. After the Legendre transform P = ∂L/∂q̇ = G q̇ + w
(eq. 2704-10)

    S = A₁ P₁ + A₂ P₂ + B,    (A₁, A₂) = G⁻¹a,    B = b − (a, G⁻¹w).

The Liouville equation for a density ρ(q) dP₁dP₂dq₁dq₂ of (2704-10) gives (proof of Theorem 1)

    ∂ ln ρ/∂q₁ = A₂,    ∂ ln ρ/∂q₂ = −A₁,

so such a density exists (locally) iff the 1-form A₂ dq₁ − A₁ dq₂ is closed, i.e. iff the
integrability condition ∂A₁/∂q₁ + ∂A₂/∂q₂ = 0 holds; ln ρ is then its line integral. ρ is found
(up to a constant factor) by, in turn: an ansatz ρ = Π fⱼ^kⱼ exp(α·q) over the irreducible factors of
A₁, A₂ and det G with rational kⱼ fitted at random points and then proved exactly; sympy's
``integrate``; the line integral from a base point (left unevaluated if sympy finds no closed form). With the
reducing multiplier N = ρ and dτ = N dt, eq. (2704-8) gives

    S̄ = (N A₁ + ∂N/∂q₂) P₁ + (N A₂ − ∂N/∂q₁) P₂ + N B = N(q) B(q)

(the paper's proof prints S̄ = B: ERRATA 6; and ∂L̄/∂q_q′ in eq. 2704-8 is ∂L̄/∂q₁′: ERRATA 14).
In the new momenta p = ∂L̄/∂q′ = N P the equations are

    dx/dτ = {x, H̄},    {q_i, p_j} = δ_ij,  {p₁, p₂} = S̄(q),  {q₁, q₂} = 0     (2704-9)

with H̄(q, p) = H(q, p/N) the energy. That is Theorem 1's convention dx/dτ = {x, H̄} = P∇H̄; the
e(3) sections (and :mod:`nonholonomic.hamiltonization.poisson`, dx/dτ = {H, x} = −P∇H) use the opposite one, in
which the same flow is ``−hamiltonian_vector_field(H̄)``, i.e. needs the bracket (2704-9) with the
opposite sign. The verification computes both and says which holds.

Monopoles (text after eq. 2704-9): :func:`monopole_charge` integrates S̄ dq₁∧dq₂ over a chart. In
angle charts the momenta p may differ from smooth fibre coordinates of T*M by a potential W(q)
singular at the poles; the smooth gyroscopic form is then that of p̃ = p − W (``shift``). For
Chaplygin's ball in Euler angles, W = (0, cN cosθ) (from L = ρ_μM = cNγ + m(p_θ, p_φ − cN cosθ)),
and the flux of the smooth form is −4πc/√det I (N = ρ_μ): non-zero for c ≠ 0, a monopole.

Every symbolic step runs to its end (:mod:`nonholonomic.bounded`: shared and cached per process); what
keeps it small is decided before it starts by deterministic sizes (:mod:`nonholonomic.work_limits`,
``limits``): a step past its limit is not tried and says so in the same words on every machine (a tidy
step keeps its expression unshortened, a proof leaves its verdict undecided, sympy's ``integrate`` is
not called). Identities rational in sin qᵢ, cos qᵢ are decided exactly by the substitution
t = tan(q/2) and an expanded numerator; numeric checks run at 40 digits.

This module is the front door: the density's three searches are in
:mod:`nonholonomic.hamiltonization.reducing_multiplier_density`, the monopole integral in
:mod:`nonholonomic.hamiltonization.monopole`, the exact trigonometric decision in :mod:`nonholonomic.rational_trig`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import mpmath
import numpy as np
import sympy as sp

from nonholonomic import bounded, work_limits
from nonholonomic.hamiltonization.monopole import SYMBOLIC_INTEGRAL_MAX_OPS, monopole_charge
from nonholonomic.hamiltonization.poisson import PoissonStructure, generalized_chaplygin_bracket
from nonholonomic.hamiltonization.reducing_multiplier_density import (
    BASE_POINT,
    _density_ansatz,
    _density_by_integration,
    _density_equations_hold,
    _density_line_integral,
    _reduce_cos_squares,
)
from nonholonomic.hamiltonization.theorem_1 import adj2, det2, prove_theorem_1
from nonholonomic.numerics.precision import working_digits
from nonholonomic.rational_trig import rational_trig_is_zero
from nonholonomic.work_limits import WorkLimits, operations, over

__all__ = ["EQUATIONS", "ReducingMultiplierResult", "hamiltonize", "monopole_charge",
           "rational_trig_is_zero", "BASE_POINT", "SYMBOLIC_INTEGRAL_MAX_OPS"]

#: Where each item of the result comes from in the paper.
EQUATIONS: dict[str, str] = {
    "system": "2704-7: d/dt dL/dq1dot - dL/dq1 = q2dot S, d/dt dL/dq2dot - dL/dq2 = -q1dot S, "
              "S = a1 q1dot + a2 q2dot + b",
    "A1, A2, B": "2704-10: P = dL/dq_dot, S = A1 P1 + A2 P2 + B; (A1, A2) = G^-1 (a1, a2), B = b - (a, G^-1 w) "
                 "for L = q_dot G q_dot / 2 + (w, q_dot) - V",
    "integrability_condition": "proof of Theorem 1: (1/rho) drho/dq1 = A2, (1/rho) drho/dq2 = -A1; "
                               "solvable (locally) iff dA1/dq1 + dA2/dq2 = 0",
    "density": "proof of Theorem 1: Liouville equation for rho(q) dP1 dP2 dq1 dq2 of 2704-10",
    "reducing_multiplier": "Theorem 1: N = rho, N dt = d tau",
    "S_bar": "2704-8 with N = rho: S_bar = N B (ERRATA 6: the proof prints B; ERRATA 14: dL/dq_q' is dL/dq1')",
    "hamiltonian": "Theorem 1: p = dL_bar/dq' = N P, H_bar = p q' - L_bar = H(q, p/N), the energy",
    "bracket": "2704-9: {q_i, p_j} = delta_ij, {p1, p2} = S_bar(q), {q1, q2} = 0",
    "convention": "Theorem 1: dq_i/dtau = {q_i, H_bar}, dp_i/dtau = {p_i, H_bar}",
    "monopole": "text after 2704-9: a smooth closed 2-form S_bar dq1^dq2 on a compact M is exact iff its integral is 0 "
                "(in angle charts the momenta may differ from smooth fibre coordinates by a singular W: see "
                "monopole_charge(shift=...))",
}

#: Relative residual below which a 40-digit evaluation counts as zero.
NUMERIC_ZERO = 1e-25
#: Relative residual accepted for the pointwise flow check (40-digit evaluation).
POINTWISE_TOLERANCE = 1e-20
#: Digits of the mpmath evaluations.
DIGITS = 40


# --------------------------------------------------------------------------------------------------
# symbolic work, run to its end


def _run(fn: Callable[..., Any], args: tuple[Any, ...]) -> tuple[str, Any]:
    """``fn(*args)`` run to its end: ``("done", value)`` or ``("error", sympy's message)``. Identical
    calls share one computation, cached per process (:mod:`nonholonomic.bounded`).

    Raises
    ------
    nonholonomic.bounded.SafetyCapExceeded
        Past the service's safety cap (a failure of the caller, never a verdict).
    """
    outcome = bounded.run(("reducing_multiplier", fn.__qualname__, args), fn, args)
    if outcome.status == "done":
        return "done", outcome.value
    return "error", outcome.message


# --------------------------------------------------------------------------------------------------
# numeric sampling at 40 digits


@dataclass
class _Sampler:
    """Random phase points and parameter values for the numeric checks (seeded, reproducible).

    Coordinates are drawn from (0.2, 1.35) (inside (0, π/2): away from sin q = 0 and cos q = 0 of
    angle charts), velocities from (−1, 1); parameters without a given value from (1.1, 2.9)."""

    given: dict[sp.Symbol, float]
    free: tuple[sp.Symbol, ...]
    seed: int = 2704
    rng: np.random.Generator = field(init=False)

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng(self.seed)
        self.drawn = {s: float(v) for s, v in zip(self.free, self.rng.uniform(1.1, 2.9, len(self.free)))}

    @property
    def values(self) -> dict[sp.Symbol, float]:
        return {**self.drawn, **self.given}

    @property
    def symbols(self) -> tuple[sp.Symbol, ...]:
        return tuple(self.values)

    def note(self) -> str:
        if not self.drawn:
            return ""
        return ("; the numeric checks evaluate the constants at values drawn at random (the symbolic work keeps "
                "them as symbols): " + ", ".join(
            f"{s}={v:.4f}" for s, v in sorted(self.drawn.items(), key=lambda kv: str(kv[0]))))

    def coordinates(self, n: int) -> np.ndarray:
        return self.rng.uniform(0.2, 1.35, (n, 2))

    def velocities(self, n: int) -> np.ndarray:
        return self.rng.uniform(-1.0, 1.0, (n, 2))

    def function(self, exprs: Sequence[sp.Expr], args: Sequence[sp.Symbol]) -> Callable[..., list[Any]]:
        """``f(*args values) -> [mpf]`` at 40 digits, the parameters filled in (as exact inputs:
        substituting floats into sympy would round every intermediate to 15 digits)."""
        names = self.symbols
        exprs = [_without_step_derivatives(e) for e in exprs]
        # an unevaluated line integral (a density left as ∫) is one quadrature per point, shared by
        # every expression that holds it (N, p = N ∂L/∂q̇ and their derivatives), not one per occurrence
        integrals = sorted({i for e in exprs if isinstance(e, sp.Basic) for i in e.atoms(sp.Integral)}, key=sp.srepr)
        held = [sp.Dummy(f"integral_{k}") for k in range(len(integrals))]
        exprs = [e.xreplace(dict(zip(integrals, held))) if isinstance(e, sp.Basic) else e for e in exprs]
        inputs = list(args) + list(names)
        try:
            fn = sp.lambdify(inputs + held, list(exprs), modules="mpmath")
            fn_integrals = sp.lambdify(inputs, integrals, modules="mpmath") if held else None
        except Exception as exc:  # sympy cannot print it as code (an unevaluated special function ...)
            raise ValueError(f"an expression derived from the input cannot be evaluated numerically: "
                             f"{type(exc).__name__}: {str(exc).splitlines()[0]}") from None
        values = [self.values[s] for s in names]

        def evaluate(*x: float) -> list[Any]:
            with working_digits(DIGITS):
                point = [mpmath.mpf(v) for v in list(x) + values]
                shared = fn_integrals(*point) if fn_integrals is not None else ()
                return [mpmath.mpmathify(r) for r in fn(*point, *shared)]

        return evaluate


def _without_step_derivatives(expr: sp.Expr) -> sp.Expr:
    """``expr`` with derivatives of floor and ceiling set to 0. sympy's antiderivatives of periodic
    functions (1/(2 + cos x)) hold floor((x - pi)/(2 pi)) to be continuous; its derivative is 0 away
    from the jumps, where random sample points fall with probability 1, and sympy leaves it
    unevaluated (``Derivative(floor(...))``), which lambdify cannot print."""
    if not isinstance(expr, sp.Basic) or not expr.has(sp.Derivative):
        return expr
    return expr.replace(lambda e: isinstance(e, sp.Derivative) and isinstance(e.expr, (sp.floor, sp.ceiling)),
                        lambda e: sp.S.Zero)


#: Where a density found by integration is checked numerically before it is used (inside (0, π/2)²,
#: away from the poles of angle charts; fixed points, not the sampler's draws).
_DENSITY_POINTS = ((0.35, 0.55), (0.7, 1.2), (1.05, 0.3), (1.3, 0.9))


def _unusable_density(rho: sp.Expr, log_rho: sp.Expr, A1: sp.Expr, A2: sp.Expr, q: tuple[sp.Symbol, sp.Symbol],
                      sampler: _Sampler) -> str | None:
    """Why a density from sympy's ``integrate`` cannot be used, or None: it must be a finite non-zero real
    number at :data:`_DENSITY_POINTS` (sympy's antiderivatives may carry complex constants), and a closed
    form must satisfy d ln rho = A2 dq1 - A1 dq2 there to 40 digits (a deterministic check, whether or not
    the exact proof is within the limits)."""
    exprs = [rho]
    if not log_rho.has(sp.Integral):
        exprs += [sp.diff(log_rho, q[0]) - A2, A2, sp.diff(log_rho, q[1]) + A1, A1]
    try:
        fn = sampler.function(exprs, q)
    except ValueError as exc:
        return str(exc)
    for point in _DENSITY_POINTS:
        values = fn(*point)
        at = f"{q[0]}={point[0]}, {q[1]}={point[1]}"
        if any(isinstance(v, mpmath.mpc) and v.imag != 0 for v in values):
            return f"is not real at {at}"
        values = [mpmath.re(v) for v in values]
        if not all(mpmath.isfinite(v) for v in values) or values[0] == 0:
            return f"is not a finite non-zero number at {at}"
        if len(values) > 1 and max(_relative(values[1], values[1:3]), _relative(values[3], values[3:5])) > NUMERIC_ZERO:
            return f"does not satisfy d ln rho = A2 dq1 - A1 dq2 at {at} (40 digits)"
    return None


def _relative(total: Any, terms: Sequence[Any]) -> float:
    scale = sum(abs(t) for t in terms)
    return float(abs(total) / scale) if scale else float(abs(total))


# --------------------------------------------------------------------------------------------------
# the Lagrangian


def _quadratic_lagrangian(L: sp.Expr, q: tuple[sp.Symbol, sp.Symbol], v: tuple[sp.Symbol, sp.Symbol],
                          sampler: _Sampler) -> tuple[sp.Matrix, sp.Matrix, sp.Expr]:
    """``(G, w, V)`` with ``L = ½ q̇ᵀG q̇ + (w, q̇) − V`` (Theorem 1: L quadratic in the velocities,
    not necessarily homogeneous).

    Raises
    ------
    ValueError
        If L is not a polynomial of degree ≤ 2 in the velocities (third derivatives non-zero at a
        random point), or if det G vanishes at every sampled point.
    """
    if not L.is_polynomial(*v):
        raise ValueError(f"the Lagrangian must be a polynomial of degree <= 2 in the velocities "
                         f"{', '.join(map(str, v))} (Theorem 1: L quadratic in the velocities)")
    third = [sp.diff(L, v[i], v[j], v[k]) for i in range(2) for j in range(i, 2) for k in range(j, 2)]
    fn = sampler.function(third, list(q) + list(v))
    for qq, vv in zip(sampler.coordinates(3), sampler.velocities(3)):
        if any(abs(x) > 1e-30 for x in fn(*qq, *vv)):
            raise ValueError("the Lagrangian has degree > 2 in the velocities; Theorem 1 needs a quadratic "
                             "function of the velocities (not necessarily homogeneous)")
    G = sp.Matrix(2, 2, lambda i, j: sp.diff(L, v[i], v[j]))
    w = sp.Matrix([sp.diff(L, vi).subs({v[0]: 0, v[1]: 0}) for vi in v])
    V = -L.subs({v[0]: 0, v[1]: 0})
    det = sampler.function([det2(G)] + list(G), list(q) + list(v))
    values = [det(*qq, *vv) for qq, vv in zip(sampler.coordinates(4), sampler.velocities(4))]
    if all(abs(x[0]) <= 1e-30 * sum(abs(g) for g in x[1:]) ** 2 for x in values):
        raise ValueError("the kinetic matrix d2L/dq_dot_i dq_dot_j is singular (det = 0 at every sampled point); "
                         "Theorem 1 needs det != 0")
    return G, w, V


def _check_coefficients(named: Mapping[str, sp.Expr], v: tuple[sp.Symbol, sp.Symbol]) -> None:
    for name, expr in named.items():
        if expr.has(*v):
            raise ValueError(f"{name} must depend on the coordinates only (eq. 2704-7), not on the velocities")


# --------------------------------------------------------------------------------------------------
# the result


def _string(x: Any) -> Any:
    if isinstance(x, sp.Basic):
        return sp.sstr(x)
    if isinstance(x, (float, int, np.floating, np.integer)) and not isinstance(x, bool):
        return float(x)
    if isinstance(x, dict):
        return {k: _string(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_string(v) for v in x]
    return x


@dataclass
class ReducingMultiplierResult:
    """Theorem 1 for one system: S in the momenta (eq. 2704-10), whether a density ρ(q) exists
    (None: undecided, with the reason), N = ρ, S̄ = N B (ERRATA 6), H̄(q, p), the bracket (2704-9), the
    verification of the flow, the monopole data, and the paper's equation for each item.

    ``momenta`` are the symbols p₁, p₂ of ``hamiltonian`` and ``bracket``; ``convention`` the one in
    which the verification holds."""

    A1: sp.Expr
    A2: sp.Expr
    B: sp.Expr
    measure_exists: bool | None
    integrability_condition: str
    reason: str
    density: sp.Expr | None
    reducing_multiplier: sp.Expr | None
    S_bar: sp.Expr | None
    hamiltonian: sp.Expr | None
    bracket: PoissonStructure | None
    verification: dict[str, Any]
    monopole: dict[str, Any] | None
    equations: dict[str, str]
    momenta: tuple[sp.Symbol, ...] = ()
    convention: str = ""

    def to_json(self) -> dict[str, Any]:
        """All sympy expressions as strings (``sp.sstr``), numbers as floats."""
        bracket = None
        if self.bracket is not None:
            b = self.bracket
            bracket = {"name": b.name, "equation": b.equation, "variables": [str(x) for x in b.variables],
                       "matrix": [[sp.sstr(x) for x in b.matrix.row(i)] for i in range(b.matrix.rows)],
                       "formula": b.formula, "convention": self.convention}
        return {
            "A1": _string(self.A1), "A2": _string(self.A2), "B": _string(self.B),
            "measure_exists": self.measure_exists,
            "integrability_condition": self.integrability_condition,
            "reason": self.reason,
            "density": _string(self.density), "reducing_multiplier": _string(self.reducing_multiplier),
            "S_bar": _string(self.S_bar), "hamiltonian": _string(self.hamiltonian),
            "momenta": [str(p) for p in self.momenta],
            "bracket": bracket,
            "verification": _string(self.verification),
            "monopole": _string(self.monopole),
            "equations": dict(self.equations),
            "convention": self.convention,
        }


def _momentum_symbols(q: tuple[sp.Symbol, sp.Symbol], taken: set[sp.Basic]) -> tuple[sp.Symbol, sp.Symbol]:
    names = {str(s) for s in taken}
    out = []
    for qi in q:
        name = f"p_{qi}"
        while name in names:
            name += "_"
        out.append(sp.Symbol(name, real=True))
    return out[0], out[1]


def _tidy(expr: sp.Expr, q: Sequence[sp.Symbol]) -> sp.Expr:
    """A cheap normal form: one fraction, cos² qᵢ reduced to 1 − sin² qᵢ in numerator and
    denominator, common factors cancelled, then both factored."""
    n, d = sp.fraction(sp.together(expr))
    n, d = sp.fraction(sp.cancel(_reduce_cos_squares(n, q) / _reduce_cos_squares(d, q)))
    return sp.factor(n) / sp.factor(d)


def _tidy_within(expr: sp.Expr, q: Sequence[sp.Symbol], limits: WorkLimits) -> sp.Expr:
    """:func:`_tidy` of ``expr`` if it has at most ``limits.max_tidy_ops`` operations (and sympy does not
    raise), else ``expr`` over a common denominator: equal either way, only not shortened."""
    if over(operations(expr), limits.max_tidy_ops, "max_tidy_ops") is not None:
        return sp.together(expr)
    status, value = _run(_tidy, (expr, tuple(q)))
    return value if status == "done" else sp.together(expr)


def _pointwise_flow(L: sp.Expr, q: tuple[sp.Symbol, sp.Symbol], v: tuple[sp.Symbol, sp.Symbol], S: sp.Expr,
                    N: sp.Expr, S_bar: sp.Expr, H_bar: sp.Expr, p: tuple[sp.Symbol, sp.Symbol],
                    sampler: _Sampler, points: int = 6) -> tuple[float, float]:
    """Max relative residual |flow − X|₁ / (|flow|₁ + |X|₁) of the τ-flow against {x, H̄}
    (Theorem 1) and against ``hamiltonian_vector_field(H̄)`` (brackets.py) at random (q, q̇), with
    the actual N (differentiated symbolically), 40 digits.

    Evaluated in stages (q̈ from eq. 2704-7; p = N ∂L/∂q̇ and its derivatives; then the field of H̄
    at (q, p)) so that no expression is substituted into another: the same quantities as
    :func:`nonholonomic.hamiltonization.theorem_1.flow_fields`, without the expression swell."""
    G = sp.Matrix(2, 2, lambda i, j: sp.diff(L, v[i], v[j]))
    rhs = (sp.Matrix([v[1] * S, -v[0] * S]) + sp.Matrix([sp.diff(L, qi) for qi in q])
           - sp.Matrix(2, 2, lambda i, j: sp.diff(L, v[i], q[j])) * sp.Matrix(v))
    p_of = [N * sp.diff(L, vi) for vi in v]
    stage1 = list(G) + list(rhs) + [N] + p_of + [sp.diff(pi, x) for pi in p_of for x in (*q, *v)]
    f1 = sampler.function(stage1, list(q) + list(v))
    field_py = generalized_chaplygin_bracket(S_bar, q, p).hamiltonian_vector_field(H_bar)
    f2 = sampler.function(list(field_py), list(q) + list(p))
    worst_t1 = worst_py = 0.0
    with working_digits(DIGITS):
        for qq, vv in zip(sampler.coordinates(points), sampler.velocities(points)):
            vals = f1(*qq, *vv)
            Gm = mpmath.matrix([[vals[0], vals[1]], [vals[2], vals[3]]])
            qdd = mpmath.lu_solve(Gm, mpmath.matrix([vals[4], vals[5]]))
            n, pp, dp = vals[6], vals[7:9], vals[9:]
            flow = [mpmath.mpf(vv[0]) / n, mpmath.mpf(vv[1]) / n] + [
                (dp[4 * i] * vv[0] + dp[4 * i + 1] * vv[1] + dp[4 * i + 2] * qdd[0] + dp[4 * i + 3] * qdd[1]) / n
                for i in range(2)]
            py = f2(*qq, *pp)
            t1 = [-x for x in py]
            scale = sum(abs(x) for x in flow) + sum(abs(x) for x in t1)
            worst_t1 = max(worst_t1, float(sum(abs(a - b) for a, b in zip(flow, t1)) / scale))
            worst_py = max(worst_py, float(sum(abs(a - b) for a, b in zip(flow, py)) / scale))
    return worst_t1, worst_py


def hamiltonize(lagrangian: sp.Expr, coordinates: tuple[sp.Symbol, sp.Symbol], velocities: tuple[sp.Symbol, sp.Symbol],
                a1: sp.Expr, a2: sp.Expr, b: sp.Expr, potential: sp.Expr | None = None,
                parameters: Mapping[sp.Symbol, float] | None = None,
                domain: tuple[tuple[float, float], tuple[float, float]] | None = None,
                shift: tuple[sp.Expr, sp.Expr] | None = None,
                multiplier_symbol: sp.Symbol | None = None,
                limits: WorkLimits = work_limits.DEFAULT) -> ReducingMultiplierResult:
    """Theorem 1 for the generalized Chaplygin system (2704-7) with Lagrangian ``L − U``.

    Parameters
    ----------
    lagrangian : L(q, q̇), a polynomial of degree ≤ 2 in the velocities (Theorem 1: quadratic, not
        necessarily homogeneous) with det ∂²L/∂q̇∂q̇ ≠ 0.
    coordinates, velocities : (q₁, q₂) and (q̇₁, q̇₂).
    a1, a2, b : S = a₁(q) q̇₁ + a₂(q) q̇₂ + b(q) (eq. 2704-7).
    potential : U(q), subtracted from L (None: already in L).
    parameters : values of constants for the numeric checks (the symbolic work keeps them as symbols);
        constants without a value get random values in (1.1, 2.9), reported in the details.
    domain : optional chart ((q₁ min, max), (q₂ min, max)); if given, ``monopole`` is
        :func:`monopole_charge` of S̄ over it.
    shift : optional (W₁, W₂) for :func:`monopole_charge`: p̃ = p − W are smooth fibre coordinates
        (needs ``domain``). May contain ``multiplier_symbol``, which stands for N found here
        (e.g. the ball: W = (0, c N cos θ)).
    multiplier_symbol : the symbol standing for N in ``shift``.
    limits : the deterministic sizes of the symbolic steps (:class:`nonholonomic.work_limits.WorkLimits`):
        the density ansatz, the closedness proof and the proof of a density found by integration are
        tried on at most ``max_proof_ops`` operations, sympy's ``integrate`` on at most
        ``max_integrate_ops`` (past it the line integral is left unevaluated), the normal forms of A₁,
        A₂, B, G, w, V on at most ``max_tidy_ops``. Every step runs to its end; the same input gives
        the same result on every machine.

    Returns
    -------
    ReducingMultiplierResult
        A₁, A₂, B (eq. 2704-10); ``measure_exists`` from the integrability condition
        ∂A₁/∂q₁ + ∂A₂/∂q₂ = 0 (proof of Theorem 1: False with the failing residual, None if
        undecided, the reason naming the limit or sympy's error); ρ with ∂ ln ρ/∂q₁ = A₂,
        ∂ ln ρ/∂q₂ = −A₁ (up to a constant factor); N = ρ; S̄ = N B (ERRATA 6); H̄(q, p) = H(q, p/N);
        the bracket (2704-9); the verification that the τ-flow is dx/dτ = {x, H̄} (Theorem 1's
        convention).

    Raises
    ------
    ValueError
        If L is not quadratic in the velocities, its kinetic matrix is singular, or a₁, a₂, b, U
        depend on the velocities.
    nonholonomic.bounded.SafetyCapExceeded
        If a symbolic step outlives the service's safety cap (a failure, not a verdict).
    """
    q = (coordinates[0], coordinates[1])
    v = (velocities[0], velocities[1])
    a1, a2, b = (sp.expand_trig(sp.sympify(x)) for x in (a1, a2, b))
    U = sp.Integer(0) if potential is None else sp.expand_trig(sp.sympify(potential))
    _check_coefficients({"a1": a1, "a2": a2, "b": b, "potential": U}, v)
    L = sp.expand_trig(sp.sympify(lagrangian)) - U
    taken = L.free_symbols | a1.free_symbols | a2.free_symbols | b.free_symbols | set(q) | set(v)
    constants = tuple(sorted(taken - set(q) - set(v), key=str))
    given = {sp.sympify(k): float(val) for k, val in (parameters or {}).items()}
    sampler = _Sampler(given, tuple(s for s in constants if s not in given))
    G, w, V = _quadratic_lagrangian(L, q, v, sampler)

    # Legendre transform (eq. 2704-10): q̇ = G⁻¹(P − w), S = (a, G⁻¹(P − w)) + b
    G = G.applyfunc(lambda e: _tidy_within(e, q, limits))
    w = w.applyfunc(lambda e: _tidy_within(e, q, limits))
    V = _tidy_within(V, q, limits)
    # L in the normal form ½ q̇ᵀGq̇ + (w, q̇) − V (equal to L; smaller to differentiate)
    L_normal = (sp.Matrix(v).T * G * sp.Matrix(v))[0, 0] / 2 + (w.T * sp.Matrix(v))[0, 0] - V
    detG = _tidy_within(det2(G), q, limits)
    Ginv = adj2(G) / detG
    avec = sp.Matrix([a1, a2])
    A = Ginv * avec
    A1, A2 = _tidy_within(A[0], q, limits), _tidy_within(A[1], q, limits)
    B = _tidy_within(b - (avec.T * Ginv * w)[0, 0], q, limits)
    S = a1 * v[0] + a2 * v[1] + b
    p = _momentum_symbols(q, taken)
    P = (sp.Dummy("P1"), sp.Dummy("P2"))
    H_of_P = ((sp.Matrix(P) - w).T * Ginv * (sp.Matrix(P) - w))[0, 0] / 2 + V

    # integrability condition: d(A2 dq1 − A1 dq2) = 0
    d1, d2 = sp.diff(A1, q[0]), sp.diff(A2, q[1])
    condition = d1 + d2
    n1, n2 = str(q[0]), str(q[1])
    condition_text = (f"dA1/d{n1} + dA2/d{n2} = 0 (the 1-form A2 d{n1} - A1 d{n2} = d ln rho must be closed; "
                      "proof of Theorem 1)")
    fn = sampler.function([d1, d2], q)
    worst, worst_at = 0.0, (0.0, 0.0)
    for qq in sampler.coordinates(8):
        t1, t2 = fn(*qq)
        r = _relative(t1 + t2, (t1, t2))
        if np.isfinite(r) and r >= worst:
            worst, worst_at = r, tuple(qq)
    base: dict[str, Any] = dict(A1=A1, A2=A2, B=B, momenta=p, convention="dx/dtau = {x, H_bar} (Theorem 1)")

    if worst > NUMERIC_ZERO:
        shown = _tidy_within(condition, q, limits)
        reason = (f"the integrability condition dA1/d{n1} + dA2/d{n2} = 0 fails: it equals {sp.sstr(shown)}; relative "
                  f"value |dA1/d{n1} + dA2/d{n2}| / (|dA1/d{n1}| + |dA2/d{n2}|) = {worst:.3g} at "
                  f"{n1}={worst_at[0]:.4f}, "
                  f"{n2}={worst_at[1]:.4f}{sampler.note()} (40 digits); so no invariant measure rho(q) dP1 dP2 dq1 dq2 "
                  "exists and Theorem 1 gives no reducing multiplier N(q)")
        return ReducingMultiplierResult(
            measure_exists=False, integrability_condition=f"{condition_text}; simplified value: {sp.sstr(shown)}",
            reason=reason, density=None, reducing_multiplier=None, S_bar=None, hamiltonian=None, bracket=None,
            verification={"method": "pointwise", "residual": worst, "passed": None,
                          "detail": "no multiplier to verify; residual is that of the integrability condition"},
            monopole=None, equations=dict(EQUATIONS), **base)

    # the density: an exact ansatz first (its proof also proves closedness), then sympy integration
    rho, how, exact_density = None, "", False
    tried: list[str] = []  # why each search found nothing (the reason when no density is found)
    skipped = over(operations(A1, A2, detG), limits.max_proof_ops, "max_proof_ops", "the ansatz")
    if skipped is None:
        status, found = _run(_density_ansatz, (A1, A2, (detG,), q, tuple(sampler.values.items())))
        if status == "done" and found is not None:
            (rho, how), exact_density = found, True
        tried.append("the ansatz " + ("found none" if status == "done" else f"failed ({found})"))
    else:
        tried.append(skipped)
    closed_proven = exact_density
    if exact_density:
        closed_detail = "implied by the exact density (d ln rho = A2 dq1 - A1 dq2 proved)"
    else:
        numeric = f"zero at 8 random points to {worst:.1e} (40 digits); "
        skipped = over(operations(condition), limits.max_proof_ops, "max_proof_ops", "symbolic proof")
        if skipped is not None:
            status, closed = "skipped", None
            closed_detail = numeric + skipped
        else:
            status, closed = _run(rational_trig_is_zero, (sp.together(condition), q))
            closed_proven = status == "done" and closed is True
            closed_detail = ("proved identically zero" if closed_proven else numeric + "symbolic proof: " + (
                f"sympy could not decide: {closed}" if status == "error" else
                "undecided (not rational in q, sin q, cos q and the parameters)"))
        if status == "done" and closed is False:  # numerically tiny but not identically zero
            return ReducingMultiplierResult(
                measure_exists=False, integrability_condition=f"{condition_text}; not identically zero",
                reason=f"the integrability condition dA1/d{n1} + dA2/d{n2} = 0 fails (its numerator is not "
                       f"identically zero) although it is below {worst:.1e} at the sampled points",
                density=None, reducing_multiplier=None, S_bar=None, hamiltonian=None, bracket=None,
                verification={"method": "symbolic", "residual": worst, "passed": None, "detail": "no multiplier"},
                monopole=None, equations=dict(EQUATIONS), **base)
        searches = ((_density_by_integration, "sympy integrate",
                     over(operations(A1, A2), limits.max_integrate_ops, "max_integrate_ops", "sympy integrate"), ()),
                    (_density_line_integral, "the line integral", None, (limits.max_integrate_ops,)))
        for attempt, name, skipped, extra in searches:
            if skipped is not None:
                tried.append(skipped)
                continue
            status, found = _run(attempt, (A1, A2, q, *extra))
            if status != "done" or found is None:
                tried.append(f"{name} " + ("found none" if status == "done" else f"failed ({found})"))
                continue
            unusable = _unusable_density(found[0], found[2], A1, A2, q, sampler)
            if unusable is not None:
                tried.append(f"{name}: its density {unusable}")
                continue
            unproved = over(operations(found[2], A1, A2), limits.max_proof_ops, "max_proof_ops", "its proof")
            holds: bool | None = None
            if unproved is None:
                status, holds = _run(_density_equations_hold, (found[2], A1, A2, q))
                if status == "done" and holds is False:  # sympy's antiderivative is wrong: do not use it
                    tried.append(f"{name} gave a wrong antiderivative")
                    continue
                if status != "done":
                    unproved, holds = f"its proof failed (sympy: {holds})", None
            rho, how = found[0], found[1]
            exact_density = holds is True
            how += "; d ln rho = A2 dq1 - A1 dq2 " + (
                "proved exactly" if exact_density
                else "not proved symbolically" + (f": {unproved}" if unproved else ""))
            break
    integrability = f"{condition_text}; simplified value: 0 ({closed_detail})"
    equations = {**EQUATIONS, "density_method": how}
    measure_exists: bool | None = True if closed_proven else None
    reason = "" if closed_proven else "undecided: " + closed_detail
    if rho is None:
        reason += "; no density found (" + "; ".join(tried) + ")"
        return ReducingMultiplierResult(
            measure_exists=measure_exists, integrability_condition=integrability, reason=reason.lstrip("; "),
            density=None, reducing_multiplier=None, S_bar=None, hamiltonian=None, bracket=None,
            verification={"method": "pointwise", "residual": worst, "passed": None, "detail": reason.lstrip("; ")},
            monopole=None, equations=equations, **base)

    N = rho
    S_bar = N * B
    H_bar = H_of_P.xreplace({P[0]: p[0] / N, P[1]: p[1] / N})
    bracket = generalized_chaplygin_bracket(S_bar, q, p, parameters=constants)

    # verification: pointwise with the actual N; symbolic = Theorem 1 for arbitrary data + exact density
    res_t1, res_py = _pointwise_flow(L_normal, q, v, S, N, S_bar, H_bar, p, sampler)
    passed_pw = bool(np.isfinite(res_t1) and res_t1 <= POINTWISE_TOLERANCE)
    theorem, theorem_detail = prove_theorem_1()
    symbolic = theorem and closed_proven and exact_density
    verification = {
        "method": "symbolic" if symbolic and passed_pw else "pointwise",
        "residual": res_t1,
        "passed": passed_pw and theorem,
        "detail": (f"convention of Theorem 1, dx/dtau = {{x, H_bar}} = P grad H_bar, P the matrix of eq. 2704-9: max "
                   f"relative residual {res_t1:.2e} at 6 random (q, q_dot) (40 digits, actual N differentiated)"
                   f"{sampler.note()}; brackets.py's hamiltonian_vector_field(H_bar) = -P grad H_bar "
                   f"(dx/dtau = {{H, x}}) gives {res_py:.2e}: in that convention the same flow needs the bracket with "
                   f"the opposite sign ({{q_i, p_j}} = -delta_ij, {{p1, p2}} = -S_bar). Symbolic: {theorem_detail}; "
                   f"this rho: {how}; closedness: {closed_detail}"),
        "pointwise_residual_brackets_py_convention": res_py,
        "symbolic": symbolic if closed_proven else None,
    }
    if domain is not None:
        W = None if shift is None else tuple(
            sp.sympify(w).xreplace({multiplier_symbol: N} if multiplier_symbol is not None else {}) for w in shift)
        monopole = monopole_charge(S_bar, q, domain, sampler.values, shift=W)
        monopole["detail"] += sampler.note()
    elif B == 0:
        monopole = {"integral": 0.0, "exact": True, "detail": "S_bar = 0: no gyroscopic 2-form"}
    else:
        monopole = {"integral": None, "exact": None,
                    "detail": "give the chart's domain (hamiltonize(..., domain=...) or monopole_charge) to integrate "
                              "the gyroscopic 2-form S_bar dq1^dq2"}
    return ReducingMultiplierResult(
        measure_exists=measure_exists, integrability_condition=integrability, reason=reason,
        density=rho, reducing_multiplier=N, S_bar=S_bar, hamiltonian=H_bar, bracket=bracket,
        verification=verification, monopole=monopole, equations=equations, **base)
