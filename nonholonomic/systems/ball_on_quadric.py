"""The nonholonomic Jacobi problem: a dynamically symmetric ball rolling on a fixed surface whose
centre moves on the quadric Φ(x) = (x, B⁻¹x) − 1 = 0.

Paper, section "Nonholonomic Jacobi problem". Constraint and equations with the reaction N
(all vectors in the space-fixed frame, I = D₀·1)::

    v − R ω × n = 0,   n = ∇Φ/|∇Φ|,   m dv/dt = N − ∂U/∂x,   D₀ dω/dt = R N × n,

where v = dx/dt (the printed "μ dω/dt" means D₀ dω/dt, ERRATA 11). Eliminating N (done by sympy
in :func:`eliminate_reaction`, with dv/dt = R(dω/dt × n + ω × dn/dt)) gives, on |n| = 1,
(n, dn/dt) = 0,

    (D₀ + D) dω/dt = D (ω, n) dn/dt − R n × ∂U/∂x,   dx/dt = R ω × n,   D = m R²,   eq. (2804-1)

with dn/dt = (∂n/∂x) dx/dt (sympy differentiates n(x) along dx/dt; it equals the paper's formula
after eq. 2804-1, dn/dt = (1 − n⊗n) Hess Φ dx/dt / |∇Φ|). The paper prints
(m + D₀/R²) dω/dt = m(ω,n) dn/dt + R n×∂U/∂x, i.e. a torque +R³ n×∂U/∂x in the form above, where
−R n×∂U/∂x holds (−(1/R) n×∂U/∂x in the printed normalisation, ERRATA 11): both the sign and the
power of R are wrong, and with either +R or +R³ the energy is not conserved (tests). Integrals
(eq. 2804-2 as corrected by ERRATA 12, the printed μ there is D)::

    Φ(x) = 0,   H = ½(D₀ + D) ω² − ½ D (ω, n)² + U(x),

the invariant measure |∇Φ(x)| d³ω d³x on the 6-dimensional space (x, ω) (eq. 2804-3 as read in
ERRATA 13) and, for U = 0, the Joachimsthal-like integral (eq. 2804-4)::

    K = (ω × n, B⁻¹ ω × n) / (n, B n).

For U = k/2 x² the paper says K "can be extended" without the form. Derived here: the potential
adds −R k/(D₀ + D) n × x to dω/dt, and with (n, B n) = (x, B⁻¹x)/|B⁻¹x|², (n, x) = (x, B⁻¹x)/|B⁻¹x|
and (ω × n, B⁻¹x) = 0 this changes d/dt K by 2k/(D₀ + D) (v, B⁻²x) = k/(D₀ + D) d/dt (x, B⁻²x). So

    K_k = K − k (x, B⁻²x)/(D₀ + D)    ((x, B⁻²x) = |∇Φ|²/4)

is an integral on every level of Φ (its Lie derivative vanishes to round-off in the tests).

Formulation: a request gives B (3 numbers for a diagonal one or a 3×3 matrix, positive definite);
the parameter "B" is checked and inverted (``transform=numpy.linalg.inv``), and its six symbols
``Binv11 … Binv33`` are the entries of A = B⁻¹, the matrix the equations use: Φ = (x, A x) − 1,
∇Φ = 2 A x, n = A x/|A x|, |∇Φ| = 2 |A x|. The field and the density are thus algebraic in A
with no determinant (sympy proves the measure in a few seconds). Only K needs B itself, written
B = adj(A)/det A.
"""

from __future__ import annotations

import sys
from functools import cache, lru_cache

import numpy as np
import sympy as sp

from nonholonomic.definition import (
    DerivedVector,
    FirstIntegral,
    InvariantMeasure,
    MechanicalSystem,
    Parameter,
    Projection,
    StateConstraint,
    StateVector,
    cross,
    dot,
    gradient,
    symmetric_matrix_symbols,
    upper_triangle,
    vector_symbols,
)
from nonholonomic.kinds import Sampling, SystemKind, root_words
from nonholonomic.memo import remembered
from nonholonomic.potentials import ZERO, Potential, catalog_of, harmonic, linear, resolve

KIND = "ball_on_quadric"
TITLE = "Nonholonomic Jacobi problem: a dynamically symmetric ball rolling on a quadric surface"

D0, m, R = sp.symbols("D0 m R", positive=True)
#: A = B⁻¹: the six symbols of the parameter "B" (the request's B is inverted before use).
A = symmetric_matrix_symbols("Binv")
B_inv = A
#: adj(A) = det(A) B and det A = 1/det B: polynomial in the entries of A.
A_adj = A.adjugate()
A_det = sp.expand(A.det())
#: B = A⁻¹ = adj(A)/det A (only K uses it).
B = A_adj / A_det
x = vector_symbols("x")
omega = vector_symbols("omega")

