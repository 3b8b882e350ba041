"""A job's ``periodic_orbit`` block: the request, its checks against the system, and the result as JSON."""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from nonholonomic.analysis.options import PeriodicOrbitOptions
from nonholonomic.analysis.periodic_orbit import MAX_PERIOD, PeriodicOrbitError, check_request
from nonholonomic.definition import MechanicalSystem
from nonholonomic.initial_state import FieldProblem, vector_slice
from nonholonomic.numerics.kernels import parameter_vector
from schemas.branches import OrbitBranchRequest, OrbitBranchResult
from schemas.sweeps import sweep_target, swept
from schemas.systems import FiniteFloat

#: Most parameter values one continuation visits (each one a Newton search).
MAX_SWEEP_VALUES = 200


class OrbitSweep(BaseModel):
    """Continue the orbit through the values of one parameter, in the order given."""

    model_config = ConfigDict(extra="forbid")

    parameter: str = Field(description="parameter path: 'D', 'inertia[1]', 'potential.a[2]'")
    values: list[FiniteFloat] = Field(min_length=1, max_length=MAX_SWEEP_VALUES,
                                      description="the parameter's values, visited in order from the job's own; "
                                                  "small steps follow a branch")


class PeriodicOrbitRequest(BaseModel):
    """Find, from the job's initial state as a seed, a fixed point of the ``period``-th return map to the section
    ``surface = value`` on the seed's level (Newton with the monodromy; Levenberg-Marquardt if Newton wanders)."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [
        {"surface": "gamma3", "value": 0.0, "direction": "increasing", "period": 1,
         "coordinates": ["gamma1", "M3"]}]})

    surface: str = Field(max_length=2000, description="the section's expression in the state (as for poincare)")
    value: FiniteFloat = Field(0.0, description="the section: surface = value")
    direction: Literal["increasing", "decreasing"] = Field("increasing", description="the crossings that count")
    period: int = Field(1, ge=1, le=MAX_PERIOD, description="k: a fixed point of the k-th return map; the seed "
                                                            "must cross the section k + 1 times before t_final")
    coordinates: list[str] | None = Field(None, min_length=2, max_length=2,
                                          description="two components to report as the orbit's point on the section")
    level: list[str] | None = Field(None, max_length=16,
                                    description="the integrals held at the seed's values (default: the kind's "
                                                "level, e.g. energy and area for the ball; every integral of a "
                                                "user's system)")
    sweep: OrbitSweep | None = Field(None, description="continue the orbit in a parameter, flagging folds and "
                                                       "period doublings")
    branch: OrbitBranchRequest | None = Field(None, description="follow the orbit as a branch in the energy or a "
                                                                "parameter by pseudo-arclength continuation, "
                                                                "through folds, its bifurcations located and the "
                                                                "period-2k branch followed at a period doubling")

    def problems(self, system: MechanicalSystem, parameters: dict[str, Any], t_final: float,
                 tolerance: float | None, prefix: str = "periodic_orbit") -> list[FieldProblem]:
        """The fields checked against the system (the surface by the safe parser, the level's names, the sweep)."""
        try:
            check_request(system, self.surface, self.value, self.direction, self.period, self.level, t_final,
                          tolerance, self.coordinates)
        except PeriodicOrbitError as exc:
            return [FieldProblem(f"{prefix}.{exc.field}", exc.reason)]
        found = [] if self.branch is None else self.branch.problems(system, parameters, f"{prefix}.branch")
        if self.sweep is None:
            return found
        try:
            group, index = sweep_target(system, self.sweep.parameter)
        except ValueError as exc:
            return found + [FieldProblem(f"{prefix}.sweep.parameter", str(exc))]
        for i, value in enumerate(self.sweep.values):
            try:
                parameter_vector(system, swept(parameters, group, index, value))
            except ValueError as exc:
                found.append(FieldProblem(f"{prefix}.sweep.values[{i}]", str(exc)))
        return found

    def options(self, system: MechanicalSystem, parameters: dict[str, Any]) -> PeriodicOrbitOptions:
        vectors: tuple[np.ndarray, ...] = ()
        if self.sweep is not None:
            group, index = sweep_target(system, self.sweep.parameter)
            vectors = tuple(parameter_vector(system, swept(parameters, group, index, v)) for v in self.sweep.values)
        return PeriodicOrbitOptions(
            self.surface, self.value, self.direction, self.period,
            None if self.coordinates is None else (self.coordinates[0], self.coordinates[1]),
            None if self.level is None else tuple(self.level),
            None if self.sweep is None else self.sweep.parameter,
            () if self.sweep is None else tuple(self.sweep.values), vectors,
            None if self.branch is None else self.branch.options(system, parameters))


class Multiplier(BaseModel):
    re: float
    im: float
    modulus: float


class OrbitCheckItem(BaseModel):
    name: str = Field(description="trivial_multipliers, multiplier_product, crossings, closes_independently")
    passed: bool | None = Field(description="null: cannot be decided (no invariant measure claimed)")
    value: float | None
    expected: float | None
    tolerance: float | None
    detail: str


class NewtonInfo(BaseModel):
    method: str = Field(description="'newton', or 'newton, then levenberg-marquardt' when Newton wandered")
    wandered: str | None = Field(description="why Newton was left for Levenberg-Marquardt")
    residuals: list[float | None] = Field(description="the scaled closing residual at each evaluation")
    evaluations: int = Field(description="integrations of the state with its monodromy")
    taylor_steps: int
    singular_ratio: float | None = Field(description="smallest / largest singular value of the closing equations' "
                                                     "Jacobian at the solution (0: a family of orbits)")
    family_dimension: int
    wall_time_s: float = Field(description="the search's time, without the seed's crossings and the checks")


class ContinuationPoint(BaseModel):
    value: float
    status: Literal["found", "degenerate", "not_found"]
    period_t: float | None
    initial_state: dict[str, list[float]]
    section_multipliers: list[Multiplier]
    trace: float | None
    stability: str | None
    residual: float | None
    checks_passed: bool | None = Field(description="every decided check passed")
    reason: str


class BranchEventItem(BaseModel):
    kind: Literal["fold", "period_doubling", "lost"]
    between: list[float | None]
    detail: str


class ContinuationResult(BaseModel):
    parameter: str
    points: list[ContinuationPoint]
    events: list[BranchEventItem]
    skipped: list[float] = Field(description="values not visited after the branch was lost")


class PeriodicOrbitResult(BaseModel):
    """A periodic orbit of the section map (a job's ``periodic_orbit``), its multipliers and its checks."""

    status: Literal["found", "degenerate", "not_found"] = Field(
        description="found: an isolated orbit, checked; degenerate: it closes on a family of periodic orbits "
                    "(a resonant torus of an integrable system), reason says which; not_found: reason says why")
    reason: str
    surface: str
    value: float
    direction: str
    period: int
    level: dict[str, float] = Field(description="the integrals held, at the seed's values")
    initial_state: dict[str, list[float]] = Field(description="x0 on the section (the best point reached when "
                                                              "not_found)")
    period_t: float | None = Field(description="T [s]: x(T) = x0")
    period_tau: float | None = Field(description="the reduced time over one period (null for systems without one)")
    coordinate_names: list[str]
    coordinates: list[float] = Field(description="x0's two coordinates on the section")
    crossing_times: list[float] = Field(description="the k crossings in (0, T] [s]")
    multipliers: list[Multiplier] = Field(description="eigenvalues of the full flow's monodromy Phi(T)")
    trivial_count: int = Field(description="how many of them are 1: the flow's direction and one per independent "
                                           "integral or constraint")
    section_multipliers: list[Multiplier] = Field(description="the others: the k-th return map's at x0")
    trace: float | None = Field(description="sum of the section multipliers (|trace| < 2: elliptic)")
    stability: str | None = Field(description="elliptic, hyperbolic, parabolic, attracting or unstable")
    residual: float | None = Field(description="max|x(T) - x0| / max(1, max|x0|), heyoka")
    residual_independent: float | None = Field(description="the same by scipy's DOP853 (an independent integrator)")
    checks: list[OrbitCheckItem]
    newton: NewtonInfo
    wall_time_s: float
    warnings: list[str]
    units: dict[str, str]
    continuation: ContinuationResult | None = None
    branch: OrbitBranchResult | None = Field(None, description="the branch by pseudo-arclength, when asked for")


def _finite(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(v) else float(v)


def _multipliers(mu: np.ndarray) -> list[dict[str, float]]:
    return [{"re": float(m.real), "im": float(m.imag), "modulus": float(abs(m))} for m in mu]


def named_state(system: MechanicalSystem, x: np.ndarray) -> dict[str, list[float]]:
    """A state vector by the system's vector names (``{"M": [..], "gamma": [..]}``)."""
    return {v.name: [float(c) for c in x[vector_slice(system, v.name)]] for v in system.state}


def orbit_to_json(system: MechanicalSystem, orbit: Any) -> dict[str, Any]:
    """A :class:`~nonholonomic.analysis.periodic_orbit.PeriodicOrbit` as JSON (NaN as null)."""
    reduced = system.reduced_time
    return {
        "status": orbit.status, "reason": orbit.reason, "surface": orbit.surface, "value": orbit.value,
        "direction": orbit.direction, "period": orbit.period, "level": dict(orbit.level),
        "initial_state": named_state(system, orbit.initial_state), "period_t": _finite(orbit.period_t),
        "period_tau": _finite(orbit.period_tau), "coordinate_names": list(orbit.coordinate_names),
        "coordinates": list(orbit.coordinates), "crossing_times": list(orbit.crossing_times),
        "multipliers": _multipliers(orbit.multipliers), "trivial_count": orbit.trivial_count,
        "section_multipliers": _multipliers(orbit.section_multipliers), "trace": _finite(orbit.trace),
        "stability": orbit.stability, "residual": _finite(orbit.residual),
        "residual_independent": _finite(orbit.residual_independent),
        "checks": [{"name": c.name, "passed": c.passed, "value": _finite(c.value), "expected": _finite(c.expected),
                    "tolerance": _finite(c.tolerance), "detail": c.detail} for c in orbit.checks],
        "newton": {"method": orbit.method, "wandered": orbit.wandered,
                   "residuals": [_finite(r) for r in orbit.iterations], "evaluations": orbit.evaluations,
                   "taylor_steps": orbit.steps, "singular_ratio": _finite(orbit.singular_ratio),
                   "family_dimension": orbit.family_dimension, "wall_time_s": orbit.search_time_s},
        "wall_time_s": orbit.wall_time_s, "warnings": list(orbit.warnings),
        "units": {"period_t": "s", "crossing_times": "s", **({"period_tau": reduced.unit} if reduced else {})},
        "continuation": None, "branch": None,
    }


def branch_to_json(system: MechanicalSystem, branch: Any) -> dict[str, Any]:
    """A :class:`~nonholonomic.analysis.periodic_orbit.continuation.Branch` as JSON."""
    points = []
    for value, orbit in zip(branch.values, branch.orbits):
        decided = [c.passed for c in orbit.checks if c.passed is not None]
        points.append({"value": float(value), "status": orbit.status, "period_t": _finite(orbit.period_t),
                       "initial_state": named_state(system, orbit.initial_state),
                       "section_multipliers": _multipliers(orbit.section_multipliers), "trace": _finite(orbit.trace),
                       "stability": orbit.stability, "residual": _finite(orbit.residual),
                       "checks_passed": all(decided) if decided else None, "reason": orbit.reason})
    return {"parameter": branch.parameter, "points": points,
            "events": [{"kind": e.kind, "between": [_finite(b) for b in e.between], "detail": e.detail}
                       for e in branch.events],
            "skipped": [float(v) for v in branch.skipped]}
