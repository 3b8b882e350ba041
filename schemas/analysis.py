"""The analysis blocks of a job or an ensemble (``poincare``, ``lyapunov``) and their results as JSON."""

from __future__ import annotations

from dataclasses import asdict, is_dataclass
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from nonholonomic.analysis.options import SectionOptions, SpectrumOptions
from nonholonomic.definition import MechanicalSystem
from nonholonomic.initial_state import FieldProblem
from schemas.settings import get_settings
from schemas.systems import FiniteFloat


class PoincareRequest(BaseModel):
    """A Poincaré section of the orbit: the points where ``surface(x) = value`` is crossed."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [
        {"surface": "gamma3", "value": 0.0, "direction": "increasing", "coordinates": ["M1", "M2"],
         "max_points": 10000}]})

    surface: str = Field(max_length=2000, description="expression in the state components (M1, gamma3, omega2, x1, "
                                                      "E3 ...; the catalog's state and derived vectors), "
                                                      "parsed safely (no eval)")
    value: FiniteFloat = Field(0.0, description="the level of the surface that is the section")
    direction: Literal["increasing", "decreasing", "both"] = Field(
        "increasing", description="which crossings count: surface increasing through the value, decreasing, or both")
    coordinates: list[str] | None = Field(None, min_length=2, max_length=2,
                                          description="two state components to report as the section's "
                                                      "coordinates (default: the kind's first two not on the surface)")
    max_points: int = Field(10_000, ge=1, description="stop the integration once this many crossings are found "
                                                      "(a warning says so)")

    @field_validator("max_points")
    @classmethod
    def _max_points_limit(cls, v: int) -> int:
        limit = get_settings().max_section_points
        if v > limit:
            raise ValueError(f"max_points = {v} exceeds this service's maximum {limit}")
        return v

    def options(self) -> SectionOptions:
        return SectionOptions(self.surface, self.value, self.direction,
                              (self.coordinates[0], self.coordinates[1]) if self.coordinates else None,
                              self.max_points)

    def problems(self, system: MechanicalSystem, prefix: str = "poincare") -> list[FieldProblem]:
        """The surface and coordinates checked against the system (unknown names with their position,
        a surface that is no function of the state)."""
        from nonholonomic.analysis.poincare import SurfaceError, parse_surface, surface_names

        try:
            parse_surface(system, self.surface)
        except SurfaceError as exc:
            where = f" (at position {exc.position})" if exc.position is not None else ""
            return [FieldProblem(f"{prefix}.surface", f"{exc.reason}{where}")]
        names = surface_names(system)
        return [FieldProblem(f"{prefix}.coordinates[{i}]", f"{name!r} is not a state component of {system.kind}; "
                                                          f"known: {', '.join(names)}")
                for i, name in enumerate(self.coordinates or []) if name not in names]


class LyapunovRequest(BaseModel):
    """The Lyapunov spectrum of the orbit (heyoka variational equations, QR every ``interval``)."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [
        {"count": 6, "interval": 1.0, "transient": 0.0}]})

    count: int | None = Field(None, ge=1, description="how many exponents (default: all, the phase space's dimension)")
    interval: FiniteFloat = Field(1.0, gt=0, description="time between QR re-orthonormalisations [s]")
    transient: FiniteFloat = Field(0.0, ge=0, description="time integrated before the averaging starts [s]")

    def options(self) -> SpectrumOptions:
        return SpectrumOptions(self.count, self.interval, self.transient)

    def problems(self, system: MechanicalSystem, t_final: float, prefix: str = "lyapunov") -> list[FieldProblem]:
        found = []
        if self.count is not None and self.count > system.dimension:
            found.append(FieldProblem(f"{prefix}.count", f"{system.kind} has {system.dimension} state variables, "
                                                         f"so at most {system.dimension} exponents"))
        if self.transient >= t_final:
            found.append(FieldProblem(f"{prefix}.transient", f"must be below t_final = {t_final:g}"))
        elif self.interval > t_final - self.transient:
            found.append(FieldProblem(f"{prefix}.interval", f"must be at most t_final - transient = "
                                                            f"{t_final - self.transient:g}"))
        return found


