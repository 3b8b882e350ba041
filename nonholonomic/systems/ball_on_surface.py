"""A dynamically symmetric ball rolling on any surface: its centre moves on Φ(x) = 0, with Φ written
by the user.

Paper, section "Nonholonomic Jacobi problem", eq. (2804-1) for a general surface. The equations are
those of :mod:`nonholonomic.systems.ball_on_quadric` (the quadric is the fast special case, with its
Joachimsthal-like integral K); only the normal changes::

    n = ∇Φ/|∇Φ|,   dx/dt = R ω × n,
    (D₀ + D) dω/dt = D (ω, n) dn/dt − R n × ∂U/∂x,   D = m R²,   eq. (2804-1), ERRATA 11

with dn/dt = (∂n/∂x) dx/dt (sympy differentiates n(x); it is the paper's formula after eq. 2804-1).
The elimination of the reaction that gives this form does not depend on the surface and is checked
once, by :func:`nonholonomic.systems.ball_on_quadric.reduction_residual`. Integrals::

    Φ(x) = 0,   H = ½(D₀ + D) ω² − ½ D (ω, n)² + U(x)   (eq. 2804-2, ERRATA 12),

and the invariant measure |∇Φ(x)| d³ω d³x on the 6-dimensional space (x, ω) (eq. 2804-3 as read in
ERRATA 13). The paper expects no further integral in general, so none is claimed.

Φ is parsed by the safe parser (:mod:`nonholonomic.expressions`, never eval), in ``x1, x2, x3`` and the
surface's own scalar parameters, and made smooth as a potential is (the equations use its second
derivatives). An initial x off the surface is projected by Newton's steps along the gradient,
``x → x − Φ ∇Φ/|∇Φ|²``.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from functools import lru_cache

import sympy as sp

from nonholonomic.definition import (
    DerivedVector,
    FirstIntegral,
    InvariantMeasure,
    MechanicalSystem,
    Parameter,
    Projection,
    StateConstraint,
    cross,
    dot,
    gradient,
)
from nonholonomic.expressions import ExpressionError, declare_symbols, parse_expression
from nonholonomic.kinds import SystemKind
from nonholonomic.memo import remembered
from nonholonomic.potentials import (
    MAX_EXPRESSION_LENGTH,
    MAX_EXPRESSION_PARAMETERS,
    Potential,
    potential_symbols,
    resolve,
    smooth_potential,
)
from nonholonomic.systems import ball_on_quadric as bq
from nonholonomic.systems.ball_on_quadric import R, angular_acceleration, omega, x

KIND = "ball_on_surface"
TITLE = "A dynamically symmetric ball rolling on a surface Phi(x) = 0 of the user's own"

#: D0, m, R: the ball is that of the nonholonomic Jacobi problem; so are its potentials.
PARAMETERS = bq.PARAMETERS[:3]
POTENTIALS = bq.POTENTIALS
#: The state vectors a potential of this kind may use (an expression potential uses their components).
POTENTIAL_VARIABLES = ("x",)
#: The names Φ may use besides its own parameters.
SURFACE_VARIABLES = tuple(potential_symbols(("x",)))
#: Newton steps at most when an initial x is projected onto Φ = 0.
PROJECTION_STEPS = 50


@dataclass(frozen=True)
class Surface:
    """The surface Φ(x) = 0 on which the ball's centre moves, as the user wrote it."""

    text: str
    Phi: sp.Expr
    parameters: tuple[Parameter, ...]


@lru_cache(maxsize=128)
def surface(text: str, parameters: tuple[str, ...] = ()) -> Surface:
    """The surface ``Φ = text`` in ``x1, x2, x3`` and the scalar ``parameters`` (their values come with
    the request), parsed without eval and cached by text and parameter names.

    Raises
    ------
    ExpressionError
        The text is not such an expression, uses a function without a second derivative (abs, sign),
        does not depend on x, or a parameter's name is taken.
    """
    if len(parameters) > MAX_EXPRESSION_PARAMETERS:
        raise ExpressionError(f"at most {MAX_EXPRESSION_PARAMETERS} parameters")
    for name in parameters:
        if name in SURFACE_VARIABLES:
            raise ExpressionError(f"parameter name {name!r} is a component of x")
    symbols = declare_symbols([*SURFACE_VARIABLES, *parameters])
    Phi = smooth_potential(parse_expression(text, symbols, max_length=MAX_EXPRESSION_LENGTH))
    Phi = Phi.xreplace({symbols[name]: xi for name, xi in zip(SURFACE_VARIABLES, x)})
    if not Phi.free_symbols & set(x):
        raise ExpressionError("Phi does not depend on x1, x2, x3: it defines no surface")
    return Surface(text, Phi, tuple(Parameter(name, (symbols[name],), "parameter of the surface Phi", "as Phi needs")
                                    for name in parameters))


#: The surface of the catalog's example and of ``define(potential)`` without one: a torus of tube
#: radius r0 around a circle of radius a0 (a quartic), on which the centre of the ball moves.
TORUS = "(x1**2 + x2**2 + x3**2 + a0**2 - r0**2)**2 - 4*a0**2*(x1**2 + x2**2)"
DEFAULT_SURFACE = surface(TORUS, ("a0", "r0"))

