"""The result of a simulation job, as JSON: trajectory, integrals, checks, integration facts."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import asdict
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from nonholonomic.analysis.ensemble import MemberResult
from nonholonomic.definition import MechanicalSystem
from nonholonomic.evidence.time_change import domain_json
from nonholonomic.simulation import SimulationResult
from schemas.analysis import SectionResult, SpectrumResult, section_to_json, spectrum_to_json
from schemas.branches import orbit_branch_to_json
from schemas.periodic_orbits import PeriodicOrbitResult, branch_to_json, orbit_to_json


class IntegralItem(BaseModel):
    """A first integral along the trajectory (samples and accepted steps)."""

    name: str
    formula: str
    equation: str = Field(description="paper equation label")
    initial: float
    final: float
    max_abs_drift: float
    max_rel_drift: float = Field(description="max_abs_drift / reference")
    reference: float = Field(description="max(|initial|, largest natural scale of the integral along the trajectory)")
    evaluated_at: int = Field(description="number of states evaluated (samples + accepted steps)")
    tolerance: float = Field(description="bound on max_rel_drift for the verdict")
    passed: bool


class CheckItem(BaseModel):
    """A machine check (e.g. the invariant measure), with method, residual, tolerance and verdict."""

    name: str
    quantity: str
    formula: str
    equation: str
    method: str = Field(description="symbolic | pointwise")
    residual: float | None
    tolerance: float | None
    passed: bool | None = Field(description="null when the check could not decide")
    detail: str


class IntegrationInfo(BaseModel):
    engine: str
    tolerance: float
    steps: int
    wall_time_s: float = Field(description="integration only (compilation is once per worker process)")
    versions: dict[str, str] = Field(description="heyoka, sympy, numpy and scipy that computed this result")
    project: dict[str, str | None] | None = Field(
        None, description="the service that computed it: name, version, and the git commit when there is one")


class TauDomain(BaseModel):
    method: str = Field(description="how tau was integrated (by quadrature along the dense output)")
    zeros: list[float] = Field(description="the first 50 times where N vanishes without changing sign")
    zero_count: int
    sign_changes: list[float] = Field(description="the first 50 times where N changes sign")
    sign_change_count: int
    not_real_from: float | None = Field(description="the time from which N is not real (tau is null after it)")
    nonzero_until: float | None = Field(description="the first time N vanishes, changes sign or stops being real: "
                                                    "the time change is a Hamiltonization on [0, nonzero_until)")


class TimeInfo(BaseModel):
    t: str = "physical time t [s]"
    tau: str | None = Field(description="reduced time of the Hamiltonization, with its formula and equation "
                                        "(null for systems without one)")
    tau_domain: TauDomain | None = Field(None, description="where N vanishes, changes sign or is not real, when "
                                                           "N is not known to be analytic and positive (tau is "
                                                           "then integrated by quadrature, cut at N's kinks)")


class SystemInfo(BaseModel):
    kind: str
    title: str
    equation: str
    potential: str
    potential_formula: str
    parameters: dict[str, Any]
    units: dict[str, str]
    components: dict[str, list[str]] | None = Field(
        None, description="the name of each component of every state and derived vector, as the exports' columns "
                          "and NetCDF variables call it: M1 ..., a system's own coordinates (x, theta, x_dot ...)")
    structure: dict[str, Any] | None = Field(
        None, description="for a system written by the user (kind lagrangian): what the structure search found, "
                          "each with its verdict: 'measure' (found / none / undecided, the density and why), "
                          "'integrals' (linear and quadratic in the velocities, in an ansatz), 'hamiltonization'")


class Trajectory(BaseModel):
    """Samples: ``t``, ``tau`` and one list of 3-vectors per state or derived vector."""

    model_config = ConfigDict(extra="allow")
    t: list[float]
    tau: list[float | None] | None = Field(description="tau at each sample; null where N is not real (see "
                                                       "time.tau_domain)")


class ProjectionItem(BaseModel):
    """What projecting the initial state onto one constraint changed (``project_initial_state``)."""

    field: str
    constraint: str
    projection: str
    value_before: float
    value_after: float
    change: float = Field(description="max |component change| of the projected vector")


class ClaimSymbolic(BaseModel):
    identically_conserved: bool | None = Field(
        description="dI/dt = sum dI/dx_i f_i is identically 0 (True), is not (False: it may still vanish on the "
                    "constraints' level set), or undecided (None: a work limit, named in the detail)")
    detail: str


class ClaimItem(BaseModel):
    """A claimed integral along the trajectory: ``max_rel_drift = max |I - I(0)| / max(|I(0)|, max |I|)``."""

    name: str
    expression: str
    initial: float | None = Field(description="I at the first sample (null: not finite)")
    final: float | None = Field(description="I at the last sample (null: not finite)")
    max_rel_drift: float | None = Field(description="null when I is not finite somewhere along the orbit")
    tolerance: float
    passed: bool = Field(description="the drift is within the tolerance of the system's own integrals")
    symbolic: ClaimSymbolic
    not_finite_points: int = Field(0, description="samples and steps where I is not finite (a power of a negative "
                                                  "number, a value past the floating-point range ...)")


class SimulationResultModel(BaseModel):
    system: SystemInfo
    initial_state: dict[str, list[float]] = Field(description="the state integrated from (after any projection)")
    projections: list[ProjectionItem]
    final_state: dict[str, list[float]]
    t_final: float
    tau_final: float | None
    time: TimeInfo
    trajectory: Trajectory | None = Field(None, description="the samples; left out of the summary view "
                                                            "(GET /v1/jobs/{id}?trajectory=false)")
    trajectory_location: str | None = Field(None, description="where the samples are, in the summary view")
    integrals: list[IntegralItem]
    checks: list[CheckItem]
    integration: IntegrationInfo
    warnings: list[str]
    poincare: SectionResult | None = Field(None, description="the Poincare section, when asked for "
                                                             "(GET /v1/jobs/{id}/section exports it)")
    lyapunov: SpectrumResult | None = Field(None, description="the Lyapunov spectrum, when asked for")
    periodic_orbit: PeriodicOrbitResult | None = Field(None, description="the periodic orbit, when asked for")
    claims: list[ClaimItem] = Field(default_factory=list, description="the request's claims, each with its evidence")


def claims_to_json(evidence: list[Any]) -> list[dict[str, Any]]:
    """The JSON form of :class:`nonholonomic.evidence.claims.ClaimEvidence` items."""
    def finite(x: float) -> float | None:
        return x if math.isfinite(x) else None

    return [{"name": c.name, "expression": c.expression, "initial": finite(c.initial), "final": finite(c.final),
             "max_rel_drift": finite(c.max_rel_drift), "tolerance": c.tolerance, "passed": c.passed,
             "symbolic": {"identically_conserved": c.symbolic, "detail": c.symbolic_detail},
             "not_finite_points": c.not_finite_points} for c in evidence]


def system_units(system: MechanicalSystem) -> dict[str, str]:
    """Units of t, τ, every state and derived vector and every parameter group of ``system``."""
    reduced = system.reduced_time
    units = {"t": "s", **({"tau": reduced.unit} if reduced else {})}
    units.update({v.name: v.unit for v in system.state})
    units.update({d.name: d.unit for d in system.derived})
    units.update({p.name: p.unit for p in system.parameters})
    return units


def component_names(system: MechanicalSystem) -> dict[str, list[str]]:
    """The name of each component of every state and derived vector of ``system``: its symbols (``M1`` ...; the
    user's own coordinates and velocities, ``x``, ``theta``, ``x_dot`` ...), ``omega1`` ... for a derived
    vector; every vector numbered (``q1`` ...) if the symbols would repeat a name or be ``t``, ``tau`` or
    ``member`` (the exports' other columns)."""
    numbered = {v.name: [f"{v.name}{k + 1}" for k in range(len(v.symbols))] for v in system.state}
    numbered.update({d.name: [f"{d.name}{k + 1}" for k in range(len(d.expression))] for d in system.derived})
    own = {**numbered, **{v.name: [str(s) for s in v.symbols] for v in system.state}}
    flat = [name for names in own.values() for name in names]
    return numbered if len(set(flat)) < len(flat) or set(flat) & {"t", "tau", "member"} else own


#: The fields of an answer that say how long, or when, something was computed, or whether it was read back:
#: the only ones in which two runs of the same request may differ (quiet or loaded, cold or warm caches,
#: embedded or queue mode). Each is removed wherever it appears by :func:`without_timing`.
TIMING_FIELDS = ("wall_time_s", "seconds", "computed")


def without_timing(answer: Any) -> Any:
    """``answer`` (JSON) without its :data:`TIMING_FIELDS`, at any depth: what must be identical between two
    runs of the same request."""
    if isinstance(answer, dict):
        return {k: without_timing(v) for k, v in answer.items() if k not in TIMING_FIELDS}
    if isinstance(answer, list):
        return [without_timing(v) for v in answer]
    return answer


def result_to_json(result: SimulationResult, parameters: dict[str, Any]) -> dict[str, Any]:
    """The JSON form of a core :class:`~nonholonomic.simulation.SimulationResult`."""
    system = result.system
    traj = result.trajectory
    vectors = [v.name for v in system.state] + [d.name for d in system.derived]
    reduced = system.reduced_time
    units = system_units(system)
    samples = {name: result.state(name).tolist() for name in vectors}
    return {
        "system": {"kind": system.kind, "title": system.title, "equation": system.equation,
                   "potential": system.potential, "potential_formula": system.potential_formula,
                   "parameters": parameters, "units": units, "components": component_names(system),
                   **({"structure": system.structure} if system.structure is not None else {})},
        "initial_state": {name: values[0] for name, values in samples.items()},
        "projections": [asdict(p) for p in result.projections],
        "final_state": {name: values[-1] for name, values in samples.items()},
        "t_final": float(traj.t[-1]),
        "tau_final": None if traj.tau is None or not np.isfinite(traj.tau[-1]) else float(traj.tau[-1]),
        "time": {"t": "physical time t [s]",
                 "tau": None if reduced is None else
                 f"reduced time, {reduced.formula} (eq. {reduced.equation}), tau(0) = 0",
                 "tau_domain": domain_json(traj.reduced_time)},
        "trajectory": {"t": traj.t.tolist(), "tau": None if traj.tau is None else _finite_or_null(traj.tau),
                       **samples},
        "integrals": [asdict(i) for i in result.integrals],
        "checks": [asdict(c) for c in result.checks],
        "integration": {"engine": traj.engine, "tolerance": traj.tolerance, "steps": traj.steps,
                        "wall_time_s": traj.wall_time_s, "versions": traj.versions},
        "warnings": list(result.warnings),
        "poincare": None if result.poincare is None else section_to_json(result.poincare),
        "lyapunov": None if result.lyapunov is None else spectrum_to_json(result.lyapunov),
        "periodic_orbit": _periodic_orbit(result),
    }


def _finite_or_null(values: np.ndarray) -> list[float | None]:
    """``values`` as a list, NaN (τ where N is not real) as None."""
    return [float(v) if np.isfinite(v) else None for v in values] if not np.all(np.isfinite(values)) \
        else values.tolist()


def _periodic_orbit(result: SimulationResult) -> dict[str, Any] | None:
    if result.periodic_orbit is None:
        return None
    out = orbit_to_json(result.system, result.periodic_orbit)
    if result.continuation is not None:
        out["continuation"] = branch_to_json(result.system, result.continuation)
    if result.branch is not None:
        out["branch"] = orbit_branch_to_json(result.system, result.branch)
    return out


#: An ensemble member's convergence series is thinned to this many rows (a job keeps ~1000).
MEMBER_CONVERGENCE_ROWS = 100


def member_to_json(member: MemberResult) -> dict[str, Any]:
    """One ensemble member as JSON: its index, label, initial state, status, and (when it succeeded)
    the same result fields as a job without the ``system`` block the members share (the Lyapunov
    convergence series thinned to :data:`MEMBER_CONVERGENCE_ROWS` rows)."""
    out: dict[str, Any] = {"index": member.index, "status": member.status, **({"label": dict(member.label)}
                                                                              if member.label else {})}
    if member.result is None:
        out["error"] = member.error
        out["initial_state"] = member.initial_state.tolist()
        return out
    body = result_to_json(member.result, {})
    del body["system"]
    spectrum = body.get("lyapunov")
    if spectrum and len(spectrum["convergence_t"]) > MEMBER_CONVERGENCE_ROWS:  # evenly thinned, the last kept
        rows = np.linspace(0, len(spectrum["convergence_t"]) - 1, MEMBER_CONVERGENCE_ROWS)
        keep = np.unique(rows.round().astype(int))
        spectrum["convergence_t"] = [spectrum["convergence_t"][i] for i in keep]
        spectrum["convergence"] = [spectrum["convergence"][i] for i in keep]
    out.update(body)
    return out


class TrajectoryExport(Trajectory):
    """``GET /v1/jobs/{id}/trajectory?format=json``: the samples with the unit of every column."""

    units: dict[str, str] = Field(description="unit of t, tau, every vector and parameter group")


class MemberResultModel(BaseModel):
    """One ensemble member: its index, label and status; when it succeeded the fields of a job's result
    (without ``system``, shared by the members); when it failed the reason (and its initial state, as
    the flat state vector, when the member got that far)."""

    index: int
    status: Literal["succeeded", "failed", "outside"] = Field(description="'outside': a map's cell where no state "
                                                                          "of the level crosses the section")
    label: dict[str, Any] | None = Field(None, description="what sets the member apart, e.g. {'parameter': 'D', "
                                                           "'value': 0.5} in a sweep, {'cell': [i, j], 'gamma1': ..., "
                                                           "'M3': ..., 'branches': 2} in a map")
    cell: dict[str, Any] | None = Field(None, description="a map's cell: status (regular, chaotic, outside, failed), "
                                                          "indicators, integral_drift, check")
    error: str | None = Field(None, description="why it failed")
    initial_state: dict[str, list[float]] | list[float] | None = None
    projections: list[ProjectionItem] | None = None
    final_state: dict[str, list[float]] | None = None
    t_final: float | None = None
    tau_final: float | None = None
    time: TimeInfo | None = None
    trajectory: Trajectory | None = None
    integrals: list[IntegralItem] | None = None
    checks: list[CheckItem] | None = None
    integration: IntegrationInfo | None = None
    warnings: list[str] | None = None
    poincare: SectionResult | None = None
    lyapunov: SpectrumResult | None = Field(None, description="the spectrum, its convergence series thinned to "
                                                              f"{MEMBER_CONVERGENCE_ROWS} rows")


def first_non_finite(value: Any, path: str = "") -> tuple[str, float] | None:
    """The first NaN or infinity in a JSON-like result, as (dotted path, value), or None.

    A result must be JSON (RFC 8259 has no NaN or infinity); a job whose numbers overflow fails instead.
    """
    if isinstance(value, float):
        return None if math.isfinite(value) else (path, value)
    items: Iterable[tuple[Any, Any]]
    if isinstance(value, dict):
        items = value.items()
    elif isinstance(value, (list, tuple)):
        if value and all(isinstance(v, float) for v in value):  # a numeric row: one vectorised test
            bad = next((i for i, v in enumerate(value) if not math.isfinite(v)), None)
            return None if bad is None else (f"{path}[{bad}]", value[bad])
        items = ((f"[{i}]", v) for i, v in enumerate(value))
    else:
        return None
    for key, item in items:
        where = f"{path}{key}" if str(key).startswith("[") else (f"{path}.{key}" if path else str(key))
        found = first_non_finite(item, where)
        if found is not None:
            return found
    return None