#: D = m R² (eq. 2804-2).
D = m * R**2

PARAMETERS = (
    Parameter("D0", (D0,), "central moment of inertia of the dynamically symmetric ball (I = D0·1)", "kg m^2",
              minimum=0.0, strict=True),
    Parameter("m", (m,), "mass of the ball", "kg", minimum=0.0, strict=True),
    Parameter("R", (R,), "radius of the ball", "m", minimum=0.0, strict=True),
    Parameter("B", upper_triangle(A), "symmetric positive-definite matrix B of the quadric (x, B^-1 x) = 1 "
              "on which the centre moves; the equations use B^-1 (the components are its entries)", "m^2 "
              "(B^-1, used by the equations: 1/m^2)", shape="symmetric_matrix", positive_definite=True,
              transform=np.linalg.inv, transform_formula="B^-1"),
)
POTENTIALS = catalog_of(ZERO, linear("x", unit="kg m/s^2"), harmonic("x"))
#: The state vectors a potential of this kind may depend on (an expression potential uses their components).
POTENTIAL_VARIABLES = ("x",)

#: A job request for this kind (the catalog shows it; tests and benchmarks run it).
EXAMPLE = {
    "system": {"kind": KIND, "D0": 0.036, "m": 1.0, "R": 0.3, "B": [1.0, 2.0, 3.0], "potential": {"kind": "zero"}},
    "initial_state": {"x": [0.4, 0.72, 1.32], "omega": [1.2, -0.8, 2.0]},
    "t_final": 1000.0, "samples": 201,
}

STATE = (
    StateVector("x", tuple(x), "position of the ball's centre, space-fixed frame", "m"),
    StateVector("omega", tuple(omega), "angular velocity of the ball, space-fixed frame", "rad/s"),
)


def quadric(v: sp.Matrix = x) -> sp.Expr:
    """``Φ(x) = (x, B⁻¹x) − 1 = (x, A x) − 1`` (text before eq. 2804-4)."""
    return dot(v, A * v) - 1


def normal(v: sp.Matrix = x, C: sp.Matrix = A) -> sp.Matrix:
    """``n = ∇Φ/|∇Φ| = C x / |C x|`` with ``C = A = B⁻¹`` (∇Φ = 2 A x).

    Any symmetric ``C`` may be given.
    """
    g = C * v
    return g / sp.sqrt(dot(g, g))


def gradient_norm(v: sp.Matrix = x) -> sp.Expr:
    """``|∇Φ(x)| = 2 |A x|``: the density of eq. (2804-3)."""
    g = A * v
    return 2 * sp.sqrt(dot(g, g))


def centre_velocity(w: sp.Matrix = omega, v: sp.Matrix = x, C: sp.Matrix = A) -> sp.Matrix:
    """``dx/dt = R ω × n`` (the rolling constraint, eq. 2804-1)."""
    return R * cross(w, normal(v, C))


def normal_rate(w: sp.Matrix = omega, v: sp.Matrix = x, C: sp.Matrix = A) -> sp.Matrix:
    """``dn/dt = (∂n/∂x) dx/dt``: the time derivative of n(x) along the flow (sympy's Jacobian)."""
    return normal(v, C).jacobian(v) * centre_velocity(w, v, C)


def eliminate_reaction() -> tuple[sp.Matrix, sp.Matrix, dict[str, sp.Matrix]]:
    """Solve the equations with the reaction for ``(dω/dt, N)`` by sympy, with generic vectors.

    ``m dv/dt = N − F``, ``D₀ dω/dt = R N × n``, ``dv/dt = R(dω/dt × n + ω × dn/dt)`` with
    F = ∂U/∂x, and n, dn/dt kept as free symbols (|n| = 1 is *not* assumed).

    Returns
    -------
    omega_dot, N : the solution.
    symbols : the free vectors used, ``{"n", "n_dot", "F", "omega"}``.
    """
    n, n_dot, F = vector_symbols("n"), vector_symbols("ndot"), vector_symbols("F")
    omega_dot, N = vector_symbols("omegadot"), vector_symbols("N")
    v_dot = R * (cross(omega_dot, n) + cross(omega, n_dot))
    equations = list(m * v_dot - N + F) + list(D0 * omega_dot - R * cross(N, n))
    (solution,) = sp.solve(equations, list(omega_dot) + list(N), dict=True)
    return (omega_dot.subs(solution), N.subs(solution),
            {"n": n, "n_dot": n_dot, "F": F, "omega": omega})


