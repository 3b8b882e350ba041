"""The initial state of a simulation: named vectors → the state vector, checked against the system's
constraints (|γ| = 1, (ω, γ) = 0, the quadric ...) and, on request, projected onto them.

Shared by :mod:`nonholonomic.simulation`, :mod:`nonholonomic.isomorphisms` and the analysis modules
(it imports none of them, so the core has no import cycle).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np

from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.kernels import numeric, parameter_vector, state_vector
from nonholonomic.systems import registered


@dataclass(frozen=True)
class FieldProblem:
    """A violation in the input, with the dotted path of the offending field."""

    field: str
    reason: str


@dataclass(frozen=True)
class ProjectionReport:
    """What projecting the initial state onto one constraint changed."""

    field: str
    constraint: str
    projection: str
    value_before: float
    value_after: float
    change: float
    """max |component change| of the projected vector"""


def vector_slice(system: MechanicalSystem, name: str) -> slice:
    offset = 0
    for vec in system.state:
        if vec.name == name:
            return slice(offset, offset + len(vec.symbols))
        offset += len(vec.symbols)
    raise KeyError(name)


def _name_problems(system: MechanicalSystem, initial_state: Mapping[str, Sequence[float]]) -> list[FieldProblem]:
    problems: list[FieldProblem] = []
    names = [v.name for v in system.state]
    alternatives = {a.name: a for a in system.alternative_inputs}
    allowed = names + list(alternatives)
    for key in initial_state:
        if key not in allowed:
            problems.append(FieldProblem(f"initial_state.{key}",
                                         f"not a state variable of {system.kind}; expected {', '.join(allowed)}"))
    for name in names:
        givers = [name] * (name in initial_state) + [a for a, alt in alternatives.items()
                                                     if alt.replaces == name and a in initial_state]
        if not givers:
            options = " or ".join([name] + [a for a, alt in alternatives.items() if alt.replaces == name])
            problems.append(FieldProblem(f"initial_state.{name}", f"missing: give {options}"))
        elif len(givers) > 1:
            problems.append(FieldProblem(f"initial_state.{givers[1]}",
                                         f"give only one of {', '.join(givers)}: they describe the same state"))
    sizes = {v.name: len(v.symbols) for v in system.state} | {a.name: len(a.symbols) for a in system.alternative_inputs}
    for key, value in initial_state.items():
        if key in sizes and len(value) != sizes[key]:
            problems.append(FieldProblem(f"initial_state.{key}", f"needs {sizes[key]} components, got {len(value)}"))
    return problems


def project_initial_state(system: MechanicalSystem, p: np.ndarray,
                          y: np.ndarray) -> tuple[np.ndarray, list[ProjectionReport]]:
    """Move ``y`` onto every constraint that has a projection, in the order the system lists them."""
    kernels = numeric(system)
    y = y.copy()
    reports: list[ProjectionReport] = []
    for i, (constraint, project) in enumerate(zip(system.constraints, kernels.projections)):
        if project is None:
            continue
        projection = constraint.projection
        assert projection is not None  # the kernel is compiled from the constraint's projection
        before = float(kernels.constraints(y[None, :], p)[0, i])
        where = vector_slice(system, projection.vector)
        start = y[where].copy()
        for _ in range(projection.steps):
            y[where] = project(y[None, :], p)[0]
            after = float(kernels.constraints(y[None, :], p)[0, i])
            if abs(after - constraint.value) <= 1e-3 * constraint.tolerance or not np.isfinite(after):
                break
        change = float(np.max(np.abs(y[where] - start)))
        if change > 0:
            reports.append(ProjectionReport(f"initial_state.{constraint.field}", constraint.formula,
                                            projection.formula, before, after, change))
    return y, reports


def constraint_problems(system: MechanicalSystem, p: np.ndarray, y: np.ndarray) -> list[FieldProblem]:
    """Constraints ``y`` violates beyond their tolerance."""
    kernels = numeric(system)
    with np.errstate(over="ignore", invalid="ignore"):  # huge inputs give inf/nan, reported below
        values = kernels.constraints(y[None, :], p)[0]
        scales = kernels.constraint_scales(y[None, :], p)[0]
    problems = []
    for constraint, value, scale in zip(system.constraints, values, scales):
        deviation = float(value - constraint.value)
        allowed = constraint.tolerance * max(1.0, float(abs(scale)))
        if not np.isfinite(deviation) or abs(deviation) > allowed:
            problems.append(FieldProblem(
                f"initial_state.{constraint.field}",
                f"violates {constraint.formula} (eq. {constraint.equation}): value {value:.12g}, "
                f"off by {deviation:.3g} (tolerance {allowed:.3g})"
                + ("; set project_initial_state to project it" if constraint.projection else "")))
    return problems


#: A check of the field at a state ``(y, p)``: why it is not determined there, or None.
FieldCheck = Callable[[np.ndarray, np.ndarray], "str | None"]


def initial_state_problems(system: MechanicalSystem, parameters: Mapping[str, object],
                           initial_state: Mapping[str, Sequence[float]], project: bool = False,
                           field_check: FieldCheck | None = None) -> list[FieldProblem]:
    """Everything wrong with ``initial_state`` for ``system``: unknown, missing or doubly given
    vectors, and violated constraints (e.g. |γ| ≠ 1 beyond 1e-9) — after projection if ``project``
    (a constraint without a projection, or a projection that cannot restore it, still counts).
    Field paths start with ``initial_state``. The field is checked at the state by its compiled kernel
    (:func:`potential_problems`), or by ``field_check`` when given (a user's Lagrangian system before its
    equations are derived: numbers only, :func:`nonholonomic.lagrangian.checks.field_problem`)."""
    problems = _name_problems(system, initial_state)
    if problems:
        return problems
    p = parameter_vector(system, dict(parameters))
    y = state_vector(system, dict(initial_state), p)
    if project:
        with np.errstate(all="ignore"):
            y, _ = project_initial_state(system, p, y)
    problems = constraint_problems(system, p, y) + surface_problems(system, p, y)
    if field_check is None:
        return problems + potential_problems(system, p, y)
    why = field_check(y, p)
    if why is None:
        return problems
    return problems + [FieldProblem("initial_state.q", f"{'; '.join(system.notes[:2])}: the field is not finite at "
                                                       f"the initial state: {why}")]


def surface_problems(system: MechanicalSystem, p: np.ndarray, y: np.ndarray) -> list[FieldProblem]:
    """A user's surface whose gradient vanishes (or is not finite) at the initial x: the normal
    ∇Φ/|∇Φ| of the equations is undefined there and every step would be nan; refused naming
    ``initial_state.x`` (the density |∇Φ| of the measure is the kernel that says so)."""
    record = registered(system.kind)
    if record is None or not record.surface:  # the state moves on a user's surface Φ(x) = 0: density |∇Φ|
        return []
    with np.errstate(all="ignore"):
        norm = float(numeric(system).density(np.asarray(y, dtype=float)[None, :], p)[0, 0])  # |grad Phi|
    if norm > 0 and np.isfinite(norm):
        return []
    why = (f"grad Phi vanishes here (|grad Phi| = {norm:g}): the normal grad Phi/|grad Phi| is undefined"
           if norm == 0 else f"grad Phi is not finite here (|grad Phi| = {norm:g}): Phi is singular")
    return [FieldProblem("initial_state.x", f"{why}; choose an x on a regular part of the surface, or another Phi")]


def potential_problems(system: MechanicalSystem, p: np.ndarray, y: np.ndarray) -> list[FieldProblem]:
    """A user's potential (``potential == "expression"``) whose gradient, so the field, is not finite at
    the initial state: refused before anything runs, naming ``system.potential.U``; for a user's
    generalized Chaplygin or Lagrangian system, any field not finite there (det M = 0 ...), naming
    ``initial_state.q``."""
    record = registered(system.kind)
    singular = None if record is None else record.singular_field
    user = singular is not None
    if user:
        field = "initial_state.q"
    elif system.potential != "expression":
        return []
    else:
        field = "system.potential.U"
    what = "; ".join(system.notes[:2]) if user else system.potential_formula
    try:
        with np.errstate(all="ignore"):
            f = numeric(system).rhs_single(np.asarray(y, dtype=float), p)
    except Exception as exc:  # noqa: BLE001 - whatever numpy cannot evaluate is the user's U's problem
        return [FieldProblem(field, f"{what}: cannot be evaluated at the initial state ({type(exc).__name__}: {exc})")]
    if np.all(np.isfinite(f)):
        return []
    why = (f"the field is not finite at the initial state: {singular}" if user else
           "its gradient is not finite at the initial state (a singularity there); choose another U or state")
    return [FieldProblem(field, f"{what}: {why}")]


def parameter_warnings(system: MechanicalSystem, parameters: Mapping[str, object]) -> list[str]:
    """Physically unrealizable but mathematically admissible parameters (they still run)."""
    warnings: list[str] = []
    inertia = parameters.get("inertia")
    if inertia is not None:
        moments = cast("Sequence[float]", inertia)  # the group "inertia" is the three principal moments
        i1, i2, i3 = (float(v) for v in moments)
        for a, b, c, names in ((i1, i2, i3, "I1 + I2 >= I3"), (i2, i3, i1, "I2 + I3 >= I1"),
                               (i3, i1, i2, "I3 + I1 >= I2")):
            if a + b < c:
                warnings.append(f"principal moments violate the triangle inequality {names} "
                                f"({a:g} + {b:g} < {c:g}): no rigid body has them; "
                                "the equations were integrated anyway")
    return warnings
