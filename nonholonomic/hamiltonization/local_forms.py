"""The Euler-angle local forms of the Veselova system and of Chaplygin's ball.

Paper: section 1 (generalized Chaplygin systems, eq. 2704-7, 2704-8, Theorem 1), section "Veselova
system" (eq. 2904-1, 2504-6 … 2504-9, Theorem 2) and section "Chaplygin's ball" (eq. 001 … 007 and
the theorem after eq. 007). Everything here is built symbolically (sympy) with θ, φ and their
velocities or momenta as symbols; nothing is simplified at build time (the expressions are cheap to
form; proofs are the tests' and the report's business). The numeric evidence
(:func:`local_form_evidence`) compares the local forms with the vector forms of the systems
(:mod:`nonholonomic.systems.veselova`, :mod:`nonholonomic.systems.chaplygin_ball`) at phase points.

Conventions (eq. 2904-1): with the Euler angles θ, φ, ψ,

    ω = ψ̇ γ + θ̇ e_N + φ̇ e_3,   γ = (sinθ sinφ, sinθ cosφ, cosθ),   e_N = (cosφ, −sinφ, 0),

so that dγ/dt = γ × ω and (ω, γ) = ψ̇ + cosθ φ̇ (eq. 2504-6). Hence from a state,
θ = atan2(√(γ₁² + γ₂²), γ₃), φ = atan2(γ₁, γ₂), θ̇ = (ω, e_N),
φ̇ = (ω₃ − cosθ (ω, γ)) / sin²θ, ψ̇ = ((ω, γ) − cosθ ω₃) / sin²θ; the angles are singular at
θ = 0, π (sinθ → 0), where such states are skipped.

The generalized Chaplygin form (eq. 2704-7) with q = (θ, φ)::

    d/dt ∂L/∂q̇₁ − ∂L/∂q₁ = q̇₂ S,   d/dt ∂L/∂q̇₂ − ∂L/∂q₂ = −q̇₁ S,   S = a₁ q̇₁ + a₂ q̇₂ + b.

Corrections to the paper used here (each is tested in tests/unit/test_local_forms.py):

* ERRATA 2: the Veselova S of eq. (2504-7) is
  S = sin²θ [θ̇ (I₂ − I₁) sinφ cosφ + φ̇ sinθ cosθ (I₁ sin²φ + I₂ cos²φ − I₃)] = −sinθ ∂T₀/∂ψ̇
  at ψ̇ = −cosθ φ̇ (the printed φ̇ coefficient −(I₁cos²φ + I₂sin²φ + I₃) and the printed
  S = ∂T₀/∂ψ̇ are wrong).
* ERRATA 3: the reducing multiplier of Theorem 2 is N = (γ, I⁻¹γ)^(−1/2) = ρ_ω⁻¹, not
  (γ, Iγ)^(−1/2) (with the printed N, S̄ ≠ 0).
* ERRATA 6: with N = ρ, eq. (2704-8) gives S̄ = N·B(q), B(q) = S at zero momenta, not B(q).
* ERRATA 7: the Hamiltonian of the ball in (θ, φ, p_θ, p_φ) is :func:`ball_hamiltonian`
  (= ½(L, adj(I_Q) L) with L = L(p)), not the printed :func:`ball_hamiltonian_printed`.
* ERRATA 14: in eq. (2704-8) ∂L̄/∂q_q′ is ∂L̄/∂q₁′.

Sign conventions: eq. (2504-7) is the form (2704-7) as it stands; eq. (003) and eq. (007) carry
the opposite sign (−φ̇ S on the θ equation), so the ball's S in the form (2704-7) is −S₍₀₀₃₎ and
its S̄ is −S̄₍₀₀₇₎.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import numpy as np
import sympy as sp

from nonholonomic.definition import MechanicalSystem, cross, dot
from nonholonomic.evidence.measure import CheckEvidence
from nonholonomic.numerics.kernels import VectorKernel, vectorize
from nonholonomic.systems import chaplygin_ball as _ball, veselova as _ves

#: Pointwise relative residual accepted as round-off.
TOLERANCE = 1e-10
#: States with sinθ below this are skipped (the Euler angles are singular at θ = 0, π; round-off
#: in the local forms grows like 1/sin²θ).
MIN_SIN_THETA = 1e-2

theta, phi, psi = sp.symbols("theta phi psi", real=True)
thetadot, phidot, psidot = sp.symbols("thetadot phidot psidot", real=True)
thetaddot, phiddot, psiddot = sp.symbols("thetaddot phiddot psiddot", real=True)
#: q′ = dq/dτ after the time substitution N dt = dτ.
thetap, phip = sp.symbols("thetap phip", real=True)
p_theta, p_phi = sp.symbols("p_theta p_phi", real=True)
#: The constant of areas c = (M, γ) = ∂T₀/∂ψ̇ (eq. 004).
c = sp.Symbol("c", real=True)
#: The reducing multiplier as a free symbol (where a formula is written with N).
N = sp.Symbol("N", positive=True)

I1, I2, I3 = _ves.I1, _ves.I2, _ves.I3
D = _ball.D
inertia = sp.diag(I1, I2, I3)

Q = (theta, phi)
QDOT = (thetadot, phidot)
QDDOT = (thetaddot, phiddot)
QPRIME = (thetap, phip)

#: Ĩ₁₂ = I₁sin²φ + I₂cos²φ and Ĩ₂₁ = I₁cos²φ + I₂sin²φ (theorem after eq. 007).
I12 = I1 * sp.sin(phi) ** 2 + I2 * sp.cos(phi) ** 2
I21 = I1 * sp.cos(phi) ** 2 + I2 * sp.sin(phi) ** 2


# --- eq. (2904-1): the Euler angles ---------------------------------------------------------------

def euler_gamma(th: sp.Expr = theta, ph: sp.Expr = phi) -> sp.Matrix:
    """γ = (sinθ sinφ, sinθ cosφ, cosθ) (eq. 2904-1)."""
    return sp.Matrix([sp.sin(th) * sp.sin(ph), sp.sin(th) * sp.cos(ph), sp.cos(th)])


def node_axis(ph: sp.Expr = phi) -> sp.Matrix:
    """e_N = (cosφ, −sinφ, 0) = ∂ω/∂θ̇ (eq. 2904-1): the line of nodes, orthogonal to γ and e₃."""
    return sp.Matrix([sp.cos(ph), -sp.sin(ph), 0])


def euler_omega(thd: sp.Expr = thetadot, phd: sp.Expr = phidot, psd: sp.Expr = psidot,
                th: sp.Expr = theta, ph: sp.Expr = phi) -> sp.Matrix:
    """ω = (ψ̇ sinθ sinφ + θ̇ cosφ, ψ̇ sinθ cosφ − θ̇ sinφ, ψ̇ cosθ + φ̇) (eq. 2904-1)."""
    return sp.Matrix([psd * sp.sin(th) * sp.sin(ph) + thd * sp.cos(ph),
                      psd * sp.sin(th) * sp.cos(ph) - thd * sp.sin(ph),
                      psd * sp.cos(th) + phd])


# --- section 1: generalized Chaplygin systems (eq. 2704-7, 2704-8) ---------------------------------

def time_derivative(f: sp.Expr, q: Sequence[sp.Symbol] = Q, qdot: Sequence[sp.Symbol] = QDOT,
                    qddot: Sequence[sp.Symbol] = QDDOT) -> sp.Expr:
    """d/dt f(q, q̇) = Σ ∂f/∂q_i q̇_i + ∂f/∂q̇_i q̈_i (chain rule; q̈ are symbols)."""
    return sum(sp.diff(f, qi) * vi + sp.diff(f, vi) * ai for qi, vi, ai in zip(q, qdot, qddot))


def generalized_chaplygin_residuals(L: sp.Expr, S: sp.Expr, q: Sequence[sp.Symbol] = Q,
                                    qdot: Sequence[sp.Symbol] = QDOT,
                                    qddot: Sequence[sp.Symbol] = QDDOT) -> tuple[sp.Expr, sp.Expr]:
    """Left minus right sides of eq. (2704-7)::

        d/dt ∂L/∂q̇₁ − ∂L/∂q₁ − q̇₂ S,   d/dt ∂L/∂q̇₂ − ∂L/∂q₂ + q̇₁ S,

    with the accelerations q̈ as symbols (both vanish along the motion if the form is right).
    """
    r1 = time_derivative(sp.diff(L, qdot[0]), q, qdot, qddot) - sp.diff(L, q[0]) - qdot[1] * S
    r2 = time_derivative(sp.diff(L, qdot[1]), q, qdot, qddot) - sp.diff(L, q[1]) + qdot[0] * S
    return r1, r2


def time_substituted_lagrangian(L: sp.Expr, N_q: sp.Expr, qdot: Sequence[sp.Symbol] = QDOT,
                                qprime: Sequence[sp.Symbol] = QPRIME) -> sp.Expr:
    """L̄(q, q′) = L(q, N q′) (text before eq. 2704-8), for N dt = dτ."""
    return L.subs({v: N_q * w for v, w in zip(qdot, qprime)}, simultaneous=True)


def reduced_gyroscopic_term(L: sp.Expr, S: sp.Expr, N_q: sp.Expr, q: Sequence[sp.Symbol] = Q,
                            qdot: Sequence[sp.Symbol] = QDOT, qprime: Sequence[sp.Symbol] = QPRIME) -> sp.Expr:
    """S̄(q, q′) of eq. (2704-8) for the time substitution N(q) dt = dτ::

        S̄ = N S + (1/N) (∂N/∂q₂ ∂L̄/∂q₁′ − ∂N/∂q₁ ∂L̄/∂q₂′),   S at q̇ = N q′,

    (the printed ∂L̄/∂q_q′ is ∂L̄/∂q₁′, ERRATA 14). Theorem 1: with N = ρ (the density of an
    invariant measure ρ(q) dP dq), S̄ = N·B(q) (ERRATA 6: not B(q)), where S = A₁P₁ + A₂P₂ + B(q).
    """
    Lbar = time_substituted_lagrangian(L, N_q, qdot, qprime)
    S_tau = S.subs({v: N_q * w for v, w in zip(qdot, qprime)}, simultaneous=True)
    return N_q * S_tau + (sp.diff(N_q, q[1]) * sp.diff(Lbar, qprime[0])
                          - sp.diff(N_q, q[0]) * sp.diff(Lbar, qprime[1])) / N_q


def reduced_gyroscopic_term_over_multiplier(L: sp.Expr, S: sp.Expr, Delta: sp.Expr, q: Sequence[sp.Symbol] = Q,
                                             qdot: Sequence[sp.Symbol] = QDOT) -> sp.Expr:
    """S̄/N of eq. (2704-8) for N = Δ(q)^(−1/2), written in the velocities q̇ = N q′::

        S̄/N = S − (1/(2Δ)) (∂Δ/∂q₂ ∂L/∂q̇₁ − ∂Δ/∂q₁ ∂L/∂q̇₂),

    from ∂N/∂q = −½ (N/Δ) ∂Δ/∂q and ∂L̄/∂q′ = N ∂L/∂q̇. Rational when L, S and Δ are, so its
    vanishing (or its independence of q̇) is decided without square roots. S̄ depends on q only
    iff this does (q′ and q̇ are proportional).
    """
    return S - (sp.diff(Delta, q[1]) * sp.diff(L, qdot[0]) - sp.diff(Delta, q[0]) * sp.diff(L, qdot[1])) / (2 * Delta)


def gyroscopic_coefficients(S: sp.Expr, qdot: Sequence[sp.Symbol] = QDOT) -> tuple[sp.Expr, sp.Expr, sp.Expr]:
    """(a₁, a₂, b) of S = a₁ q̇₁ + a₂ q̇₂ + b (eq. 2704-7), for S linear in the velocities."""
    zero = {v: 0 for v in qdot}
    b = S.subs(zero)
    return (sp.diff(S, qdot[0]).subs(zero), sp.diff(S, qdot[1]).subs(zero), b)


# --- Veselova system (eq. 2504-6 … 2504-9, Theorem 2) -----------------------------------------------

def veselova_free_kinetic_energy() -> sp.Expr:
    """T₀ = ½(ω, Iω) with ω(θ̇, φ̇, ψ̇) of eq. (2904-1): the kinetic energy without the constraint."""
    w = euler_omega()
    return dot(w, inertia * w) / 2


def veselova_constraint() -> sp.Expr:
    """f = (ω, γ) in Euler angles (eq. 2504-6; equals ψ̇ + cosθ φ̇)."""
    return dot(euler_omega(), euler_gamma())


#: ψ̇ on the constraint (eq. 2504-6).
VESELOVA_PSIDOT = -sp.cos(theta) * phidot


def veselova_kinetic_energy() -> sp.Expr:
    """T = T₀ at ψ̇ = −cosθ φ̇ (eq. 2504-8), as printed::

        T = ½I₁(θ̇ cosφ − φ̇ sinφ sinθ cosθ)² + ½I₂(θ̇ sinφ + φ̇ cosφ sinθ cosθ)² + ½I₃ φ̇² sin⁴θ.
    """
    s, co = sp.sin(theta), sp.cos(theta)
    return (I1 * (thetadot * sp.cos(phi) - phidot * sp.sin(phi) * s * co) ** 2
            + I2 * (thetadot * sp.sin(phi) + phidot * sp.cos(phi) * s * co) ** 2
            + I3 * phidot ** 2 * s ** 4) / 2


def veselova_gyroscopic_term() -> sp.Expr:
    """S of eq. (2504-7) as corrected in ERRATA 2::

        S = sin²θ [θ̇ (I₂ − I₁) sinφ cosφ + φ̇ sinθ cosθ (I₁ sin²φ + I₂ cos²φ − I₃)]
          = −sinθ ∂T₀/∂ψ̇ |_{ψ̇ = −cosθ φ̇}.

    With it, T − U satisfies eq. (2504-7) = (2704-7) along the Veselova flow (b = 0: an ordinary
    Chaplygin system). The printed form (:func:`veselova_gyroscopic_term_printed`) does not.
    """
    s, co = sp.sin(theta), sp.cos(theta)
    return s ** 2 * (thetadot * (I2 - I1) * sp.sin(phi) * sp.cos(phi) + phidot * s * co * (I12 - I3))


def veselova_gyroscopic_term_printed() -> sp.Expr:
    """S as printed in eq. (2504-7) (wrong, ERRATA 2):
    sin²θ (θ̇ (I₂ − I₁) sinφ cosφ − φ̇ (I₁cos²φ + I₂sin²φ + I₃))."""
    return sp.sin(theta) ** 2 * (thetadot * (I2 - I1) * sp.sin(phi) * sp.cos(phi) - phidot * (I21 + I3))


def veselova_reducing_multiplier() -> sp.Expr:
    """N = (γ, I⁻¹γ)^(−1/2) = ρ_ω⁻¹ (Theorem 2 as corrected in ERRATA 3), γ = γ(θ, φ)."""
    g = euler_gamma()
    return 1 / sp.sqrt(dot(g, _ves.inertia_inv * g))


def veselova_reducing_multiplier_printed() -> sp.Expr:
    """N = (γ, Iγ)^(−1/2) as printed in Theorem 2 (wrong, ERRATA 3: S̄ ≠ 0 with it)."""
    g = euler_gamma()
    return 1 / sp.sqrt(dot(g, inertia * g))


def veselova_reduced_lagrangian(U: sp.Expr = sp.Integer(0)) -> sp.Expr:
    """L̄(θ, φ, θ′, φ′) = T(θ, φ, Nθ′, Nφ′) − U (Theorem 2, eq. 2504-9), N of ERRATA 3.

    ``U`` is a function of the vector γ (symbols of :mod:`nonholonomic.systems.veselova`); it is
    taken at γ(θ, φ).
    """
    return (time_substituted_lagrangian(veselova_kinetic_energy(), veselova_reducing_multiplier())
            - on_euler_gamma(U))


def veselova_reduced_lagrangian_vector(U: sp.Expr = sp.Integer(0)) -> sp.Expr:
    """The vector form of Theorem 2: L = ½(γ′×γ, I(γ′×γ)) / (γ, I⁻¹γ) − U(γ), with γ = γ(θ, φ) and
    γ′ = ∂γ/∂θ θ′ + ∂γ/∂φ φ′."""
    g = euler_gamma()
    gp = g.diff(theta) * thetap + g.diff(phi) * phip
    v = cross(gp, g)
    return dot(v, inertia * v) / (2 * dot(g, _ves.inertia_inv * g)) - on_euler_gamma(U)


def on_euler_gamma(U: sp.Expr, gamma: sp.Matrix = _ves.gamma) -> sp.Expr:
    """U(γ) at γ = γ(θ, φ)."""
    return sp.sympify(U).subs(dict(zip(gamma, euler_gamma())), simultaneous=True)


# --- Chaplygin's ball (eq. 001 … 007 and the theorem after eq. 007) ---------------------------------

def ball_kinetic_energy() -> sp.Expr:
    """T₀ with ẋ, ẏ eliminated by the constraints (eq. 001)::

        T = ½(Iω, ω) + ½D(θ̇² + φ̇² sin²θ),   D = mR²,

    since ẋ² + ẏ² = R²(θ̇² + φ̇² sin²θ) (= R²|ω × γ|²); ω(θ̇, φ̇, ψ̇) of eq. (2904-1). It equals
    ½(M, ω) with M = I_Q ω (eq. 2604-1, 2604-2).
    """
    w = euler_omega()
    return dot(w, inertia * w) / 2 + D * (thetadot ** 2 + phidot ** 2 * sp.sin(theta) ** 2) / 2


def ball_cyclic_momentum() -> sp.Expr:
    """∂T₀/∂ψ̇ = (I₁ − I₂) θ̇ sinθ sinφ cosφ + I₃ φ̇ cosθ + (γ, Iγ) ψ̇ = c (eq. 004); c = (M, γ)."""
    g = euler_gamma()
    return ((I1 - I2) * thetadot * sp.sin(theta) * sp.sin(phi) * sp.cos(phi) + I3 * phidot * sp.cos(theta)
            + dot(g, inertia * g) * psidot)


def ball_psidot() -> sp.Expr:
    """ψ̇(θ, φ, θ̇, φ̇; c) from the cyclic integral (eq. 004)."""
    g = euler_gamma()
    return (c - (I1 - I2) * thetadot * sp.sin(theta) * sp.sin(phi) * sp.cos(phi)
            - I3 * phidot * sp.cos(theta)) / dot(g, inertia * g)


def ball_routh_function() -> sp.Expr:
    """The Routh function ℛ = T₀ − ψ̇ ∂T₀/∂ψ̇ with ẋ, ẏ and ψ̇ eliminated (eq. 003, 004)::

        ℛ = ½[(Ĩ₂₁ + D) θ̇² + (I₃ + D sin²θ) φ̇²] − (c − (I₁−I₂) θ̇ sinθ sinφ cosφ − I₃ φ̇ cosθ)² / (2(γ, Iγ)).
    """
    g = euler_gamma()
    beta = (I1 - I2) * thetadot * sp.sin(theta) * sp.sin(phi) * sp.cos(phi) + I3 * phidot * sp.cos(theta)
    return (((I21 + D) * thetadot ** 2 + (I3 + D * sp.sin(theta) ** 2) * phidot ** 2) / 2
            - (c - beta) ** 2 / (2 * dot(g, inertia * g)))


def ball_gyroscopic_term_routh() -> sp.Expr:
    """S of eq. (003) (its own sign: −φ̇ S on the θ equation): S = D sinθ (φ̇ cosθ + ψ̇), ψ̇ of eq. (004)."""
    return D * sp.sin(theta) * (phidot * sp.cos(theta) + ball_psidot())


def ball_gyroscopic_term() -> sp.Expr:
    """S in the form (2704-7): −S₍₀₀₃₎ = a₁θ̇ + a₂φ̇ + b with (G = (γ, Iγ))::

        a₁ = D (I₁ − I₂) sin²θ sinφ cosφ / G,   a₂ = −D sin³θ cosθ (Ĩ₁₂ − I₃) / G,   b = −D c sinθ / G.
    """
    return -ball_gyroscopic_term_routh()


def ball_reducing_multiplier() -> sp.Expr:
    """N = ρ_μ = (det I_Q)^(−1/2) at γ = γ(θ, φ) (eq. 005, 2604-3)."""
    return _ball.measure_density(euler_gamma())


def ball_S_bar_printed(N_q: sp.Expr = N) -> sp.Expr:
    """S̄ of eq. (007), in that equation's sign convention (−φ′ S̄ on the θ equation)::

        S̄ = c (I₃ + D) D N³ sinθ (I₁cos²φ + I₂sin²φ + D).

    Confirmed (tests): it is −S̄ of eq. (2704-8) with N = ρ_μ, and equals N·B(q) (ERRATA 6).
    """
    return c * (I3 + D) * D * N_q ** 3 * sp.sin(theta) * (I21 + D)


def ball_momenta() -> tuple[sp.Expr, sp.Expr]:
    """(p_θ, p_φ) = (∂ℛ̄/∂θ′, ∂ℛ̄/∂φ′) = N (∂ℛ/∂θ̇, ∂ℛ/∂φ̇), N = ρ_μ(θ, φ) (theorem after eq. 007)."""
    R, n = ball_routh_function(), ball_reducing_multiplier()
    return n * sp.diff(R, thetadot), n * sp.diff(R, phidot)


def ball_L_from_momenta(N_q: sp.Expr = N) -> sp.Matrix:
    """L = ρ_μ M in (θ, φ, p_θ, p_φ) (the paper's formula after the theorem, confirmed)::

        L₁ = p_θ cosφ − p_φ cosθ sinφ / sinθ + cN sinφ / sinθ,
        L₂ = −p_θ sinφ − p_φ cosθ cosφ / sinθ + cN cosφ / sinθ,   L₃ = p_φ,

    i.e. the solution of (L, e_N) = p_θ, L₃ = p_φ, (L, γ) = N c.
    """
    s, co = sp.sin(theta), sp.cos(theta)
    return sp.Matrix([p_theta * sp.cos(phi) - p_phi * co * sp.sin(phi) / s + c * N_q * sp.sin(phi) / s,
                      -p_theta * sp.sin(phi) - p_phi * co * sp.cos(phi) / s + c * N_q * sp.cos(phi) / s,
                      p_phi])


def ball_hamiltonian(N_q: sp.Expr = N) -> sp.Expr:
    """H(θ, φ, p_θ, p_φ) of the theorem after eq. (007), corrected (ERRATA 7), G = (γ, Iγ)::

        H = ½ p_θ² (I₃Ĩ₁₂ + D G) + ½ (p_φ²/sin²θ)(I₁I₂ sin²θ + I₃Ĩ₂₁ cos²θ + D G)
          + (p_θ p_φ / sinθ) I₃ (I₁−I₂) cosθ sinφ cosφ − (N c p_θ / sinθ)(I₁−I₂)(I₃ + D sin²θ) sinφ cosφ
          − (N c p_φ cosθ / sin²θ) I₃ (Ĩ₂₁ + D) + (N² c² / (2 sin²θ))(I₃ + D sin²θ)(Ĩ₂₁ + D).

    It equals ½(L, adj(I_Q) L) with L = L(p) (:func:`ball_L_from_momenta`), identically in N; with
    N = ρ_μ it is the kinetic energy ½(M, ω) (the potential adds U(γ(θ, φ))).
    """
    s, co = sp.sin(theta), sp.cos(theta)
    sc = sp.sin(phi) * sp.cos(phi)
    G = I12 * s ** 2 + I3 * co ** 2
    return (p_theta ** 2 * (I3 * I12 + D * G) / 2
            + p_phi ** 2 / s ** 2 * (I1 * I2 * s ** 2 + I3 * I21 * co ** 2 + D * G) / 2
            + p_theta * p_phi / s * I3 * (I1 - I2) * co * sc
            - N_q * c * p_theta / s * (I1 - I2) * (I3 + D * s ** 2) * sc
            - N_q * c * p_phi * co / s ** 2 * I3 * (I21 + D)
            + N_q ** 2 * c ** 2 / (2 * s ** 2) * (I3 + D * s ** 2) * (I21 + D))


def ball_hamiltonian_printed(N_q: sp.Expr = N) -> sp.Expr:
    """H as printed after eq. (007) (wrong, ERRATA 7; the printed "+ +" read as one "+")."""
    s, co = sp.sin(theta), sp.cos(theta)
    sc = sp.sin(phi) * sp.cos(phi)
    G = I12 * s ** 2 + I3 * co ** 2
    return (p_theta ** 2 * (I3 * I12 - D * G) / 2
            + p_phi ** 2 / s ** 2 * (I1 * I2 * s ** 2 + I3 * I12 * co ** 2 - D * G) / 2
            + p_theta * p_phi / s * I3 * (I1 - I2) * co * s * sc
            - N_q * c * p_theta / s * (I1 - I2) * (I3 + D * s ** 2) * sc
            - N_q * c * p_phi / s ** 2 * I3 * (I21 + D)
            + N_q ** 2 * c ** 2 / s ** 2 * (I3 + D * s ** 2) * (I21 + D))


# --- Theorem 1 worked examples (strings for POST /v1/hamiltonize) -----------------------------------

#: Theorem 1 inputs for the Veselova system (U = 0): L = T of eq. (2504-8), S of ERRATA 2 (b = 0).
_VESELOVA_EXAMPLE = {
    "L": "I1*(thetadot*cos(phi) - phidot*sin(phi)*sin(theta)*cos(theta))**2/2"
                  " + I2*(thetadot*sin(phi) + phidot*cos(phi)*sin(theta)*cos(theta))**2/2"
                  " + I3*phidot**2*sin(theta)**4/2",
    "a1": "(I2 - I1)*sin(theta)**2*sin(phi)*cos(phi)",
    "a2": "sin(theta)**3*cos(theta)*(I1*sin(phi)**2 + I2*cos(phi)**2 - I3)",
    "b": "0",
    "coordinates": "theta,phi",
    "velocities": "thetadot,phidot",
}

_BALL_G = "(sin(theta)**2*(I1*sin(phi)**2 + I2*cos(phi)**2) + I3*cos(theta)**2)"
#: Theorem 1 inputs for Chaplygin's ball (U = 0): L = ℛ (eq. 003, 004), S = −S₍₀₀₃₎.
_BALL_EXAMPLE = {
    "L": "((I1*cos(phi)**2 + I2*sin(phi)**2 + D)*thetadot**2 + (I3 + D*sin(theta)**2)*phidot**2)/2"
                  " - (c - (I1 - I2)*thetadot*sin(theta)*sin(phi)*cos(phi) - I3*phidot*cos(theta))**2"
                  f"/(2*{_BALL_G})",
    "a1": f"D*(I1 - I2)*sin(theta)**2*sin(phi)*cos(phi)/{_BALL_G}",
    "a2": f"-D*sin(theta)**3*cos(theta)*(I1*sin(phi)**2 + I2*cos(phi)**2 - I3)/{_BALL_G}",
    "b": f"-D*c*sin(theta)/{_BALL_G}",
    "coordinates": "theta,phi",
    "velocities": "thetadot,phidot",
}


#: Where the ball's gyroscopic form lives (text after eq. 2704-9): Euler angles cover S², and the
#: momenta of the Routh form differ from smooth fibre coordinates of T*S² by W = (0, c N cos θ), so
#: L = ρ_μ M = c N γ + m(p_θ, p_φ − c N cos θ), m the angular momentum map in spherical coordinates
#: (checked in tests/unit/test_reducing_multiplier.py). N is the reducing multiplier found.
BALL_MONOPOLE_CHART = {"domain": [["0", "pi"], ["0", "2*pi"]], "shift": ["0", "c*N*cos(theta)"]}


def veselova_generalized_chaplygin() -> dict[str, str]:
    """Theorem 1 inputs for the Veselova system in (θ, φ) (U = 0).

    ``lagrangian`` is T of eq. (2504-8); S = a₁θ̇ + a₂φ̇ + b of eq. (2704-7) is the S of eq.
    (2504-7) as corrected in ERRATA 2 (b = 0). The reducing multiplier is
    N = (γ, I⁻¹γ)^(−1/2) (ERRATA 3), giving S̄ = 0.
    """
    return dict(_VESELOVA_EXAMPLE)


def chaplygin_ball_generalized_chaplygin() -> dict[str, str]:
    """Theorem 1 inputs for Chaplygin's ball in (θ, φ) (U = 0; parameters I1, I2, I3, D and the
    constant of areas c).

    ``lagrangian`` is the Routh function ℛ of eq. (003) with ẋ, ẏ, ψ̇ eliminated (eq. 001, 004);
    S = a₁θ̇ + a₂φ̇ + b is −S of eq. (003) (whose sign convention is the opposite of eq. 2704-7),
    G = (γ, Iγ)::

        a₁ = D (I₁−I₂) sin²θ sinφ cosφ / G,  a₂ = −D sin³θ cosθ (Ĩ₁₂ − I₃) / G,  b = −D c sinθ / G.

    With N = ρ_μ, S̄ = −c (I₃+D) D N³ sinθ (Ĩ₂₁ + D) (eq. 007 up to its sign convention).
    """
    return dict(_BALL_EXAMPLE)


# --- numeric evidence: local forms against vector forms ---------------------------------------------

def euler_angles_and_rates(omega: np.ndarray, gamma: np.ndarray) -> tuple[np.ndarray, ...]:
    """θ, φ, θ̇, φ̇, ψ̇ and sinθ from body-frame ω and γ (rows), by inverting eq. (2904-1).

    θ = atan2(√(γ₁²+γ₂²), γ₃), φ = atan2(γ₁, γ₂), θ̇ = (ω, e_N), φ̇ = (ω₃ − cosθ (ω, γ̂))/sin²θ,
    ψ̇ = ((ω, γ̂) − cosθ ω₃)/sin²θ, γ̂ = γ/|γ|. Rates are NaN where sinθ = 0.
    """
    g1, g2, g3 = gamma[:, 0], gamma[:, 1], gamma[:, 2]
    rho = np.hypot(g1, g2)
    th = np.arctan2(rho, g3)
    ph = np.arctan2(g1, g2)
    s, co = np.sin(th), np.cos(th)
    thd = omega[:, 0] * np.cos(ph) - omega[:, 1] * np.sin(ph)
    wg = np.einsum("ij,ij->i", omega, gamma) / np.linalg.norm(gamma, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        phd = (omega[:, 2] - co * wg) / s ** 2
        psd = (wg - co * omega[:, 2]) / s ** 2
    return th, ph, thd, phd, psd, s


def _potential(system: MechanicalSystem, velocity: Sequence[sp.Symbol]) -> sp.Expr:
    """U(γ): the energy integral at zero velocity (the kinetic part is quadratic in it)."""
    (energy,) = [i.expression for i in system.integrals if i.name == "energy"]
    return energy.subs({v: 0 for v in velocity})


class _Kernels:
    """Compiled local and vector forms of one system (args: local variables, then parameters)."""

    def __init__(self, system: MechanicalSystem) -> None:
        params = system.parameter_symbols
        if system.kind == "veselova":
            U = _potential(system, _ves.omega)
            w, g = _ves.omega, _ves.gamma
            n_vec = 1 / sp.sqrt(dot(g, _ves.inertia_inv * g))
            v = cross(cross(g, w) / n_vec, g)  # γ′ × γ with γ′ = γ̇ / N, γ̇ = γ × ω
            self.vector: VectorKernel = vectorize(
                [dot(w, inertia * w) / 2, dot(v, inertia * v) / (2 * dot(g, _ves.inertia_inv * g)) - U, U],
                system.state_symbols + params)
            self.multiplier = vectorize([veselova_reducing_multiplier()], Q + params)
            self.local = vectorize([veselova_kinetic_energy()], Q + QDOT + params)
            self.lagrangian = vectorize([veselova_reduced_lagrangian(U)], Q + QPRIME + params)
        else:
            M, g = _ball.M, _ball.gamma
            rho = _ball.measure_density(g)
            self.vector = vectorize([dot(M, _ball.contact_inertia_inverse(g) * M) / 2, *(rho * M)],
                                    system.state_symbols + params)
            self.momenta = vectorize(list(ball_momenta()), Q + QDOT + (c,) + params)
            n = ball_reducing_multiplier()
            self.local = vectorize([ball_hamiltonian(n), *ball_L_from_momenta(n)],
                                   Q + (p_theta, p_phi, c) + params)


@lru_cache(maxsize=16)
def _kernels(system: MechanicalSystem) -> _Kernels:
    return _Kernels(system)


def _relative(a: np.ndarray, b: np.ndarray, scale: np.ndarray) -> float:
    scale = np.where(scale > 0, scale, 1.0)
    err = np.abs(a - b) if a.ndim == 1 else np.linalg.norm(a - b, axis=1)
    return float(np.max(err / scale)) if len(err) else float("nan")


def _item(name: str, quantity: str, formula: str, equation: str, residual: float | None, used: int,
          skipped: int, min_sin_theta: float, how: str) -> CheckEvidence:
    if used == 0:
        return CheckEvidence(name, quantity, formula, equation, "pointwise", None, TOLERANCE, None,
                             f"undecided: all {skipped} states have sin(theta) < {min_sin_theta:g} "
                             "(Euler angles singular at theta = 0, pi)")
    passed = bool(residual is not None and np.isfinite(residual) and residual <= TOLERANCE)
    return CheckEvidence(name, quantity, formula, equation, "pointwise", residual, TOLERANCE, passed,
                         f"{how}; max over {used} states, {skipped} skipped with sin(theta) < {min_sin_theta:g} "
                         "(Euler angles singular at theta = 0, pi); theta, phi from gamma = (sin theta sin phi, "
                         "sin theta cos phi, cos theta), rates from omega = psidot gamma + thetadot e_N + "
                         "phidot e_3 (eq. 2904-1)")


def local_form_evidence(system: MechanicalSystem, parameters: np.ndarray, states: np.ndarray,
                        min_sin_theta: float = MIN_SIN_THETA) -> list[CheckEvidence]:
    """The Euler-angle local forms against the vector forms at ``states`` (rows in
    ``system.state_symbols`` order: Veselova (ω, γ), the ball (M, γ)).

    Veselova: T of eq. (2504-8) vs ½(Iω, ω); the Lagrangian L̄(θ, φ, θ′, φ′) of Theorem 2
    (N = (γ, I⁻¹γ)^(−1/2), ERRATA 3; θ′ = θ̇/N) vs ½(γ′×γ, I(γ′×γ))/(γ, I⁻¹γ) − U, γ′ = γ̇/N.
    Chaplygin's ball: p = N ∂ℛ/∂q̇ (Legendre transform of ℛ̄, N = ρ_μ, c = (M, γ)); H(θ, φ, p_θ, p_φ)
    of ERRATA 7 vs ½(M, ω); L(p) vs ρ_μ M. Other kinds: [].

    Residuals are relative (to ½(Iω, ω); to |T| + |U|; to ½(M, ω); to |ρ_μ M|), maximised over the
    states with sinθ ≥ ``min_sin_theta``; tolerance :data:`TOLERANCE`.
    """
    if system.kind not in ("veselova", "chaplygin_ball"):
        return []
    states = np.atleast_2d(np.asarray(states, dtype=float))
    p = np.asarray(parameters, dtype=float)
    kernels = _kernels(system)
    gamma = states[:, 3:6]
    if system.kind == "veselova":
        omega = states[:, 0:3]
    else:
        inertia_idx = [system.parameter_symbols.index(s) for s in (I1, I2, I3, D)]
        i1, i2, i3, d = p[inertia_idx]
        IQ = np.diag([i1 + d, i2 + d, i3 + d])[None, :, :] - d * np.einsum("ni,nj->nij", gamma, gamma)
        omega = np.linalg.solve(IQ, states[:, 0:3, None])[:, :, 0]
    th, ph, thd, phd, psd, s = euler_angles_and_rates(omega, gamma)
    keep = np.abs(s) >= min_sin_theta
    used, skipped = int(keep.sum()), int((~keep).sum())
    th, ph, thd, phd = th[keep], ph[keep], thd[keep], phd[keep]
    vector = kernels.vector(states[keep], p) if used else np.zeros((0, 4))

    if system.kind == "veselova":
        T_vec, L_vec, U = vector[:, 0], vector[:, 1], vector[:, 2]
        T_loc = kernels.local(np.column_stack([th, ph, thd, phd]), p)[:, 0] if used else T_vec
        n = kernels.multiplier(np.column_stack([th, ph]), p)[:, 0] if used else T_vec
        L_loc = kernels.lagrangian(np.column_stack([th, ph, thd / n, phd / n]), p)[:, 0] if used else L_vec
        return [
            _item("euler_kinetic_energy", "T(theta, phi, thetadot, phidot)",
                  "T = T0 at psidot = -cos(theta) phidot: "
                  "1/2 I1 (thetadot cos phi - phidot sin phi sin theta cos theta)^2"
                  " + 1/2 I2 (thetadot sin phi + phidot cos phi sin theta cos theta)^2 + 1/2 I3 phidot^2 sin^4 theta"
                  " = (I omega, omega)/2", "2504-8", _relative(T_loc, T_vec, np.abs(T_vec)) if used else None,
                  used, skipped, min_sin_theta, "|T_local - (I omega, omega)/2| / ((I omega, omega)/2)"),
            _item("euler_reduced_lagrangian", "L(theta, phi, theta', phi') after N dt = d tau",
                  "L = T(theta, phi, N theta', N phi') - U = 1/2 (gamma' x gamma, I (gamma' x gamma)) / "
                  "(gamma, I^-1 gamma) - U, N = (gamma, I^-1 gamma)^(-1/2) (ERRATA 3)", "2504-9",
                  _relative(L_loc, L_vec, np.abs(T_vec) + np.abs(U)) if used else None, used, skipped,
                  min_sin_theta,
                  "|L_local - L_vector| / (|T| + |U|), theta' = thetadot / N, gamma' = gamma x omega / N"),
        ]

    M = states[keep, 0:3]
    c_val = np.einsum("ij,ij->i", M, gamma[keep])
    if used:
        mom = kernels.momenta(np.column_stack([th, ph, thd, phd, c_val]), p)
        local = kernels.local(np.column_stack([th, ph, mom[:, 0], mom[:, 1], c_val]), p)
    else:
        local = vector
    H_vec, L_vec = vector[:, 0], vector[:, 1:4]
    return [
        _item("euler_hamiltonian", "H(theta, phi, p_theta, p_phi)",
              "H of the theorem after eq. 007 as corrected in ERRATA 7 = 1/2 (L, adj(I_Q) L) = (M, omega)/2, "
              "p = N dR/d(qdot), N = rho_mu, c = (M, gamma)", "007",
              _relative(local[:, 0], H_vec, np.abs(H_vec)) if used else None, used, skipped, min_sin_theta,
              "|H_local - (M, omega)/2| / ((M, omega)/2)"),
        _item("euler_momenta", "L(theta, phi, p_theta, p_phi)",
              "L1 = p_theta cos phi - p_phi cos theta sin phi / sin theta + c N sin phi / sin theta, "
              "L2 = -p_theta sin phi - p_phi cos theta cos phi / sin theta + c N cos phi / sin theta, L3 = p_phi; "
              "= rho_mu M", "2604-5",
              _relative(local[:, 1:4], L_vec, np.linalg.norm(L_vec, axis=1)) if used else None, used, skipped,
              min_sin_theta, "|L(p) - rho_mu M| / |rho_mu M|"),
    ]
