"""An integral found in the coordinates (q, u) of the constraint manifold, written again in the full velocities
where that removes its singular denominator (issue 33, item 5).

The searches write an integral with the dependent velocities eliminated, q̇_D = −A_D⁻¹ A_I u, so it carries
powers of Δ = det A_D in its denominator: the Chaplygin skate's energy is (… + 1500 ẋ²)/(2000 cos²θ), singular
where the blade is along y, on the orbit it describes. Here the manifold's velocities are written as q̇ = B̃(q) w
with B̃ the columns of B (q̇ = B u) each multiplied by its denominators (the skate: B̃ = [(cos θ, sin θ, 0),
(0, 0, 1)], w = (speed along the blade, θ̇)), u replaced by its part of B̃ w and w by (B̃ᵀB̃)⁻¹ B̃ᵀ q̇. The result
equals the integral on the manifold (where the motion is); it is kept only when its denominator is a constant,
i.e. it is regular everywhere.
"""

from __future__ import annotations

from collections.abc import Sequence

import sympy as sp

from nonholonomic.lagrangian.equations import dependent_columns, tidy
from nonholonomic.lagrangian.parse import LagrangianData
from nonholonomic.work_limits import operations

__all__ = ["dependent_velocities", "regular_density", "regular_form"]

#: Integrals of more operations than this are left as they are (a bound on the work, not a clock).
MAX_OPS = 400


def dependent_velocities(data: LagrangianData, columns: Sequence[int] | None = None,
                         ) -> tuple[tuple[sp.Symbol, sp.Expr], ...]:
    """The dependent velocities as functions of (q, u): those of ``columns``, by default the columns the searches
    choose (:func:`~nonholonomic.lagrangian.equations.dependent_columns`)."""
    columns = dependent_columns(data) if columns is None else columns
    k = data.A.shape[0]
    if not k or columns is None:
        return ()
    A = sp.Matrix(data.A)
    independent = [j for j in range(len(data.v)) if j not in columns]
    solved = A.extract(list(range(k)), list(columns)).LUsolve(
        -A.extract(list(range(k)), independent) * sp.Matrix([data.v[j] for j in independent]))
    return tuple((data.v[j], tidy(solved[r])) for r, j in enumerate(columns))


def regular_form(data: LagrangianData, expression: sp.Expr, dependent: tuple[tuple[sp.Symbol, sp.Expr], ...],
                 ) -> sp.Expr | None:
    """``expression`` (in q and the independent velocities u) in the full velocities without a singular
    denominator, equal to it on the constraint manifold; None when it already has none or none was found.

    Parameters
    ----------
    data : the user's system.
    expression : an integral in (q, u).
    dependent : the dependent velocities as functions of (q, u), as the searches solved them.
    """
    if not dependent or sp.denom(sp.together(expression)).is_number or operations(expression) > MAX_OPS:
        return None
    on = dict(dependent)
    u = [v for v in data.v if v not in on]
    velocities = [on.get(v, v) for v in data.v]
    columns = []
    for j in u:
        column = [sp.together(sp.diff(e, j)) for e in velocities]
        scale = sp.lcm([sp.denom(c) for c in column])
        columns.append([_cancelled(c * scale) for c in column])
    B = sp.Matrix(columns).T  # n x m, no denominators
    w = sp.symbols(f"w0:{len(u)}")
    in_w = {uj: sum((B[data.v.index(uj), k] * w[k] for k in range(len(u))), sp.Integer(0)) for uj in u}
    F_w = _cancelled(expression.xreplace(in_w))
    if not sp.denom(F_w).is_number:
        return None
    gram = tidy_matrix(B.T * B)
    if not sp.denom(sp.together(gram.det())).is_number:
        return None
    inverse = tidy_matrix(gram.inv())
    w_of_qdot = inverse * B.T * sp.Matrix(data.v)
    if any(not sp.denom(sp.together(e)).is_number for e in w_of_qdot):
        return None
    regular = _cancelled(F_w.xreplace(dict(zip(w, w_of_qdot))))
    return regular if sp.denom(regular).is_number else None


def regular_density(density: sp.Expr, point: dict[sp.Symbol, float]) -> sp.Expr | None:
    """A density with radicals whose square cancels to a perfect square without a denominator, written without
    them (the sign it has at ``point``): the skate's cos θ / √(1 − sin²θ) in (q, q̇) is ±1, and evaluated as
    written it loses digits where cos θ → 0 (its pointwise check failed there, 5.8e-9, beside a symbolic proof).
    None when the density has no radical or its square does not simplify so."""
    if not any(not p.exp.is_integer for p in density.atoms(sp.Pow)) or operations(density) > MAX_OPS:
        return None
    square = _cancelled(density**2)
    if not sp.denom(square).is_number:
        return None
    root = sp.sqrt(sp.factor(square))
    if root.has(sp.Abs) or any(not p.exp.is_integer for p in root.atoms(sp.Pow)):
        return None
    value = complex(root.evalf(subs=point)).real
    original = complex(density.evalf(subs=point)).real
    if value == 0 or original == 0:
        return None
    return root if (value > 0) == (original > 0) else -root


def _cancelled(expr: sp.Expr) -> sp.Expr:
    """``expr`` as one fraction cancelled with sin² = 1 − cos² in numerator and denominator, or with
    cos² = 1 − sin² when that leaves a constant denominator (:func:`tidy` writes them apart)."""
    together = sp.together(expr)
    angles = {f.args[0] for f in together.atoms(sp.sin, sp.cos)}
    best = tidy(together)
    for square, other in ((sp.sin, sp.cos), (sp.cos, sp.sin)):
        rule = {square(a) ** 2: 1 - other(a) ** 2 for a in angles}
        num, den = sp.fraction(together)
        candidate = sp.cancel(sp.expand(num).subs(rule) / sp.expand(den).subs(rule))
        if sp.denom(candidate).is_number:
            return sp.expand(candidate)
    return best


def tidy_matrix(matrix: sp.Matrix) -> sp.Matrix:
    return matrix.applyfunc(_cancelled)
