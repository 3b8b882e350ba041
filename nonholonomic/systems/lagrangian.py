"""A nonholonomic system written by the user as a Lagrangian L(q, q̇) in its own coordinates and constraints
linear and homogeneous in the velocities, as a :class:`MechanicalSystem` in the state (q, q̇).

The equations are the Lagrange–d'Alembert equations with the multipliers eliminated
(:func:`nonholonomic.lagrangian.derive`)::

    M(q) q̈ + h(q, q̇) = Aᵀ λ,   A(q) q̇ = 0,   M = ∂²L/∂q̇∂q̇,

the state being (q, q̇) (vectors ``q`` and ``q_dot``, n components each, n ≤ 8). Claimed along the motion:

* the energy E = (q̇, ∂L/∂q̇) − L (the constraint forces do no work: q̇ᵀAᵀλ = 0);
* every constraint fᵢ = Σⱼ Aᵢⱼ(q) q̇ⱼ, which stays 0 (the derived field keeps A q̇ constant);
* no invariant measure: the measure search for this kind is not built yet, so none is claimed (the
  ``measure`` check says so, undecided, never passed).

An initial q̇ off a constraint is refused (tolerance :data:`CONSTRAINT_TOLERANCE` relative to the
constraint's terms) or, on request, projected onto the constraints: orthogonally (Euclidean) onto the
rows of A made orthogonal by Gram–Schmidt, one constraint after the other, so that after the i-th
projection the first i constraints hold.

Jobs integrate autonomous systems: an L or a constraint with the time t explicitly is refused here
(:class:`~nonholonomic.lagrangian.DataError` naming the field), as is a parameter-free numeric field
the integrator cannot take.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import sympy as sp

from nonholonomic.definition import (
    FirstIntegral,
    InvariantMeasure,
    MechanicalSystem,
    Parameter,
    Projection,
    StateConstraint,
    StateVector,
)
from nonholonomic.lagrangian import DataError, LagrangianData, derive
from nonholonomic.lagrangian.parse import KIND, MAX_COORDINATES
from nonholonomic.memo import remembered

__all__ = ["CONSTRAINT_TOLERANCE", "EXAMPLE", "EXAMPLE_JOB", "KIND", "MAX_COORDINATES", "TITLE", "define"]

TITLE = "Lagrangian system with constraints linear in the velocities, written by the user"
#: The equations' source, for the results.
EQUATION = "Lagrange-d'Alembert"
#: An initial q̇ may violate a constraint by this much times max(1, Σⱼ |Aᵢⱼ q̇ⱼ|).
CONSTRAINT_TOLERANCE = 1e-10
#: Why no invariant measure is claimed.
NO_MEASURE = "none claimed: the invariant-measure search for lagrangian systems is not built yet (undecided)"

#: Chaplygin's sleigh: a knife edge at distance a from the centre of mass, in the plane.
EXAMPLE: dict[str, Any] = {
    "kind": KIND, "coordinates": ["x", "y", "theta"],
    "L": "m/2*((x_dot - a*sin(theta)*theta_dot)**2 + (y_dot + a*cos(theta)*theta_dot)**2) + J/2*theta_dot**2",
    "constraints": ["-sin(theta)*x_dot + cos(theta)*y_dot"],
    "parameters": {"m": 1.3, "a": 0.4, "J": 0.25}}
#: A job request with it.
EXAMPLE_JOB: dict[str, Any] = {"system": EXAMPLE, "initial_state": {"q": [0.2, -0.1, 0.0], "q_dot": [0.9, 0.0, 0.7]},
                               "t_final": 20.0, "samples": 201, "checks": ["integrals", "measure"]}


def _autonomous(data: LagrangianData) -> None:
    """Refuse an explicit time (the integrators take autonomous fields)."""
    for field, expr in (("L", data.L), *((f"constraints[{i}]", f) for i, f in enumerate(data.constraints))):
        if expr.has(data.t):
            raise DataError(field, "depends on the time t explicitly: jobs integrate autonomous systems only "
                                   "(a time-dependent L or constraint is not supported yet)")


def _projections(data: LagrangianData) -> tuple[Projection, ...]:
    """Per constraint, q̇ projected orthogonally onto the i-th row of A made orthogonal to the rows before it
    (Gram–Schmidt): applied in order, the i-th leaves the first i constraints satisfied."""
    v = sp.Matrix(data.v)
    rows: list[sp.Matrix] = []
    out = []
    for i in range(data.A.shape[0]):
        e = data.A[i, :].T
        for r in rows:
            e = e - r * (e.dot(r) / r.dot(r))
        rows.append(e)
        projected = v - e * (e.dot(v) / e.dot(e))
        out.append(Projection("q_dot", tuple(projected),
                              f"q_dot - e{i + 1} (e{i + 1}, q_dot)/|e{i + 1}|^2, e{i + 1} = row {i + 1} of A made "
                              "orthogonal to the rows before it (Gram-Schmidt)"))
    return tuple(out)


@lru_cache(maxsize=64)  # as the kernels and integrators compiled from it
@remembered("definition")  # derived once per machine and version (nonholonomic.memo)
def define(data: LagrangianData) -> MechanicalSystem:
    """The user's system as a :class:`MechanicalSystem` in the state (q, q̇).

    Parameters
    ----------
    data : LagrangianData
        From :func:`nonholonomic.lagrangian.lagrangian_data` (parsed and checked).

    Returns
    -------
    MechanicalSystem
        State vectors ``q`` and ``q_dot``; integrals: the energy and each constraint; no measure claimed.

    Raises
    ------
    DataError
        ``L`` or ``constraints[i]`` with the time t explicitly.
    DerivationError
        The symbolic derivation past its budget (:data:`nonholonomic.lagrangian.equations.DERIVATION_BUDGET_S`).
    """
    _autonomous(data)
    eqs = derive(data)
    q, v, L = data.q, data.v, data.L
    texts = dict(data.texts)
    half = sp.expand(sum((vi * sp.diff(L, vi) for vi in v), sp.Integer(0)) / 2)  # T₂ + T₁/2: the size of E's terms
    assert eqs.energy is not None  # L has no t (checked above)
    integrals = [FirstIntegral("energy", eqs.energy, sp.Abs(half) + sp.Abs(L - half), "E = (q_dot, dL/dq_dot) - L",
                               EQUATION)]
    constraints = []
    for i, (f, projection) in enumerate(zip(data.constraints, _projections(data))):
        scale = sum((sp.Abs(data.A[i, j] * v[j]) for j in range(len(v)) if data.A[i, j] != 0), sp.Integer(0))
        text = texts[f"constraints[{i}]"]
        integrals.append(FirstIntegral(f"constraint {i + 1}", f, scale, f"{text} = 0 (constraint {i + 1})", EQUATION))
        constraints.append(StateConstraint("q_dot", f, 0.0, f"{text} = 0 (constraint {i + 1})", EQUATION,
                                           tolerance=CONSTRAINT_TOLERANCE, scale=scale, projection=projection))
    return MechanicalSystem(
        kind=KIND,
        potential="zero",
        title=TITLE,
        equation=EQUATION,
        parameters=tuple(Parameter(str(s), (s,), "parameter of the user's system", "as L needs")
                         for s in data.parameters),
        state=(StateVector("q", q, f"generalized coordinates ({', '.join(map(str, q))})", "as L's coordinates"),
               StateVector("q_dot", v, f"generalized velocities ({', '.join(map(str, v))})", "q's unit/s")),
        rhs=eqs.rhs,
        integrals=tuple(integrals),
        measure=InvariantMeasure(None, NO_MEASURE, EQUATION),  # type: ignore[arg-type]
        reduced_time=None,
        potential_formula="U: part of L",
        constraints=tuple(constraints),
        notes=(f"L = {texts['L']}",
               "constraints: " + ("; ".join(f"{texts[f'constraints[{i}]']} = 0" for i in range(len(data.constraints)))
                                  or "none"),
               "Lagrange-d'Alembert equations derived symbolically, the multipliers eliminated"),
    )
