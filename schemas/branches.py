"""A periodic orbit's ``branch``: the request (pseudo-arclength continuation in the energy or a parameter) and
the result as JSON (points, bifurcations, the branches switched onto)."""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from nonholonomic.analysis.periodic_orbit.bifurcations import LOCATE_BRACKET, LOCATE_TOLERANCE
from nonholonomic.analysis.periodic_orbit.branch import MAX_BRANCH_POINTS, BranchOptions, BranchPoint, OrbitBranch
from nonholonomic.definition import MechanicalSystem
from nonholonomic.initial_state import FieldProblem
from nonholonomic.numerics.kernels import parameter_vector
from schemas.sweeps import sweep_target, swept
from schemas.systems import FiniteFloat


class OrbitBranchRequest(BaseModel):
    """Follow the orbit as a branch by pseudo-arclength continuation, through folds, locating its bifurcations and
    (``switch``) following the period-2k branch born at each period doubling."""

    model_config = ConfigDict(extra="forbid", validate_by_name=True, validate_by_alias=True,
                              serialize_by_alias=True,
                              json_schema_extra={"examples": [{"in": "energy", "to": 4.0},
                                                              {"in": "potential.a[2]", "to": 1.2}]})

    continued: str = Field(alias="in", max_length=100,
                           description="'energy' (the family at fixed parameters: the level's other integrals "
                                       "held at the seed's values), another of the system's integrals by name "
                                       "('area'), or a parameter path as in sweeps ('D', 'potential.a[2]': the "
                                       "whole level held)")
    to: FiniteFloat = Field(description="the branch ends where the continued value reaches this (or after "
                                        "max_points, or when it returns to the start's value after a fold)")
    max_points: int = Field(100, ge=2, le=MAX_BRANCH_POINTS, description="most points of the branch")
    step: float = Field(0.05, gt=0, le=1, description="first step in the arclength of (x0, T, value)")
    min_step: float = Field(1e-5, gt=0, le=1, description="below this the branch is lost")
    max_step: float = Field(0.1, gt=0, le=1, description="the step grows after easy corrections up to this")
    switch: bool = Field(True, description="at each period doubling, follow the period-2k branch born there")
    switch_points: int = Field(40, ge=2, le=MAX_BRANCH_POINTS, description="most points of a switched branch")
    check_every: int = Field(10, ge=1, le=MAX_BRANCH_POINTS,
                             description="scipy's DOP853 re-checks the closing at every check_every-th point, the "
                                         "ends and each bifurcation")
    max_multiplier: float = Field(1e3, gt=1, le=1e12,
                                  description="the branch stops where a section multiplier's modulus exceeds this "
                                              "(the closing equations lose digits; near a homoclinic orbit T grows "
                                              "without bound)")

    def problems(self, system: MechanicalSystem, parameters: dict[str, Any], prefix: str) -> list[FieldProblem]:
        """The fields checked against the system: the continued name, the value ``to``, the steps."""
        found: list[FieldProblem] = []
        if not self.min_step <= self.step <= self.max_step:
            found.append(FieldProblem(f"{prefix}.step", f"needs min_step <= step <= max_step, got {self.min_step:g}, "
                                                        f"{self.step:g}, {self.max_step:g}"))
        if self.continued in [i.name for i in system.integrals]:
            return found
        try:
            self.parameter_index(system)
        except ValueError as exc:
            integrals = ", ".join(i.name for i in system.integrals) or "none"
            found.append(FieldProblem(f"{prefix}.in", f"{exc}; or one of its integrals: {integrals}"))
            return found
        group, index = sweep_target(system, self.continued)
        try:
            start = parameter_vector(system, parameters)[self.parameter_index(system)]
            parameter_vector(system, swept(parameters, group, index, self.to))
        except ValueError as exc:
            found.append(FieldProblem(f"{prefix}.to", str(exc)))
            return found
        if float(start) == self.to:
            found.append(FieldProblem(f"{prefix}.to", f"is the job's own {self.continued} ({self.to:g}): a branch "
                                                      "goes from it to another value"))
        return found

    def parameter_index(self, system: MechanicalSystem) -> int:
        """The index in the parameter vector (``system.parameter_symbols``' order) of the parameter the path names.

        Raises
        ------
        ValueError
            An unknown path.
        """
        group, index = sweep_target(system, self.continued)
        return list(system.parameter_symbols).index(group.symbols[0 if index is None else index])

    def options(self, system: MechanicalSystem, parameters: dict[str, Any]) -> BranchOptions:
        integral = self.continued in [i.name for i in system.integrals]
        index = None if integral else self.parameter_index(system)
        return BranchOptions(self.continued, float(self.to), index, self.max_points, self.step, self.min_step,
                             self.max_step, self.switch, self.switch_points, self.check_every,
                             self.max_multiplier)


