"""First integrals evaluated along a trajectory: initial, final and the largest drift."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nonholonomic.definition import MechanicalSystem
from nonholonomic.integration import Trajectory
from nonholonomic.kernels import numeric

#: The verdict's tolerance on the relative drift never goes below this.
INTEGRAL_TOLERANCE_FLOOR = 1e-10
#: ...and is this many integrator tolerances above a looser integrator tolerance.
INTEGRAL_TOLERANCE_FACTOR = 1e4


def integral_tolerance(integrator_tolerance: float) -> float:
    """Tolerance on an integral's relative drift: ``max(1e-10, 1e4 · integrator tolerance)``."""
    return max(INTEGRAL_TOLERANCE_FLOOR, INTEGRAL_TOLERANCE_FACTOR * integrator_tolerance)


@dataclass(frozen=True)
class IntegralEvidence:
    """One first integral along a trajectory.

    ``max_rel_drift = max_abs_drift / reference`` with ``reference = max(|initial|, scale)``, where
    ``scale`` is the largest natural size of the integral along the trajectory (e.g. ``|M||γ|`` for
    ``c = (M, γ)``), so that an integral whose value is zero still gets a meaningful relative drift.
    """

    name: str
    formula: str
    equation: str
    initial: float
    final: float
    max_abs_drift: float
    max_rel_drift: float
    reference: float
    evaluated_at: int
    tolerance: float
    passed: bool


def integral_evidence(system: MechanicalSystem, parameters: np.ndarray, trajectory: Trajectory,
                      tolerance: float | None = None) -> list[IntegralEvidence]:
    """Evaluate every integral of ``system`` at the samples and at every accepted step.

    Parameters
    ----------
    tolerance : bound on ``max_rel_drift`` for the verdict; by default
        :func:`integral_tolerance` of the trajectory's integrator tolerance.
    """
    if not system.integrals:
        return []
    kernels = numeric(system)
    tol = integral_tolerance(trajectory.tolerance) if tolerance is None else tolerance
    points = np.vstack([trajectory.states, trajectory.step_states])
    values = kernels.integrals(points, parameters)
    initial = values[0]
    final = values[len(trajectory.t) - 1]
    scale = np.max(np.abs(kernels.integral_scales(points, parameters)), axis=0)
    reference = np.maximum(np.abs(initial), scale)
    reference = np.where(reference > 0, reference, 1.0)
    abs_drift = np.max(np.abs(values - initial), axis=0)
    rel_drift = abs_drift / reference
    return [
        IntegralEvidence(
            name=claim.name, formula=claim.formula, equation=claim.equation,
            initial=float(initial[i]), final=float(final[i]),
            max_abs_drift=float(abs_drift[i]), max_rel_drift=float(rel_drift[i]),
            reference=float(reference[i]), evaluated_at=len(points), tolerance=tol,
            passed=bool(np.isfinite(rel_drift[i]) and rel_drift[i] <= tol),
        )
        for i, claim in enumerate(system.integrals)
    ]
