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
        {"surface": "gamma3", "value": 0.0, "direction": "increasing", "coordinates": ["gamma1", "gamma2"],
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
                              tuple(self.coordinates) if self.coordinates else None,  # type: ignore[arg-type]
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