class SectionResult(BaseModel):
    """A Poincaré section of one orbit (a job's or a member's ``poincare``): the crossings of ``surface = value``
    in time order, every state and derived vector at each, and the section's own evidence."""

    count: int = Field(description="number of crossings")
    surface: str = Field(description="the surface's expression as requested")
    value: float = Field(description="the level of the surface")
    direction: Literal["increasing", "decreasing", "both"]
    t: list[float] = Field(description="crossing times [s]")
    tau: list[float] | None = Field(description="the reduced time at the crossings (null for systems without one)")
    points: dict[str, list[list[float]]] = Field(
        description="every state and derived vector by name (M, gamma, omega for the ball), one row per crossing")
    coordinate_names: list[str] = Field(description="the two components reported as the section's coordinates")
    coordinates: list[list[float]] = Field(description="those two components, one pair per crossing")
    surface_residual_max: float = Field(description="max |S(x) - value| / surface_scale at the points")
    surface_scale: float = Field(description="the surface's natural size (normalises the residual)")
    integral_drift_max: dict[str, float] = Field(
        description="per first integral, max |I(x) - I(x0)| / max(|I(x0)|, its natural scale) over the points")
    stopped_early: bool = Field(description="max_points crossings were found before t_final")
    warnings: list[str]
    steps: int = Field(description="accepted Taylor steps")
    wall_time_s: float
    t_final: float = Field(description="the requested end time [s]")
    tolerance: float = Field(description="the integrator's tolerance")


class SectionExport(SectionResult):
    """``GET /v1/jobs/{id}/section?format=json``: the job's section with the unit of every column."""

    units: dict[str, str] = Field(description="unit of t, tau, every vector and parameter group")


class ExpectedZeroItem(BaseModel):
    """One structural reason for a vanishing Lyapunov exponent, counted or not."""

    reason: str
    formula: str
    counted: bool = Field(description="whether it adds a zero exponent")
    note: str = Field(description="why it counts or not")


class SpectrumResult(BaseModel):
    """A Lyapunov spectrum (a job's or a member's ``lyapunov``): exponents, running estimates and the checks
    of their sum against the invariant measure."""

    exponents: list[float] = Field(description="the count largest exponents, descending [1/s]")
    all_exponents: list[float] = Field(description="the whole spectrum, descending [1/s]")
    convergence_t: list[float] = Field(description="times of the kept QR steps after the transient [s]")
    convergence: list[list[float]] = Field(description="running estimates, one row per convergence_t")
    sum: float = Field(description="sum of the whole spectrum (= time average of div f, Liouville)")
    sum_expected: float | None = Field(description="what the invariant measure predicts for T -> infinity (0); "
                                                    "null when the system claims no measure")
    sum_reason: str
    divergence_average: float | None = Field(description="(1/T) int div f dt by quadrature")
    measure_average: float | None = Field(description="-[ln rho]/T: the claimed measure's prediction at this T")
    measure_consistent: bool | None = Field(description="sum equals measure_average; false: the measure is "
                                                        "contradicted")
    expected_zero: list[ExpectedZeroItem]
    zero_count: int = Field(description="how many exponents must vanish")
    zero_indices: list[int] = Field(description="indices into all_exponents of the zero_count smallest in magnitude")
    zero_observed: list[float]
    moved_last_20pct: list[float] = Field(description="per exponent, max - min of its estimate over the last 20 %")
    symmetry_residual: float | None = Field(description="max |lambda_i + lambda_(n+1-i)| for a reversible field")
    method: str
    interval: float
    transient: float
    t_final: float
    tolerance: float
    steps: int = Field(description="QR re-orthonormalisations after the transient")
    integrator_steps: int
    wall_time_s: float
    warnings: list[str]


def _plain(value: Any) -> Any:
    """Arrays to lists, dataclasses to dicts, recursively (JSON-ready)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if is_dataclass(value) and not isinstance(value, type):
        return {k: _plain(v) for k, v in asdict(value).items()}
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def section_to_json(section: Any) -> dict[str, Any]:
    """A :class:`nonholonomic.analysis.poincare.Section` as JSON."""
    out = {"count": section.count}
    out.update({k: _plain(v) for k, v in vars(section).items() if not k.startswith("_")})
    return out


def spectrum_to_json(spectrum: Any) -> dict[str, Any]:
    """A :class:`nonholonomic.analysis.lyapunov.Spectrum` as JSON."""
    return {k: _plain(v) for k, v in vars(spectrum).items() if not k.startswith("_")}
