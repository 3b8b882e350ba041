"""Hamiltonian forms of two nonholonomic systems after the paper's time substitutions.

1. Veselova → e(3) (section "Veselova system", eq. 2504-10-2, 2504-11 and the inverse map after it)::

       M = ρ_ω I^(1/2) ω,   Γ = ρ_ω⁻¹ I^(−1/2) γ,   ρ_ω = (γ, I⁻¹γ)^(1/2) = (Γ, IΓ)^(−1/2),
       dτ = dt / (ρ_ω √det I),   H = ½ (Γ, IΓ) M² + Ũ(Γ),   Ũ(Γ) = U(γ(Γ)),
       ω = (Γ, IΓ)^(1/2) I^(−1/2) M,   γ = (Γ, IΓ)^(−1/2) I^(1/2) Γ,

   with the e(3) bracket. The paper's Ũ(Γ) = U(ρ_ω I^(1/2) Γ) is the same function once ρ_ω is read
   as (Γ, IΓ)^(−1/2). The map sends |γ| = 1, (ω, γ) = 0 onto the symplectic leaf Γ² = 1, (M, Γ) = 0
   ((M, Γ) = (ω, γ) and Γ² = 1 hold for every γ ≠ 0); the text's "(M, γ) = 0" (twice) must be read
   (M, Γ) = 0. For U = 0 the integral (2504-5) becomes F = (IM, M)(IΓ, Γ) − (IM, Γ)², which under
   the map equals (Iω, Iω)(γ, γ) − (Iω, γ)² = |Iω × γ|² for every γ (Lagrange's identity), and
   {H, F} = 2 (M, Γ)(Γ, IΓ)(IΓ, IM × M) vanishes exactly on the leaf (M, Γ) = 0.
   Theorem 2's reducing multiplier N = ρ_ω⁻¹ (ERRATA 3; the printed (γ, Iγ)^(−1/2) fails) gives the
   same τ up to the constant factor √det I, i.e. H / √det I in that time.

2. Chaplygin's ball → (L, γ) (section "Chaplygin's ball", eq. 2604-5 … 2604-7)::

       dτ = ρ_μ dt,   L = ρ_μ M,   ρ_μ = (det I_Q)^(−1/2),
       H = det J / 2 ((1 − D (γ, J⁻¹γ)) (L, J⁻¹L) + D (J⁻¹L, γ)²) + U(γ),

   with the bracket (2604-6); the text's "dM_k/dτ = {H, M_k}" means dL_k/dτ = {H, L_k} and "the
   energy (2504-2)" means (2604-2) (ERRATA 5). H is ½(L, adj(I_Q) L) + U = ½(M, I_Q⁻¹M) + U.

Sign convention (the paper's, ERRATA 4): dx_i/dτ = {H, x_i} = −(P ∇H)_i with P_ij = {x_i, x_j}, as in
:meth:`nonholonomic.hamiltonization.poisson.PoissonStructure.hamiltonian_vector_field`.

The potential U(γ) is read off the system's own energy integral, U = E|_(velocity = 0) (the kinetic
energy is a quadratic form in ω, resp. M), so no potential is written twice and every potential of
the system modules is covered.

Checks (:func:`hamiltonian_form_evidence`): the pushforward of the system's field through the map,
divided by dτ/dt, equals the Hamiltonian field — symbolically (below) and pointwise at trajectory
samples; the same in the original time t as a control (it must fail); the energy equals H under the
map; from ∘ to = identity; and, for U = 0, F in the new variables.

Symbolic proof (:func:`symbolic_flow_identity`), parameters kept symbolic: the identity is pulled back
to the bracket side. Veselova: Γ is the stereographic image of (u, v), M = Γ × (w1, w2, 0) spans
(M, Γ) = 0, I_i = j_i² makes I^(1/2) rational; the only irrational function left is
s = (Γ, IΓ)^(1/2) (and ρ_ω = 1/s at from(y), checked). Ball: no restriction is needed, the identity
holds on all of R⁶; J_i = c_i² leaves s = (1 − D (γ, J⁻¹γ))^(1/2). Every component's numerator,
a polynomial A(s²) + s B(s²), is reduced with s² = radicand in a sparse polynomial ring over QQ;
A = B = 0 proves it. Otherwise one exact evaluation (50 digits) at a random rational point with a
non-zero value disproves it; if neither, the verdict is None. The proof runs to its end and is cached
per process (:mod:`nonholonomic.bounded`); it is tried only on a form and field of at most
``max_proof_ops`` sympy operations (:mod:`nonholonomic.work_limits`), else the verdict is None with
that reason, the same on every machine.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cache, lru_cache

import numpy as np
import sympy as sp

from nonholonomic import bounded, work_limits
from nonholonomic.definition import MechanicalSystem, dot
from nonholonomic.evidence.measure import CheckEvidence
from nonholonomic.hamiltonization.poisson import PoissonStructure, chaplygin_ball_bracket, e3
from nonholonomic.numerics.kernels import VectorKernel, numeric, vectorize
from nonholonomic.systems import chaplygin_ball as ball, veselova as ves
from nonholonomic.work_limits import WorkLimits, operations, over

#: Pointwise relative residual accepted as round-off.
POINTWISE_TOLERANCE = 1e-10
#: The original-time control "passes" (shows the time substitution is needed) above this residual.
CONTROL_THRESHOLD = 1e-6


@dataclass(frozen=True)
class HamiltonianForm:
    """A system written as a Hamiltonian system after a time substitution.

    Attributes
    ----------
    system_kind : the :class:`MechanicalSystem` kind.
    bracket : the Poisson structure, in the new variables ``bracket.variables``.
    to_bracket_variables : the new variables as expressions in the system's state symbols.
    from_bracket_variables : the system's state (in ``system.state_symbols`` order) in terms of
        ``bracket.variables``; same parameter symbols as the system. With ``from_indices``, only the
        state components at those indices (a Chaplygin reduction's shape coordinates and velocities: the
        cyclic coordinates are not functions of the bracket variables).
    hamiltonian : H in the bracket variables and parameters.
    time_density : ``dτ/dt`` in the system's state (dx/dτ = (1/time_density) dx/dt).
    formula, equation : the map, time and H, and the paper's equation labels.
    extra_integrals : ``(name, expression in bracket variables, equation)``.
    """

    system_kind: str
    bracket: PoissonStructure
    to_bracket_variables: tuple[sp.Expr, ...]
    from_bracket_variables: tuple[sp.Expr, ...]
    hamiltonian: sp.Expr
    time_density: sp.Expr
    formula: str
    equation: str
    extra_integrals: tuple[tuple[str, sp.Expr, str], ...] = ()
    proof: tuple[bool | None, str] | None = None
    """The symbolic flow identity's verdict when it comes with the form (Theorem 1 for a user's
    system); None: proved here on the leaf (:func:`symbolic_flow_identity`)."""
    from_indices: tuple[int, ...] | None = None


# --- the forms ------------------------------------------------------------------------------------

def potential_of(system: MechanicalSystem) -> sp.Expr:
    """U(γ) of ``system``: its energy integral at zero velocity (the first state vector: ω or M).

    The kinetic energy of both systems is a quadratic form in that vector, so ``E|_(v = 0) = U``.
    """
    energy = next(i.expression for i in system.integrals if i.name == "energy")
    return energy.xreplace({s: sp.Integer(0) for s in system.state[0].symbols})


def _veselova_form(system: MechanicalSystem) -> HamiltonianForm:
    """Eq. (2504-10-2), (2504-11) and the inverse map after them (see the module docstring)."""

    inertia = ves.inertia
    sqrt_I = sp.diag(*[sp.sqrt(i) for i in (ves.I1, ves.I2, ves.I3)])
    inv_sqrt_I = sp.diag(*[1 / sp.sqrt(i) for i in (ves.I1, ves.I2, ves.I3)])
    rho = ves.measure_density()  # ρ_ω = (γ, I⁻¹γ)^(1/2), eq. (2504-4)
    M_of = rho * sqrt_I * ves.omega
    Gamma_of = inv_sqrt_I * ves.gamma / rho

    bracket = e3()
    M, G = sp.Matrix(bracket.variables[:3]), sp.Matrix(bracket.variables[3:])
    GIG = dot(G, inertia * G)  # (Γ, IΓ) = ρ_ω⁻² on |γ| = 1
    gamma_of = sqrt_I * G / sp.sqrt(GIG)
    omega_of = sp.sqrt(GIG) * inv_sqrt_I * M
    U_tilde = potential_of(system).xreplace(dict(zip(ves.gamma, gamma_of)))
    H = GIG * dot(M, M) / 2 + U_tilde

    extra: tuple[tuple[str, sp.Expr, str], ...] = ()
    if system.potential == "zero":
        IM = inertia * M
        extra = (("F", dot(IM, M) * GIG - dot(IM, G) ** 2, "2504-5 in (M, Gamma)"),)
    if system.reduced_time is None:  # pragma: no cover - the system module defines it
        raise ValueError("veselova has no reduced time")
    return HamiltonianForm(
        system_kind=system.kind,
        bracket=bracket,
        to_bracket_variables=tuple(M_of) + tuple(Gamma_of),
        from_bracket_variables=tuple(omega_of) + tuple(gamma_of),
        hamiltonian=H,
        time_density=system.reduced_time.density,
        formula=("M = rho_omega I^(1/2) omega, Gamma = rho_omega^-1 I^(-1/2) gamma, "
                 "rho_omega = (gamma, I^-1 gamma)^(1/2) "
                 "= (Gamma, I Gamma)^(-1/2); d tau = dt / (rho_omega sqrt(det I)); "
                 "H = (Gamma, I Gamma) M^2 / 2 + U(gamma(Gamma)), "
                 "gamma(Gamma) = (Gamma, I Gamma)^(-1/2) I^(1/2) Gamma; "
                 "e(3) bracket, dx/dtau = {H, x}"),
        equation="2504-10-2, 2504-11",
        extra_integrals=extra,
    )


def _ball_form(system: MechanicalSystem) -> HamiltonianForm:
    """Eq. (2604-5) … (2604-7), read as in ERRATA 5 (dL_k/dτ = {H, L_k}, H = energy 2604-2)."""

    rho = ball.measure_density()  # ρ_μ = det(I_Q)^(−1/2), eq. (2604-3)
    bracket = chaplygin_ball_bracket()
    L = sp.Matrix(bracket.variables[:3])
    g = sp.Matrix(bracket.variables[3:])
    if tuple(g) != tuple(ball.gamma):  # pragma: no cover - the bracket is written in the ball's γ
        raise ValueError("the bracket's gamma symbols differ from the ball's")
    J_inv = ball.J_inv
    # eq. (2604-7)
    H = ball.det_J / 2 * ((1 - ball.D * dot(g, J_inv * g)) * dot(L, J_inv * L) + ball.D * dot(J_inv * L, g) ** 2) \
        + potential_of(system)
    M_of_L = L * sp.sqrt(ball.contact_inertia_determinant(g))  # M = L / ρ_μ
    extra: tuple[tuple[str, sp.Expr, str], ...] = ()
    if system.potential == "zero":
        extra = (("F", dot(L, L) * ball.contact_inertia_determinant(g),
                  "2604-4 in (L, gamma): F = M^2 = L^2 / rho_mu^2"),)
    if system.reduced_time is None:  # pragma: no cover
        raise ValueError("chaplygin_ball has no reduced time")
    return HamiltonianForm(
        system_kind=system.kind,
        bracket=bracket,
        to_bracket_variables=tuple(rho * ball.M) + tuple(ball.gamma),
        from_bracket_variables=tuple(M_of_L) + tuple(g),
        hamiltonian=H,
        time_density=system.reduced_time.density,
        formula=("L = rho_mu M, rho_mu = det(I_Q)^(-1/2); d tau = rho_mu dt; "
                 "H = det J / 2 ((1 - D (gamma, J^-1 gamma)) (L, J^-1 L) + D (J^-1 L, gamma)^2) + U(gamma); "
                 "bracket (2604-6), dx/dtau = {H, x}"),
        equation="2604-5, 2604-6, 2604-7",
        extra_integrals=extra,
    )


@cache
def hamiltonian_form(system: MechanicalSystem) -> HamiltonianForm | None:
    """The Hamiltonian form of ``system`` after the paper's time substitution, or None.

    Parameters
    ----------
    system : a Veselova (eq. 2504-10-2, 2504-11) or Chaplygin-ball (eq. 2604-5 … 2604-7) system
        with any of its potentials; other kinds give None.
    """
    if system.hamiltonian_form is not None:
        return system.hamiltonian_form
    if system.kind == "veselova":
        return _veselova_form(system)
    if system.kind == "chaplygin_ball":
        return _ball_form(system)
    return None


# --- numeric kernels ------------------------------------------------------------------------------

@dataclass(frozen=True)
class _FlowKernels:
    to: VectorKernel            # x ↦ y
    back: VectorKernel          # y ↦ x
    pushforward: VectorKernel   # x ↦ (∂y/∂x) f(x), d/dt of the bracket variables
    time_density: VectorKernel  # x ↦ dτ/dt
    hamiltonian_field: VectorKernel  # y ↦ {H, y}
    hamiltonian: VectorKernel   # y ↦ H
    extra_integrals: VectorKernel  # y ↦ the form's extra integrals


@lru_cache(maxsize=64)
def _kernels(form: HamiltonianForm, system: MechanicalSystem) -> _FlowKernels:
    x, p, y = system.state_symbols, system.parameter_symbols, form.bracket.variables
    missing = set(form.bracket.parameters) - set(p)
    if missing:
        raise ValueError(f"bracket parameters {sorted(map(str, missing))} are not parameters of {system.kind}")
    push = sp.Matrix(form.to_bracket_variables).jacobian(x) * sp.Matrix(system.rhs)
    return _FlowKernels(
        to=vectorize(form.to_bracket_variables, x + p),
        back=vectorize(form.from_bracket_variables, y + p),
        pushforward=vectorize(list(push), x + p),
        time_density=vectorize([form.time_density], x + p),
        hamiltonian_field=vectorize(form.bracket.hamiltonian_vector_field(form.hamiltonian), y + p),
        hamiltonian=vectorize([form.hamiltonian], y + p),
        extra_integrals=vectorize([e for _, e, _ in form.extra_integrals] or [sp.Integer(0)], y + p),
    )


def flow_residual(form: HamiltonianForm, system: MechanicalSystem, states: np.ndarray, parameters: np.ndarray,
                  *, time: str = "tau") -> float:
    """``max |(∂y/∂x) f / N − {H, y}| / max |{H, y}|`` over ``states`` (y = the bracket variables).

    Parameters
    ----------
    states : rows in ``system.state_symbols`` order (on the constraint manifold for Veselova).
    parameters : in ``system.parameter_symbols`` order.
    time : ``"tau"`` divides the pushforward by N = dτ/dt (d/dτ = (1/N) d/dt); ``"t"`` does not
        (the control: the field in the original time).
    """
    if time not in ("tau", "t"):
        raise ValueError(f"time must be 'tau' or 't', got {time!r}")
    k = _kernels(form, system)
    X = np.atleast_2d(np.asarray(states, dtype=float))
    p = np.asarray(parameters, dtype=float)
    push = k.pushforward(X, p)
    if time == "tau":
        push = push / k.time_density(X, p)
    field = k.hamiltonian_field(k.to(X, p), p)
    scale = float(np.max(np.abs(field)))
    return float(np.max(np.abs(push - field)) / (scale if scale > 0 else 1.0))


def time_density_spread(form: HamiltonianForm, system: MechanicalSystem, states: np.ndarray,
                        parameters: np.ndarray) -> float:
    """``max N / min N − 1`` over ``states``: how far N = dτ/dt is from constant along them."""
    N = _kernels(form, system).time_density(np.atleast_2d(states), np.asarray(parameters, dtype=float))[:, 0]
    return float(np.max(N) / np.min(N) - 1)


# --- the symbolic proof ---------------------------------------------------------------------------

@dataclass(frozen=True)
class _Leaf:
    """A rational parametrisation of the leaf in the bracket variables, with one square root.

    ``s`` stands for ``sqrt(radicand)`` (in y); ``relation`` is ``s²`` on the parametrisation;
    ``x_radicand`` is the system-side radicand (in x) and ``x_root`` its square root in terms of
    (y, s), verified on the parametrisation before use.
    """

    param_subs: dict[sp.Symbol, sp.Expr]
    point: dict[sp.Symbol, sp.Expr]
    s: sp.Symbol
    radicand: sp.Expr
    relation: sp.Expr
    x_radicand: sp.Expr
    x_root: sp.Expr
    description: str


def _stereographic(u: sp.Symbol, v: sp.Symbol) -> sp.Matrix:
    d = 1 + u**2 + v**2
    return sp.Matrix([2 * u / d, 2 * v / d, (1 - u**2 - v**2) / d])


def _root_base(radicand: sp.Expr) -> sp.Expr:
    """The base sympy keeps under the root of ``sqrt(radicand)`` (positive factors are pulled out)."""
    bases = [f.base for f in sp.Mul.make_args(sp.sqrt(radicand)) if _is_root(f)]
    if len(bases) != 1:
        raise ValueError(f"expected one square root in sqrt({radicand}), got {bases}")
    return bases[0]


def _veselova_leaf(form: HamiltonianForm) -> _Leaf:

    j = sp.symbols("j1:4", positive=True)
    param_subs = {ves.I1: j[0] ** 2, ves.I2: j[1] ** 2, ves.I3: j[2] ** 2}  # I^(1/2) = diag(j)
    u, v, w1, w2 = sp.symbols("u v w1 w2", real=True)
    G = _stereographic(u, v)
    M = G.cross(sp.Matrix([w1, w2, 0]))  # spans the tangent plane (M, Γ) = 0 where Γ3 ≠ 0
    y = form.bracket.variables
    point = dict(zip(y, list(M) + list(G)))
    Gs = sp.Matrix(y[3:])
    radicand = _root_base(dot(Gs, ves.inertia * Gs).xreplace(param_subs))
    x_radicand = _root_base(dot(ves.gamma, ves.inertia_inv * ves.gamma).xreplace(param_subs))
    s = sp.Symbol("s", positive=True)
    return _Leaf(param_subs, point, s, radicand, radicand.xreplace(point), x_radicand, 1 / s,
                 "Gamma = stereographic(u, v) on Gamma^2 = 1, M = Gamma x (w1, w2, 0) on (M, Gamma) = 0, I_i = j_i^2, "
                 "s = (Gamma, I Gamma)^(1/2), rho_omega = 1/s")


def _ball_leaf(form: HamiltonianForm) -> _Leaf:

    c = sp.symbols("c1:4", positive=True)
    param_subs = {ball.I1: c[0] ** 2 - ball.D, ball.I2: c[1] ** 2 - ball.D, ball.I3: c[2] ** 2 - ball.D}  # J_i = c_i^2
    radicand = _root_base(ball.contact_inertia_determinant(ball.gamma).xreplace(param_subs))
    s = sp.Symbol("s", positive=True)
    # No parametrisation: the identity is checked on all of R^6 (γ need not be a unit vector).
    return _Leaf(param_subs, {}, s, radicand, radicand, radicand, s,
                 "all of R^6 (L, gamma free), I_i = c_i^2 - D, s = (1 - D (gamma, J^-1 gamma))^(1/2) = "
                 "1/(rho_mu sqrt(det J))")


_LEAVES: dict[str, Callable[[HamiltonianForm], _Leaf]] = {"veselova": _veselova_leaf, "chaplygin_ball": _ball_leaf}


def _is_root(e: sp.Basic) -> bool:
    return bool(e.is_Pow and e.exp.is_Rational and not e.exp.is_Integer)


def _roots_to_symbol(expr: sp.Expr, radicand: sp.Expr, s: sp.Symbol) -> sp.Expr:
    """Replace ``radicand^(k/2)`` (and ``(1/radicand)^(k/2)``) by ``s^k``."""
    seen: dict[sp.Expr, int] = {}

    def match(b: sp.Expr) -> int:
        if b not in seen:
            seen[b] = 1 if (b == radicand or sp.cancel(b - radicand) == 0) else \
                -1 if sp.cancel(b * radicand - 1) == 0 else 0
        return seen[b]

    return expr.replace(lambda e: _is_root(e) and match(e.base) != 0,
                        lambda e: s ** (2 * match(e.base) * e.exp))


def _leftover_roots(expr: sp.Expr) -> list[sp.Expr]:
    return [e for e in sp.preorder_traversal(sp.sympify(expr)) if _is_root(e)]


def _vanishes_mod_root(expr: sp.Expr, s: sp.Symbol, relation: sp.Expr) -> bool:
    """Whether ``expr(s) = 0`` given ``s² = relation``: the numerator is A(s²) + s B(s²), and both
    A(relation) and B(relation) must vanish (sufficient; necessary when ``relation`` is not a square).

    Works in sympy's sparse polynomial rings over QQ (much faster than expanding expressions).
    """
    numerator = sp.numer(sp.together(expr))
    rn, rd = sp.fraction(sp.cancel(relation))
    gens = sorted(numerator.free_symbols | rn.free_symbols | rd.free_symbols | {s}, key=sp.default_sort_key)
    ring = sp.polys.rings.PolyRing(gens, sp.QQ)
    P = ring.from_expr(numerator)
    if not P:
        return True
    Rn, Rd = ring.from_expr(rn), ring.from_expr(rd)
    k_s = gens.index(s)
    top = max(m[k_s] for m in P.monoms()) // 2
    parts = [ring.zero, ring.zero]
    by_power: dict[int, object] = {}
    for monom, coeff in P.terms():
        k = monom[k_s]
        rest = monom[:k_s] + (0,) + monom[k_s + 1:]
        by_power[k] = by_power.get(k, ring.zero) + ring({rest: coeff})
    for k, c in by_power.items():
        parts[k % 2] += c * Rn ** (k // 2) * Rd ** (top - k // 2)
    return not parts[0] and not parts[1]


def _prove_flow(form: HamiltonianForm, system: MechanicalSystem) -> tuple[bool | None, str]:
    """Pushforward of the τ-field minus the Hamiltonian field ≡ 0 on the leaf, parameters symbolic."""
    leaf = _LEAVES[form.system_kind](form)
    x, y, s = system.state_symbols, form.bracket.variables, leaf.s
    sub = leaf.param_subs
    rho_x = sp.Symbol("rho_x", positive=True)
    # (1) d/dτ of the bracket variables in x, with the system's root as the symbol rho_x.
    jac = sp.Matrix(form.to_bracket_variables).xreplace(sub).jacobian(x)
    push = jac * sp.Matrix(system.rhs).xreplace(sub) / form.time_density.xreplace(sub)
    push = _roots_to_symbol(push, leaf.x_radicand, rho_x)
    # (2) x = from(y) on the leaf; check rho_x = x_root there (both positive: compare squares).
    back = [_roots_to_symbol(e.xreplace(sub), leaf.radicand, s).xreplace(leaf.point)
            for e in form.from_bracket_variables]
    x_of = dict(zip(x, back))
    check = sp.cancel(leaf.x_radicand.xreplace(x_of) - leaf.x_root.xreplace(leaf.point) ** 2)
    if check != 0 and not _vanishes_mod_root(check, s, leaf.relation):
        return None, f"could not identify the system's square root on the leaf ({leaf.description})"
    x_root = {rho_x: leaf.x_root.xreplace(leaf.point)}
    # to(from(y)) = y on the leaf, so {H, ·} below is taken at the image of x.
    for e, target in zip(form.to_bracket_variables, y):
        image = _roots_to_symbol(e.xreplace(sub), leaf.x_radicand, rho_x).xreplace(x_of).xreplace(x_root)
        if _leftover_roots(image) or not _vanishes_mod_root(image - target.xreplace(leaf.point), s, leaf.relation):
            return None, f"to(from(y)) = y not shown for {target} ({leaf.description})"
    push = push.xreplace(x_of).xreplace(x_root)
    # (3) {H, y} at y on the leaf, root → s.
    field = [_roots_to_symbol(e.xreplace(sub), leaf.radicand, s).xreplace(leaf.point)
             for e in form.bracket.hamiltonian_vector_field(form.hamiltonian)]
    for i, (a, b) in enumerate(zip(push, field)):
        residual = a - b
        left = _leftover_roots(residual)
        if left:
            verdict, where = _disprove(residual, leaf)
            if verdict is False:
                return False, f"d{y[i]}/dtau - {{H, {y[i]}}} = {where} (not 0) on the leaf ({leaf.description})"
            return None, f"component {y[i]}: square roots other than s left ({left[0]}), not decided"
        if not _vanishes_mod_root(residual, s, leaf.relation):
            verdict, where = _disprove(residual, leaf)
            if verdict is False:
                return False, f"d{y[i]}/dtau - {{H, {y[i]}}} = {where} (not 0) on the leaf ({leaf.description})"
            return None, f"component {y[i]}: the reduction mod s^2 does not vanish but no point disproves it"
    return True, f"all 6 components vanish identically ({leaf.description}); parameters symbolic"


def _disprove(residual: sp.Expr, leaf: _Leaf, tries: int = 50) -> tuple[bool | None, str]:
    """Evaluate ``residual`` (s = +sqrt(relation)) at random rational points to 50 digits.

    Symbols assumed positive (or non-negative) get values in (0, 2], others in [−1, 1]; points where
    ``relation`` is not positive are skipped. A value far from 0 at one point disproves the identity:
    returns (False, "value at point"), else (None, "").
    """
    rng = np.random.default_rng(2504)
    free = sorted(residual.free_symbols - {leaf.s}, key=sp.default_sort_key)
    for _ in range(tries):
        point = {x: sp.Rational(int(rng.integers(1, 1001)), 500) if (x.is_positive or x.is_nonnegative)
                 else sp.Rational(int(rng.integers(-1000, 1001)), 1000) for x in free}
        rel = leaf.relation.xreplace(point)
        if not rel.is_positive:
            continue
        value = residual.xreplace(point).xreplace({leaf.s: sp.sqrt(rel)}).evalf(50)
        if value.is_number and abs(value) > sp.Float("1e-30"):
            return False, f"{sp.N(value, 6)} at {{{', '.join(f'{k}={v}' for k, v in point.items())}}}"
    return None, ""


@lru_cache(maxsize=64)
def _flow_size(form: HamiltonianForm, system: MechanicalSystem) -> int:
    """Sympy operations of what the flow proof works on: the map, its inverse, H, dτ/dt and the field."""
    return operations(*form.to_bracket_variables, *form.from_bracket_variables, form.hamiltonian,
                      form.time_density, *system.rhs)


def symbolic_flow_identity(form: HamiltonianForm, system: MechanicalSystem,
                           limits: WorkLimits = work_limits.DEFAULT) -> tuple[bool | None, str]:
    """Whether the τ-pushforward equals ``{H, ·}`` identically on the leaf.

    Parameters
    ----------
    form, system : the Hamiltonian form and its system.
    limits : the proof is tried when the map, its inverse, H, dτ/dt and the system's field have at most
        ``limits.max_proof_ops`` sympy operations together; past it the verdict is None with that reason.

    Returns
    -------
    (verdict, detail)
        True (proved), False (disproved at a point, named), None (undecided: the detail says why, e.g.
        ``"not tried: 25,310 operations > max 20,000 (max_proof_ops)"``). The proof runs to its end
        and is cached (:mod:`nonholonomic.bounded`).

    Raises
    ------
    nonholonomic.bounded.SafetyCapExceeded
        If the proof outlives the service's safety cap (a failure, not a verdict).
    """
    if form.proof is not None:
        return form.proof
    skipped = over(_flow_size(form, system), limits.max_proof_ops, "max_proof_ops", "the symbolic proof")
    if skipped is not None:
        return None, skipped
    return bounded.prove(("flow", form, system), _prove_flow, (form, system))


# --- evidence -------------------------------------------------------------------------------------

def _relative(a: np.ndarray, b: np.ndarray, scale: np.ndarray | None = None) -> float:
    s = np.max(np.abs(b if scale is None else scale))
    return float(np.max(np.abs(a - b)) / (s if s > 0 else 1.0))


def hamiltonian_form_evidence(system: MechanicalSystem, parameters: np.ndarray, states: np.ndarray,
                              limits: WorkLimits = work_limits.DEFAULT) -> list[CheckEvidence]:
    """Evidence that ``system`` is Hamiltonian after the time substitution (empty for other kinds).

    Parameters
    ----------
    parameters : in ``system.parameter_symbols`` order.
    states : phase points on the constraint manifold (e.g. a trajectory's samples).
    limits : the size limit of the symbolic proof (:func:`symbolic_flow_identity`; None verdict past it).
    """
    form = hamiltonian_form(system)
    if form is None:
        return []
    p = np.asarray(parameters, dtype=float)
    X = np.atleast_2d(np.asarray(states, dtype=float))
    k = _kernels(form, system)
    quantity = "d y/d tau - {H, y}"
    evidence: list[CheckEvidence] = []

    proven, detail = symbolic_flow_identity(form, system, limits)
    evidence.append(CheckEvidence(
        name="hamiltonian_flow", quantity=quantity, formula=form.formula, equation=form.equation, method="symbolic",
        residual=0.0 if proven else None, tolerance=0.0, passed=proven,
        detail="pushforward of the system's field through the map, divided by d tau/dt, minus the Hamiltonian "
               "field dx/dtau = {H, x} = -(P grad H): " + detail))

    residual = flow_residual(form, system, X, p)
    evidence.append(CheckEvidence(
        name="hamiltonian_flow", quantity=quantity, formula=form.formula, equation=form.equation, method="pointwise",
        residual=residual, tolerance=POINTWISE_TOLERANCE,
        passed=bool(np.isfinite(residual) and residual <= POINTWISE_TOLERANCE),
        detail=f"max over {len(X)} states of |(dy/dx) f / N - {{H, y}}| / max |{{H, y}}|, N = d tau/dt, "
               "derivatives exact (symbolic, compiled)"))

    control = flow_residual(form, system, X, p, time="t")
    spread = time_density_spread(form, system, X, p)
    evidence.append(CheckEvidence(
        name="hamiltonian_flow_control", quantity="d y/dt - {H, y}", formula=form.formula, equation=form.equation,
        method="pointwise", residual=control, tolerance=CONTROL_THRESHOLD,
        passed=bool(np.isfinite(control) and control > CONTROL_THRESHOLD),
        detail=("control in the original time t: the same comparison without dividing by N = d tau/dt. It passes "
                f"when the residual exceeds {CONTROL_THRESHOLD:g}, i.e. the field in t is NOT the Hamiltonian field "
                f"of H, so the time substitution is needed. N varies by {spread:.3g} (max N / min N - 1) over the "
                "states, so no constant rescaling of t would do either; a failed control (small residual) means N "
                "is close to 1 at these parameters and states, not that the substitution is wrong")))

    own = numeric(system)
    values, scales = own.integrals(X, p), own.integral_scales(X, p)
    column = {i.name: n for n, i in enumerate(system.integrals)}
    Y = k.to(X, p)
    n_E = column["energy"]
    H = k.hamiltonian(Y, p)[:, 0]
    residual = _relative(H, values[:, n_E], np.maximum(np.abs(values[:, n_E]), np.abs(scales[:, n_E])))
    evidence.append(CheckEvidence(
        name="energy_equals_hamiltonian", quantity="H(to(x)) - E(x)", formula=f"H(to(x)) = E(x); {form.formula}",
        equation=form.equation, method="pointwise", residual=residual, tolerance=POINTWISE_TOLERANCE,
        passed=bool(np.isfinite(residual) and residual <= POINTWISE_TOLERANCE),
        detail=f"max over {len(X)} states of |H(to(x)) - E(x)| / max(|E|, scale of E), "
               f"E = {system.integrals[n_E].formula}"))

    back = k.back(Y, p)
    target = X if form.from_indices is None else X[:, list(form.from_indices)]
    residual = _relative(back, target, target)
    evidence.append(CheckEvidence(
        name="inverse_map", quantity="from(to(x)) - x", formula=form.formula, equation=form.equation,
        method="pointwise", residual=residual, tolerance=POINTWISE_TOLERANCE,
        passed=bool(np.isfinite(residual) and residual <= POINTWISE_TOLERANCE),
        detail=f"max over {len(X)} states of |from(to(x)) - x| / max |x|"))

    # e.g. "M_Gamma" for e(3), "L_gamma" for the ball: the names of the two vectors
    in_variables = "_".join(str(v).rstrip("123") for v in form.bracket.variables[::3])
    mapped = k.extra_integrals(Y, p)
    for n, (name, expression, equation) in enumerate(form.extra_integrals):
        if name not in column:
            continue
        claim, c = system.integrals[column[name]], column[name]
        residual = _relative(mapped[:, n], values[:, c], np.maximum(np.abs(values[:, c]), np.abs(scales[:, c])))
        evidence.append(CheckEvidence(
            name=f"{name}_in_{in_variables}", quantity=f"{name}(to(x)) - {name}(x)",
            formula=f"{name} = {sp.sstr(expression)}", equation=equation,
            method="pointwise", residual=residual, tolerance=POINTWISE_TOLERANCE,
            passed=bool(np.isfinite(residual) and residual <= POINTWISE_TOLERANCE),
            detail=f"max over {len(X)} states of |{name} in the bracket variables at to(x) - {claim.formula}| / "
                   f"max(|{name}|, its scale), {claim.formula} (eq. {claim.equation})"))
    return evidence