#: A job request for this kind (the catalog shows it; tests and benchmarks run it).
EXAMPLE = {
    "system": {"kind": KIND, "D0": 0.036, "m": 1.0, "R": 0.3,
               "surface": {"Phi": TORUS, "parameters": {"a0": 2.0, "r0": 1.0}},
               "potential": {"kind": "linear", "a": [0.0, 0.0, 9.81]}},
    "initial_state": {"x": [3.0, 0.0, 0.0], "omega": [0.5, 2.0, 0.3]},
    "t_final": 100.0, "samples": 201,
}

STATE = bq.STATE


def surface_gradient(Phi: sp.Expr) -> sp.Matrix:
    """``∇Φ(x)``."""
    return gradient(Phi, x)


def normal(Phi: sp.Expr) -> sp.Matrix:
    """``n = ∇Φ/|∇Φ|``: the unit normal of the surface at x (eq. 2804-1)."""
    g = surface_gradient(Phi)
    return g / sp.sqrt(dot(g, g))


def gradient_norm(Phi: sp.Expr) -> sp.Expr:
    """``|∇Φ(x)|``: the density of eq. (2804-3) (for d³ω d³x, ERRATA 13)."""
    g = surface_gradient(Phi)
    return sp.sqrt(dot(g, g))


def equations_of_motion(Phi: sp.Expr, U: sp.Expr, torque: sp.Expr = -R) -> tuple[sp.Expr, ...]:
    """``(dx/dt, dω/dt)`` of eq. (2804-1) on the surface Φ = 0 (``torque = −R`` is ERRATA 11's form)."""
    n = normal(Phi)
    x_dot = R * cross(omega, n)
    n_dot = n.jacobian(x) * x_dot
    return tuple(x_dot) + tuple(angular_acceleration(n, n_dot, gradient(U, x), torque))


def energy(Phi: sp.Expr, U: sp.Expr) -> sp.Expr:
    """``H = ½(D₀ + D) ω² − ½ D (ω, n)² + U`` (eq. 2804-2, ERRATA 12)."""
    return bq.kinetic_energy(normal(Phi)) + U


def newton_step(Phi: sp.Expr) -> tuple[sp.Expr, ...]:
    """``x − Φ ∇Φ/|∇Φ|²``: one Newton step of x towards Φ = 0 along the gradient."""
    g = surface_gradient(Phi)
    return tuple(x - Phi * g / dot(g, g))


@lru_cache(maxsize=64)  # as the kernels and integrators compiled from it
@remembered("definition")  # derived once per machine and version (nonholonomic.memo)
def define(potential: str | Potential = "zero", on: Surface = DEFAULT_SURFACE) -> MechanicalSystem:
    """The ball rolling with ``potential`` (a key of :data:`POTENTIALS` or a user's) on the surface ``on``.

    Raises
    ------
    AssertionError
        If sympy's elimination of the reaction does not reduce to the closed form used.
    """
    bq.check_reduction()
    pot = resolve(POTENTIALS, potential)
    variables = {"x": x}
    U = pot.build(variables)
    Phi = on.Phi
    n = normal(Phi)
    kinetic = bq.kinetic_energy(n)
    size = sp.sqrt(dot(x, x)) * gradient_norm(Phi) + sp.Abs(Phi)  # the size of Φ's terms near the surface
    formula = f"Phi(x) = {on.text} = 0"
    return MechanicalSystem(
        kind=KIND,
        potential=pot.kind,
        title=TITLE,
        equation="2804-1",
        parameters=PARAMETERS + on.parameters + pot.parameters,
        state=STATE,
        rhs=equations_of_motion(Phi, U),
        integrals=(
            FirstIntegral("surface", Phi, size, formula, "2804-2"),
            FirstIntegral("energy", kinetic + U, kinetic + pot.scale(variables),
                          "H = (D0 + D) omega^2/2 - D (omega, n)^2/2 + U(x), D = m R^2", "2804-2"),
        ),
        measure=InvariantMeasure(gradient_norm(Phi), "rho = |grad Phi(x)| (density for d^3omega d^3x)", "2804-3"),
        reduced_time=None,
        potential_formula=pot.formula,
        derived=(
            DerivedVector("v", tuple(R * cross(omega, n)), "v = R omega x n",
                          "velocity of the ball's centre, space-fixed frame", "m/s"),
            DerivedVector("n", tuple(n), "n = grad Phi/|grad Phi|", "unit normal of the surface at x, space-fixed "
                          "frame", "1"),
        ),
        constraints=(
            StateConstraint("x", Phi, 0.0, f"{formula}: x must lie on the surface", "2804-2", scale=size,
                            projection=Projection("x", newton_step(Phi),
                                                  "Newton's steps x -> x - Phi grad Phi/|grad Phi|^2 until Phi = 0",
                                                  steps=PROJECTION_STEPS)),
        ),
        notes=(f"the surface: {formula}",
               "(D0 + m R^2) domega/dt = m R^2 (omega, n) dn/dt - R n x dU/dx with n = grad Phi/|grad Phi|: the "
               "printed eq. 2804-1 has the wrong sign and power of R in the potential's term (ERRATA 11)",
               "in H the coefficient of (omega, n)^2/2 is D = m R^2, not D0 (ERRATA 12)",
               "the density |grad Phi| is for d^3omega d^3x on the 6-dimensional space (ERRATA 13)",
               "no integral besides Phi and H is claimed: in general there is none (paper, after eq. 2804-3); "
               "for a quadric, kind ball_on_quadric adds the Joachimsthal-like K"),
    )


#: The kind's record (nonholonomic.kinds): it takes the user's surface Phi; no sampling plan (the extent of the
#: surface's level sets is unknown).
SYSTEM_KIND = SystemKind(sys.modules[__name__], surface=True)