def angular_acceleration(n: sp.Matrix, n_dot: sp.Matrix, F: sp.Matrix, torque: sp.Expr = -R) -> sp.Matrix:
    """``dω/dt = (D (ω, n) dn/dt + torque · n × F)/(D₀ + D)`` with F = ∂U/∂x.

    ``torque = −R`` is the derived form (ERRATA 11); the printed eq. (2804-1) multiplied by R² has
    ``torque = +R³``.
    """
    return (D * dot(omega, n) * n_dot + torque * cross(n, F)) / (D0 + D)


@cache
@remembered("reduction")
def reduction_residual() -> sp.Matrix:
    """The solved dω/dt of :func:`eliminate_reaction` minus :func:`angular_acceleration` on the
    constraint set |n| = 1, (n, dn/dt) = 0, simplified (the zero vector if the closed form is right).

    n is the rational parametrisation of the unit sphere n = (2a, 2b, 1 − a² − b²)/(1 + a² + b²)
    and dn/dt = n × w with a free w, so the identity is a rational one in (a, b, w, ω, F).
    """
    omega_dot, _, s = eliminate_reaction()
    a, b = sp.symbols("a b", real=True)
    w = vector_symbols("w")
    n = sp.Matrix([2 * a, 2 * b, 1 - a**2 - b**2]) / (1 + a**2 + b**2)
    on_sphere = {**dict(zip(s["n"], n)), **dict(zip(s["n_dot"], cross(n, w)))}
    closed = angular_acceleration(s["n"], s["n_dot"], s["F"])
    return (omega_dot - closed).subs(on_sphere).applyfunc(sp.cancel)


def check_reduction() -> None:
    """Raise AssertionError unless :func:`reduction_residual` is zero (the closed form used is sympy's)."""
    if any(e != 0 for e in reduction_residual()):
        raise AssertionError("eliminating N does not give (D0 + D) domega/dt = D (omega, n) dn/dt - R n x dU/dx")


def kinetic_energy(n: sp.Matrix, coefficient: sp.Expr = D) -> sp.Expr:
    """``½(D₀ + D) ω² − ½ c (ω, n)²`` with ``c = D`` (eq. 2804-2, ERRATA 12) for the normal ``n``."""
    return (D0 + D) * dot(omega, omega) / 2 - coefficient * dot(omega, n) ** 2 / 2


def equations_of_motion(U: sp.Expr, torque: sp.Expr = -R, C: sp.Matrix = A) -> tuple[sp.Expr, ...]:
    """``(dx/dt, dω/dt)`` of eq. (2804-1) with the potential's ``torque`` coefficient (see
    :func:`angular_acceleration`) and ``n = C x/|C x|`` (``C = A = B⁻¹`` for the quadric)."""
    return tuple(centre_velocity(C=C)) + tuple(
        angular_acceleration(normal(C=C), normal_rate(C=C), gradient(U, x), torque))


def energy(U: sp.Expr, coefficient: sp.Expr = D) -> sp.Expr:
    """``H = ½(D₀ + D) ω² − ½ c (ω, n)² + U`` with ``c = D`` (eq. 2804-2, ERRATA 12)."""
    return kinetic_energy(normal(), coefficient) + U


def joachimsthal(k: sp.Expr = sp.Integer(0)) -> sp.Expr:
    """``K = (ω×n, B⁻¹ ω×n)/(n, B n) − k (x, B⁻²x)/(D₀ + D)`` (eq. 2804-4 for k = 0).

    The k-term is the extension to U = k/2 x² derived in the module docstring.
    """
    n = normal()
    w_x_n = cross(omega, n)
    # (n, B n) = (n, adj(A) n)/det A with A = B⁻¹.
    K = A_det * dot(w_x_n, A * w_x_n) / dot(n, A_adj * n)
    if k == 0:
        return K
    A_x = A * x
    return K - k * dot(A_x, A_x) / (D0 + D)


