"""One simulation: validate the initial state, integrate, and collect the evidence asked for."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from nonholonomic.definition import MechanicalSystem
from nonholonomic.evidence.integrals import IntegralEvidence, integral_evidence
from nonholonomic.evidence.measure import CheckEvidence, measure_evidence
from nonholonomic.integration import ProgressCallback, Trajectory, integrate
from nonholonomic.kernels import numeric, parameter_vector, state_vector

#: Evidence a simulation can compute.
CHECKS = ("integrals", "measure")


@dataclass(frozen=True)
class FieldProblem:
    """A violation in the input, with the dotted path of the offending field."""

    field: str
    reason: str


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

    def state(self, name: str) -> np.ndarray:
        """Samples of the state vector ``name`` (shape ``(n, 3)``), or of a derived vector."""
        if name in self.derived:
            return self.derived[name]
        offset = 0
        for vec in self.system.state:
            if vec.name == name:
                return self.trajectory.states[:, offset:offset + len(vec.symbols)]
            offset += len(vec.symbols)
        raise KeyError(name)


def initial_state_problems(system: MechanicalSystem, parameters: Mapping[str, object],
                           initial_state: Mapping[str, Sequence[float]]) -> list[FieldProblem]:
    """Everything wrong with ``initial_state`` for ``system``: unknown, missing or doubly given
    vectors, and violated constraints (e.g. |γ| ≠ 1 beyond 1e-9). Field paths start with
    ``initial_state``."""
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
    if problems:
        return problems
    p = parameter_vector(system, dict(parameters))  # type: ignore[arg-type]
    y = state_vector(system, dict(initial_state), p)
    values = numeric(system).constraints(y[None, :], p)[0]
    for constraint, value in zip(system.constraints, values):
        deviation = float(value - constraint.value)
        if not np.isfinite(deviation) or abs(deviation) > constraint.tolerance:
            problems.append(FieldProblem(
                f"initial_state.{constraint.field}",
                f"violates {constraint.formula} (eq. {constraint.equation}): value {value:.12g}, "
                f"off by {deviation:.3g} (tolerance {constraint.tolerance:g})"))
    return problems


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
    checks: Sequence[str] = CHECKS,
    engine: str = "heyoka",
    tolerance: float | None = None,
    progress: ProgressCallback | None = None,
) -> SimulationResult:
    """Integrate ``system`` and compute the requested evidence.

    Parameters
    ----------
    parameters : named parameter groups (``{"inertia": [..], "D": .., "a": [..]}``).
    initial_state : named state vectors, or their alternatives (``omega`` for the ball's ``M``).
    checks : a subset of :data:`CHECKS`.

    Raises
    ------
    ValueError
        If the initial state is invalid (see :func:`initial_state_problems`) or a check is unknown.
    """
    unknown = sorted(set(checks) - set(CHECKS))
    if unknown:
        raise ValueError(f"unknown checks {unknown}; known: {CHECKS}")
    problems = initial_state_problems(system, parameters, initial_state)
    if problems:
        raise ValueError("; ".join(f"{p.field}: {p.reason}" for p in problems))
    p = parameter_vector(system, dict(parameters))  # type: ignore[arg-type]
    y0 = state_vector(system, dict(initial_state), p)
    trajectory = integrate(system, p, y0, t_final, samples, engine=engine, tolerance=tolerance, progress=progress)
    kernels = numeric(system)
    derived = {name: fn(trajectory.states, p) for name, fn in kernels.derived.items()}
    integrals = integral_evidence(system, p, trajectory) if "integrals" in checks else []
    evidence = measure_evidence(system, p, trajectory.states) if "measure" in checks else []
    return SimulationResult(system, p, trajectory, derived, integrals, evidence,
                            parameter_warnings(system, parameters))
