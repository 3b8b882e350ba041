"""One simulation: validate the initial state, integrate, and collect the evidence asked for."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from nonholonomic.analysis.options import PeriodicOrbitOptions, SectionOptions, SpectrumOptions
from nonholonomic.definition import MechanicalSystem
from nonholonomic.evidence.integrals import IntegralEvidence, integral_evidence
from nonholonomic.evidence.measure import CheckEvidence, measure_evidence
from nonholonomic.evidence.time_change import time_change_evidence
from nonholonomic.hamiltonization.structure import bracket_evidence, euler_angle_evidence, structural_checks
from nonholonomic.initial_state import (
    ProjectionReport,
    initial_state_problems,
    parameter_warnings,
    project_initial_state,
    vector_slice,
)
from nonholonomic.isomorphisms import isomorphism_evidence, maps_for
from nonholonomic.numerics.integration import ProgressCallback, Trajectory, integrate
from nonholonomic.numerics.kernels import numeric, parameter_vector, state_vector

if TYPE_CHECKING:
    from nonholonomic.analysis.lyapunov import Spectrum
    from nonholonomic.analysis.periodic_orbit import PeriodicOrbit
    from nonholonomic.analysis.periodic_orbit.branch import OrbitBranch
    from nonholonomic.analysis.periodic_orbit.continuation import Branch
    from nonholonomic.analysis.poincare import Section

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
    """A trajectory with its evidence. Arrays are at the sample times; ``poincare`` and ``lyapunov``
    are set when they were asked for."""

    system: MechanicalSystem
    parameters: np.ndarray
    trajectory: Trajectory
    derived: dict[str, np.ndarray]
    integrals: list[IntegralEvidence]
    checks: list[CheckEvidence]
    warnings: list[str] = field(default_factory=list)
    projections: list[ProjectionReport] = field(default_factory=list)
    poincare: Section | None = None
    lyapunov: Spectrum | None = None
    periodic_orbit: PeriodicOrbit | None = None
    continuation: Branch | None = None
    branch: OrbitBranch | None = None

    def state(self, name: str) -> np.ndarray:
        """Samples of the state vector ``name`` (shape ``(n, 3)``), or of a derived vector."""
        if name in self.derived:
            return self.derived[name]
        return self.trajectory.states[:, vector_slice(self.system, name)]


def phase(progress: ProgressCallback | None, start: float, end: float) -> ProgressCallback | None:
    """``progress`` for one part of a job that covers the fraction ``[start, end]`` of the whole."""
    if progress is None:
        return None
    return lambda fraction: progress(start + (end - start) * fraction)


def evidence(system: MechanicalSystem, p: np.ndarray, trajectory: Trajectory, checks: Sequence[str],
             integrals: list[IntegralEvidence] | None = None,
             ) -> tuple[dict[str, np.ndarray], list[IntegralEvidence], list[CheckEvidence]]:
    """The derived vectors at the samples, the integrals' drift and the checks in ``checks`` for one
    trajectory (``integrals``: the drift already computed, e.g. for a batch of members at once)."""
    kernels = numeric(system)
    derived = {name: fn(trajectory.states, p) for name, fn in kernels.derived.items()}
    if integrals is None:
        integrals = integral_evidence(system, p, trajectory) if "integrals" in checks else []
    found = measure_evidence(system, p, trajectory.states) if "measure" in checks else []
    if "bracket" in checks:
        found += bracket_evidence(system, p, trajectory.states)
    if "euler_angles" in checks:
        found += euler_angle_evidence(system, p, trajectory.states)
    if "isomorphisms" in checks:
        found += isomorphism_evidence(system, p, trajectory.t, trajectory.tau, trajectory.states)
    return derived, integrals, found


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
    poincare: SectionOptions | None = None,
    lyapunov: SpectrumOptions | None = None,
    periodic_orbit: PeriodicOrbitOptions | None = None,
) -> SimulationResult:
    """Integrate ``system`` and compute the requested evidence, section and spectrum.

    Parameters
    ----------
    parameters : named parameter groups (``{"inertia": [..], "D": .., "a": [..]}``).
    initial_state : named state vectors, or their alternatives (``omega`` for the ball's ``M``).
    checks : a subset of :func:`available_checks`.
    project : move the initial state onto the constraints first (reported in ``projections``)
        instead of refusing a state off them.
    poincare : a Poincaré section of the same orbit over [0, t_final] (heyoka events).
    lyapunov : the Lyapunov spectrum of the orbit (heyoka variational equations, QR).
    periodic_orbit : a periodic orbit of a section map seeded by the initial state, and its continuation.

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
    parts = 1 + (poincare is not None) + (lyapunov is not None) + (periodic_orbit is not None)
    trajectory = integrate(system, p, y0, t_final, samples, engine=engine, tolerance=tolerance,
                           progress=phase(progress, 0.0, 1.0 / parts))
    section = spectrum = orbit = branch = orbit_branch = None
    done = 1
    if poincare is not None:
        section = poincare.run(system, p, y0, t_final, tolerance=tolerance,
                               progress=phase(progress, done / parts, (done + 1) / parts))
        done += 1
    if lyapunov is not None:
        spectrum = lyapunov.run(system, p, y0, t_final, tolerance=tolerance,
                                progress=phase(progress, done / parts, (done + 1) / parts))
        done += 1
    if periodic_orbit is not None:
        orbit, branch, orbit_branch = periodic_orbit.run(system, p, y0, t_final, tolerance=tolerance,
                                           progress=phase(progress, done / parts, 1.0))
    derived, integrals, found = evidence(system, p, trajectory, checks)
    time_checks, time_warnings = time_change_evidence(system, trajectory)
    return SimulationResult(system, p, trajectory, derived, integrals, found + time_checks,
                            parameter_warnings(system, parameters) + time_warnings, projections, section, spectrum,
                            orbit, branch, orbit_branch)