@lru_cache(maxsize=64)  # as the kernels and integrators compiled from it
@remembered("definition")  # derived once per machine and version (nonholonomic.memo)
def define(potential: str | Potential = "zero") -> MechanicalSystem:
    """The nonholonomic Jacobi problem with ``potential`` (a key of :data:`POTENTIALS`).

    Raises
    ------
    AssertionError
        If sympy's elimination of the reaction does not reduce to the closed form used.
    """
    check_reduction()
    pot = resolve(POTENTIALS, potential)
    variables = {"x": x}
    U = pot.build(variables)
    n = normal()
    B_inv_x = A * x
    x_B_inv_x = dot(x, B_inv_x)
    omega_sq = dot(omega, omega)
    kinetic = kinetic_energy(n)
    # ω² tr(B⁻¹)/(n, B n), with (n, B n) = (n, adj(A) n)/det A.
    K_scale = omega_sq * A.trace() * A_det / dot(n, A_adj * n)
    integrals = [
        FirstIntegral("quadric", quadric(), x_B_inv_x, "Phi(x) = (x, B^-1 x) - 1 = 0", "2804-2"),
        FirstIntegral("energy", energy(U), kinetic + pot.scale(variables),
                      "H = (D0 + D) omega^2/2 - D (omega, n)^2/2 + U(x), D = m R^2", "2804-2"),
    ]
    notes = ["(D0 + m R^2) domega/dt = m R^2 (omega, n) dn/dt - R n x dU/dx: derived by eliminating the reaction N; "
             "the printed eq. 2804-1, (m + D0/R^2) domega/dt = m (omega, n) dn/dt + R n x dU/dx, has the wrong "
             "sign and power of R and does not conserve energy (ERRATA 11)",
             "in H the coefficient of (omega, n)^2/2 is D = m R^2, not D0 (ERRATA 12)",
             "the density |grad Phi| is for d^3omega d^3x on the 6-dimensional space (ERRATA 13)",
             "the request gives B; its components Binv11..Binv33 are the entries of B^-1 (computed from B), which "
             "the equations use: Phi = (x, B^-1 x) - 1, n = B^-1 x/|B^-1 x|, |grad Phi| = 2 |B^-1 x|; "
             "only K uses B = adj(B^-1)/det(B^-1)"]
    if pot.kind == "zero":
        integrals.append(FirstIntegral("K", joachimsthal(), K_scale,
                                       "K = (omega x n, B^-1 omega x n)/(n, B n)", "2804-4"))
    elif pot.kind == "harmonic":
        k = pot.parameters[0].symbols[0]
        integrals.append(FirstIntegral(
            "K", joachimsthal(k), K_scale + sp.Abs(k) * dot(B_inv_x, B_inv_x) / (D0 + D),
            "K = (omega x n, B^-1 omega x n)/(n, B n) - k (x, B^-2 x)/(D0 + m R^2)", "2804-4"))
        notes.append("K for U = k/2 x^2: the paper only says it extends; the term -k (x, B^-2 x)/(D0 + D) is "
                     "derived here (the potential changes d/dt K by k/(D0 + D) d/dt (x, B^-2 x))")
    else:
        notes.append("no Joachimsthal-like integral K is claimed for the linear potential")
    return MechanicalSystem(
        kind=KIND,
        potential=pot.kind,
        title=TITLE,
        equation="2804-1",
        parameters=PARAMETERS + pot.parameters,
        state=STATE,
        rhs=equations_of_motion(U),
        integrals=tuple(integrals),
        measure=InvariantMeasure(gradient_norm(), "rho = |grad Phi(x)| = 2 |B^-1 x| (density for d^3omega d^3x)",
                                 "2804-3"),
        reduced_time=None,
        potential_formula=pot.formula,
        derived=(
            DerivedVector("v", tuple(centre_velocity()), "v = R omega x n", "velocity of the ball's centre, "
                          "space-fixed frame", "m/s"),
            DerivedVector("n", tuple(n), "n = grad Phi/|grad Phi| = B^-1 x/|B^-1 x|",
                          "unit normal of the quadric at x, space-fixed frame", "1"),
        ),
        constraints=(
            StateConstraint("x", quadric(), 0.0, "Phi(x) = (x, B^-1 x) - 1 = 0: x must lie on the quadric", "2804-2",
                            scale=x_B_inv_x,
                            projection=Projection("x", tuple(x / sp.sqrt(x_B_inv_x)),
                                                  "x -> x / sqrt((x, B^-1 x)) (radial, along x from the centre)")),
        ),
        notes=tuple(notes),
    )



def _sampling_words(names: tuple[str, ...]) -> str:
    if "K" not in names:
        return f"x uniform by area on the quadric; omega = t u with u uniform on the sphere; {root_words('eq. 2804-2')}"
    return ("x uniform by area on the quadric; with K fixed, omega = w + a n, w ⊥ n of uniform direction and size set "
            "by K (eq. 2804-4), a = ±sqrt(2 (h - U(x) - (D0 + D) w^2/2)/D0), either sign with probability 1/2 (eq. "
            "2804-2); else omega = t u with u uniform on the sphere; positions and directions that miss the level are "
            "redrawn")


#: The kind's record (nonholonomic.kinds): sampling on a level of H and K (eqs. 2804-2, 2804-4).
SYSTEM_KIND = SystemKind(sys.modules[__name__], sampling=Sampling("ball_on_quadric", "omega", ("energy", "K"),
                                                                  "eq. 2804-2", describe=_sampling_words))
