"""One simulation: validate the initial state, integrate, and collect the evidence asked for."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from nonholonomic.definition import MechanicalSystem
from nonholonomic.evidence.integrals import IntegralEvidence, integral_evidence
from nonholonomic.evidence.measure import CheckEvidence, measure_evidence
from nonholonomic.integration import ProgressCallback, Trajectory, integrate
from nonholonomic.isomorphisms import isomorphism_evidence, maps_for
from nonholonomic.kernels import numeric, parameter_vector, state_vector
from nonholonomic.structure import bracket_evidence, euler_angle_evidence, structural_checks

#: Evidence a simulation can compute (``bracket``, ``euler_angles`` and ``isomorphisms`` only for some kinds, see
#: :func:`available_checks`); jobs default to :data:`DEFAULT_CHECKS`.
CHECKS = ("integrals", "measure", "bracket", "euler_angles", "isomorphisms")
DEFAULT_CHECKS = ("integrals", "measure")


def available_checks(system: MechanicalSystem) -> tuple[str, ...]:
    """The checks ``system`` supports."""
    return DEFAULT_CHECKS + structural_checks(system.kind) + (
        ("isomorphisms",) if maps_for(system.kind, system.potential) else ())


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


@dataclass(frozen=True)
class SimulationResult:
    """A trajectory with its evidence. Arrays are at the sample times."""

    system: MechanicalSystem
    parameters: np.ndarray
    trajectory: Trajectory
    derived: dict[str, np.ndarray]
    integrals: list[IntegralEvidence]
    checks: list[CheckEvidence]
    warnings: list[str] = field(default_factory=list)
    projections: list[ProjectionReport] = field(default_factory=list)

    def state(self, name: str) -> np.ndarray:
        """Samples of the state vector ``name`` (shape ``(n, 3)``), or of a derived vector."""
        if name in self.derived:
            return self.derived[name]
        return self.trajectory.states[:, _vector_slice(self.system, name)]


def _vector_slice(system: MechanicalSystem, name: str) -> slice:
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
        before = float(kernels.constraints(y[None, :], p)[0, i])
        where = _vector_slice(system, constraint.projection.vector)  # type: ignore[union-attr]
        new = project(y[None, :], p)[0]
        change = float(np.max(np.abs(new - y[where])))
        y[where] = new
        after = float(kernels.constraints(y[None, :], p)[0, i])
        if change > 0:
            reports.append(ProjectionReport(f"initial_state.{constraint.field}", constraint.formula,
                                            constraint.projection.formula, before, after, change))  # type: ignore[union-attr]
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


def initial_state_problems(system: MechanicalSystem, parameters: Mapping[str, object],
                           initial_state: Mapping[str, Sequence[float]], project: bool = False) -> list[FieldProblem]:
    """Everything wrong with ``initial_state`` for ``system``: unknown, missing or doubly given
    vectors, and violated constraints (e.g. |γ| ≠ 1 beyond 1e-9) — after projection if ``project``
    (a constraint without a projection, or a projection that cannot restore it, still counts).
    Field paths start with ``initial_state``."""
    problems = _name_problems(system, initial_state)
    if problems:
        return problems
    p = parameter_vector(system, dict(parameters))
    y = state_vector(system, dict(initial_state), p)
    if project:
        with np.errstate(all="ignore"):
            y, _ = project_initial_state(system, p, y)
    return constraint_problems(system, p, y)


def parameter_warnings(system: MechanicalSystem, parameters: Mapping[str, object]) -> list[str]:
    """Physically unrealizable but mathematically admissible parameters (they still run)."""
    warnings: list[str] = []
    inertia = parameters.get("inertia")
    if inertia is not None:
        i1, i2, i3 = (float(v) for v in inertia)  # type: ignore[union-attr]
        for a, b, c, names in ((i1, i2, i3, "I1 + I2 >= I3"), (i2, i3, i1, "I2 + I3 >= I1"),
                               (i3, i1, i2, "I3 + I1 >= I2")):
            if a + b < c:
                warnings.append(f"principal moments violate the triangle inequality {names} "
                                f"({a:g} + {b:g} < {c:g}): no rigid body has them; the equations were integrated anyway")
    return warnings


def simulate(
    system: MechanicalSystem,
    parameters: Mapping[str, object],
    initial_state: Mapping[str, Sequence[float]],
    t_final: float,
    samples: int,
    *,
    checks: Sequence[str] = DEFAULT_CHECKS,
    project: bool = False,
    engine: str = "heyoka",
    tolerance: float | None = None,
    progress: ProgressCallback | None = None,
) -> SimulationResult:
    """Integrate ``system`` and compute the requested evidence.

    Parameters
    ----------
    parameters : named parameter groups (``{"inertia": [..], "D": .., "a": [..]}``).
    initial_state : named state vectors, or their alternatives (``omega`` for the ball's ``M``).
    checks : a subset of :func:`available_checks`.
    project : move the initial state onto the constraints first (reported in ``projections``)
        instead of refusing a state off them.

    Raises
    ------
    ValueError
        If the initial state is invalid (see :func:`initial_state_problems`) or a check is unknown.
    """
    unknown = sorted(set(checks) - set(available_checks(system)))
    if unknown:
        raise ValueError(f"checks {unknown} are not available for {system.kind}; available: {available_checks(system)}")
    problems = initial_state_problems(system, parameters, initial_state, project)
    if problems:
        raise ValueError("; ".join(f"{p.field}: {p.reason}" for p in problems))
    p = parameter_vector(system, dict(parameters))
    y0 = state_vector(system, dict(initial_state), p)
    projections: list[ProjectionReport] = []
    if project:
        y0, projections = project_initial_state(system, p, y0)
    trajectory = integrate(system, p, y0, t_final, samples, engine=engine, tolerance=tolerance, progress=progress)
    kernels = numeric(system)
    derived = {name: fn(trajectory.states, p) for name, fn in kernels.derived.items()}
    integrals = integral_evidence(system, p, trajectory) if "integrals" in checks else []
    evidence = measure_evidence(system, p, trajectory.states) if "measure" in checks else []
    if "bracket" in checks:
        evidence += bracket_evidence(system, p, trajectory.states)
    if "euler_angles" in checks:
        evidence += euler_angle_evidence(system, p, trajectory.states)
    if "isomorphisms" in checks:
        evidence += isomorphism_evidence(system, p, trajectory.t, trajectory.tau, trajectory.states)
    return SimulationResult(system, p, trajectory, derived, integrals, evidence,
                            parameter_warnings(system, parameters), projections)
