"""The checks of a user's Lagrangian system that need numbers: at a few sample points q (and t) with the
parameters' values, the mass matrix M = ∂²L/∂q̇∂q̇ is regular, the constraints are homogeneous and
independent (rank A(q) = k), and A M⁻¹ Aᵀ is regular (so that the multipliers are determined).

A property that fails on a thin set only (Euler angles at sin θ = 0) holds at a generic point, so the
points are pseudo-random (fixed seed: the same input gives the same verdict) and a property counts as
holding when it holds at one of them; it is refused when it fails at every point where the system can be
evaluated (real and finite). What is cheap symbolically (a velocity without a kinetic term, a row of
zeros in M) is said in those terms.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import sympy as sp

from nonholonomic.lagrangian.parse import DataError, LagrangianData

#: How many sample points are tried.
SAMPLE_POINTS = 4
#: Coordinates at the sample points are drawn from this interval (inside most functions' domains).
SAMPLE_INTERVAL = (0.15, 0.85)
#: The time at the sample points.
SAMPLE_TIME = 0.37
#: A matrix counts as singular at a point when its smallest singular value is below this times its largest.
RANK_TOLERANCE = 1e-10
#: A constraint's term without velocities counts as zero below this times the size of its other terms.
HOMOGENEITY_TOLERANCE = 1e-10


def sample_points(data: LagrangianData) -> list[dict[sp.Symbol, float]]:
    """The substitutions {q, t, parameters → numbers} of the sample points."""
    rng = np.random.default_rng(20240704)
    low, high = SAMPLE_INTERVAL
    points = []
    for _ in range(SAMPLE_POINTS):
        point = dict(zip(data.q, (float(x) for x in rng.uniform(low, high, len(data.q)))))
        point[data.t] = SAMPLE_TIME
        point.update(data.parameter_values)
        points.append(point)
    return points


def number(expr: sp.Expr, point: dict[sp.Symbol, float]) -> float | None:
    """``expr`` at ``point`` as a float; None where it is not real and finite there."""
    try:
        value = complex(sp.sympify(expr).xreplace({s: sp.Float(x, 17) for s, x in point.items()}).evalf(17))
    except (TypeError, ValueError, ZeroDivisionError, OverflowError):
        return None
    if not (np.isfinite(value.real) and abs(value.imag) <= 1e-12 * max(1.0, abs(value.real))):
        return None
    return value.real


def numeric_matrix(matrix: sp.Matrix, point: dict[sp.Symbol, float]) -> np.ndarray | None:
    """``matrix`` at ``point``; None where an entry is not real and finite there."""
    out = np.empty(matrix.shape)
    for (i, j), _entry in np.ndenumerate(np.empty(matrix.shape)):
        value = number(matrix[i, j], point)
        if value is None:
            return None
        out[i, j] = value
    return out


def regular(matrix: np.ndarray) -> bool:
    """Whether the square ``matrix`` is regular to :data:`RANK_TOLERANCE` (relative)."""
    s = np.linalg.svd(matrix, compute_uv=False)
    return bool(s.size == 0 or s[0] > 0 and s[-1] > RANK_TOLERANCE * s[0])


def first_dependent_row(A: np.ndarray) -> int | None:
    """The first row of ``A`` that depends on the rows before it (rows scaled to unit length), or None."""
    rows: list[np.ndarray] = []
    for i, row in enumerate(A):
        size = np.linalg.norm(row)
        if size == 0:
            return i
        rows.append(row / size)
        s = np.linalg.svd(np.array(rows), compute_uv=False)
        if s[-1] <= RANK_TOLERANCE * max(s[0], 1.0) * len(rows):
            return i
    return None


def mass_matrix(data: LagrangianData) -> sp.Matrix:
    """``M = ∂²L/∂q̇∂q̇`` (independent of q̇: L is at most quadratic in the velocities)."""
    return sp.hessian(data.L, data.v)


def check_sample_points(data: LagrangianData, rests: tuple[sp.Expr, ...] = ()) -> None:
    """Refuse what the Lagrange–d'Alembert equations cannot take, checked at the sample points.

    Parameters
    ----------
    data : LagrangianData
        The parsed system.
    rests : tuple of sympy.Expr
        Per constraint, its value at q̇ = 0 (must vanish: the constraints are homogeneous).

    Raises
    ------
    DataError
        ``L``: no velocity of some coordinate in its kinetic part, M singular at every sample point, or L
        not real and finite at any; ``constraints[i]``: a term without velocities, or the constraint
        depends on the ones before it at every sample point; ``constraints``: A M⁻¹ Aᵀ singular.
    """
    M = mass_matrix(data)
    for j, vj in enumerate(data.v):
        if all(M[j, i] == 0 for i in range(M.shape[1])):
            raise DataError("L", f"has no kinetic term in {vj}: the row of {vj} in the mass matrix d2L/dq_dot2 is "
                                 "zero, so M is singular (a coordinate without inertia)")
    points = sample_points(data)
    fields = [("L", M), *((f"constraints[{i}]", data.A[i, :]) for i in range(data.A.shape[0]))]
    evaluated: list[tuple[dict[sp.Symbol, float], dict[str, np.ndarray]]] = []
    for point in points:
        computed = {field: numeric_matrix(sp.Matrix(matrix), point) for field, matrix in fields}
        finite = {field: value for field, value in computed.items() if value is not None}
        if len(finite) == len(computed):
            evaluated.append((point, finite))
    if not evaluated:
        field = next((f for f, m in fields if all(numeric_matrix(sp.Matrix(m), p) is None for p in points)), "L")
        raise DataError(field, f"is not real and finite at any of {len(points)} sample points with coordinates in "
                               f"{SAMPLE_INTERVAL} (check its domain and the parameters' values)")
    for i, rest in enumerate(rests):
        if rest == 0:
            continue
        scale = [np.abs(values[f"constraints[{i}]"]).sum() for _, values in evaluated]
        for (point, _), size in zip(evaluated, scale):
            r = number(rest, point)
            if r is None or abs(r) > HOMOGENEITY_TOLERANCE * max(size, 1e-300):
                raise DataError(f"constraints[{i}]", f"is not homogeneous in the velocities: its term without "
                                                     f"velocities, {sp.sstr(rest)}, is not zero")
    if not any(regular(values["L"]) for _, values in evaluated):
        raise DataError("L", "the mass matrix d2L/dq_dot2 is singular at every sample point (with the parameters' "
                             "values): the accelerations are not determined")
    k = data.A.shape[0]
    if k == 0:
        return
    dependent: list[int | None] = []
    for _, values in evaluated:
        A = np.vstack([values[f"constraints[{i}]"] for i in range(k)])
        dependent.append(first_dependent_row(A))
    rows = [row for row in dependent if row is not None]
    if len(rows) == len(dependent):  # a dependent row at every point
        i = max(rows)  # the point where the most constraints are independent
        raise DataError(f"constraints[{i}]", f"depends on the constraints before it (rank A(q) < {k} at every "
                                             "sample point): remove it")
    for _, values in evaluated:
        A = np.vstack([values[f"constraints[{i}]"] for i in range(k)])
        if regular(values["L"]) and first_dependent_row(A) is None and regular(A @ np.linalg.solve(values["L"], A.T)):
            return
    raise DataError("constraints", "A M^-1 A^T is singular at every sample point: the multipliers are not "
                                   "determined (is the mass matrix indefinite?)")


def field_problem(data: LagrangianData, q: Sequence[float], qdot: Sequence[float],
                  values: Mapping[sp.Symbol, float] | None = None) -> str | None:
    """Why the Lagrange–d'Alembert field of ``data`` is not determined at the state (q, q̇), or None.

    Numbers only (M, h, A and Ȧ q̇ evaluated there, then q̈ = M⁻¹(Aᵀλ − h) with
    λ = (A M⁻¹ Aᵀ)⁻¹(A M⁻¹ h − Ȧ q̇) solved in floating point): what a request's initial state is
    checked with before the equations are derived, in milliseconds whatever the system's size.

    Parameters
    ----------
    data : LagrangianData
        The parsed system.
    q, qdot : sequence of float
        The state.
    values : mapping, optional
        The parameters' values (default: the system's own).
    """
    from nonholonomic.lagrangian.equations import dynamics_terms

    point: dict[sp.Symbol, float] = {**dict(zip(data.q, map(float, q))), **dict(zip(data.v, map(float, qdot))),
                                     data.t: 0.0, **dict(values if values is not None else data.parameter_values)}
    M, h, A, Adot_v = dynamics_terms(data)
    Mn, An = numeric_matrix(M, point), numeric_matrix(A, point) if A.shape[0] else np.zeros((0, len(data.q)))
    hn, dn = (numeric_matrix(sp.Matrix(h), point),
              numeric_matrix(sp.Matrix(Adot_v), point) if Adot_v else np.zeros((0, 1)))
    if Mn is None or An is None or hn is None or dn is None:
        return "L or a constraint is not real and finite there"
    if not regular(Mn):
        return "the mass matrix d2L/dq_dot2 is singular there"
    W, u = np.linalg.solve(Mn, An.T), np.linalg.solve(Mn, hn[:, 0])
    if An.shape[0]:
        S = An @ W
        if not regular(S):
            return "A M^-1 A^T is singular there: the multipliers are not determined"
        qddot = W @ np.linalg.solve(S, An @ u - dn[:, 0]) - u
    else:
        qddot = -u
    return None if np.all(np.isfinite(qddot)) else "the accelerations are not finite there"