class BranchPointItem(BaseModel):
    value: float = Field(description="the continued value: the energy (another integral) or the parameter")
    arclength: float = Field(description="along the branch from its start, in (x0, T, value) scaled")
    period_t: float = Field(description="T [s]")
    period_tau: float | None = Field(description="the reduced time over one period (null without one)")
    coordinates: list[float] = Field(description="x0's two coordinates on the section")
    initial_state: dict[str, list[float]]
    trace: float | None = Field(description="trace of the section map (tr Phi - trivial count for a 2-d map)")
    multipliers: list[dict[str, float]] = Field(description="the section map's multipliers (re, im, modulus)")
    stability: str | None
    residual: float | None = Field(description="scaled closing residual, heyoka")
    residual_independent: float | None = Field(description="the same by scipy's DOP853 (null where not run)")
    tangent_value: float = Field(description="the tangent's component along the value (0 at a fold)")
    checks: list[dict[str, Any]] = Field(description="trivial_multipliers, multiplier_product, closes_independently")
    checks_passed: bool | None


class BifurcationItem(BaseModel):
    kind: Literal["fold", "tangent", "period_doubling", "resonance_1:3", "resonance_1:4", "neimark_sacker",
                  "krein_collision"]
    value: float
    between: list[int] = Field(description="the indices of the points it lies between")
    located: bool = Field(description="the test function solved to the tolerance (else the best trial point)")
    test_function: float | None
    tolerance: float = Field(description="|test function| reached, or the bracket's size as a fraction of the step")
    bracket: float = Field(description="the last bracket of the zero in arclength")
    trials: int
    detail: str
    point: BranchPointItem
    switched: int | None = Field(description="index in switched of the branch followed from here")


class OrbitBranchResult(BaseModel):
    continued: str = Field(alias="in")
    to: float
    period: int
    status: Literal["reached", "bound", "max_points", "lost", "degenerate", "unstable_limit"]
    reason: str
    origin: str | None = Field(description="for a switched branch: the bifurcation it starts from")
    coordinate_names: list[str]
    points: list[BranchPointItem]
    bifurcations: list[BifurcationItem]
    switched: list[OrbitBranchResult]
    evaluations: int = Field(description="integrations of the state with its monodromy")
    taylor_steps: int
    wall_time_s: float
    warnings: list[str]
    units: dict[str, str]


def _f(v: float | None) -> float | None:
    return None if v is None or not np.isfinite(v) else float(v)


def point_to_json(system: MechanicalSystem, bp: BranchPoint) -> dict[str, Any]:
    """One point of a branch as JSON."""
    from schemas.periodic_orbits import named_state

    return {"value": bp.value, "arclength": bp.arclength, "period_t": bp.period_t, "period_tau": _f(bp.period_tau),
            "coordinates": list(bp.coordinates), "initial_state": named_state(system, bp.initial_state),
            "trace": _f(bp.trace),
            "multipliers": [{"re": float(m.real), "im": float(m.imag), "modulus": float(abs(m))}
                            for m in bp.multipliers],
            "stability": bp.stability, "residual": _f(bp.residual),
            "residual_independent": _f(bp.residual_independent), "tangent_value": bp.tangent_value,
            "checks": [{"name": c.name, "passed": c.passed, "value": _f(c.value), "expected": _f(c.expected),
                        "tolerance": _f(c.tolerance)} for c in bp.checks],
            "checks_passed": bp.checks_passed}


def orbit_branch_to_json(system: MechanicalSystem, branch: OrbitBranch) -> dict[str, Any]:
    """An :class:`~nonholonomic.analysis.periodic_orbit.branch.OrbitBranch` as JSON."""
    reduced = system.reduced_time
    value_unit: str | None = None
    if branch.continued == "energy":
        value_unit = "J"
    elif branch.continued not in [i.name for i in system.integrals]:
        group, _ = sweep_target(system, branch.continued)
        value_unit = group.unit
    return {
        "in": branch.continued, "to": branch.to, "period": branch.period, "status": branch.status,
        "reason": branch.reason, "origin": branch.origin, "coordinate_names": list(branch.coordinate_names),
        "points": [point_to_json(system, bp) for bp in branch.points],
        "bifurcations": [{"kind": b.kind, "value": b.value, "between": [b.index, b.index + 1], "located": b.located,
                          "test_function": _f(b.test_value),
                          "tolerance": LOCATE_BRACKET if b.kind == "krein_collision" else LOCATE_TOLERANCE,
                          "bracket": b.bracket, "trials": b.trials, "detail": b.detail,
                          "point": point_to_json(system, b.point), "switched": b.switched}
                         for b in branch.bifurcations],
        "switched": [orbit_branch_to_json(system, s) for s in branch.switched],
        "evaluations": branch.evaluations, "taylor_steps": branch.taylor_steps, "wall_time_s": branch.wall_time_s,
        "warnings": list(branch.warnings),
        "units": {**({"value": value_unit} if value_unit else {}), "period_t": "s",
                  "arclength": "1 (x0, T and value, scaled)", **({"period_tau": reduced.unit} if reduced else {})},
    }
