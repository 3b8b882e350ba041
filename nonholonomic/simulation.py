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
from nonholonomic.initial_state import (
    FieldProblem,
    ProjectionReport,
    initial_state_problems,
    parameter_warnings,
    project_initial_state,
    vector_slice,
)
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
        return self.trajectory.states[:, vector_slice(self.system, name)]


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
