"""The section explorer's requests (``/v1/explore``): a system, a section plane on a level, a clicked point.

A click is one cell of a 1 × 1 grid (:mod:`nonholonomic.analysis.chaos_map.grid`): the point's two coordinates
and the section's value fix three components, the system's constraints and the level the rest.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from nonholonomic.analysis.chaos_map.grid import Grid, GridError, complete, default_ranges, plan
from nonholonomic.analysis.periodic_orbit import MAX_PERIOD
from nonholonomic.definition import MechanicalSystem
from nonholonomic.initial_state import FieldProblem
from nonholonomic.numerics.kernels import parameter_vector
from schemas.jobs import t_final_within_limit
from schemas.systems import FiniteFloat, JobSystemSpec

#: Longest integration of one click [s] and most crossings it streams.
MAX_EXPLORE_T = 20_000.0
MAX_EXPLORE_POINTS = 5_000


class ExploreSection(BaseModel):
    """The section ``surface = value`` crossed in ``direction``, drawn in two state components on a level."""

    model_config = ConfigDict(extra="forbid")

    surface: str = Field(description="the section's state component, e.g. 'gamma3'")
    value: FiniteFloat = Field(0.0, description="the section: surface = value")
    direction: Literal["increasing", "decreasing"] = Field("increasing")
    coordinates: list[str] = Field(min_length=2, max_length=2, description="the plane's two state components")
    level: dict[str, FiniteFloat] = Field(description="integral name -> value (the energy required)")
    sheet: str | None = Field(None, max_length=500, description="keep the states where this expression is > 0")

    def grid(self, point: list[float] | None = None) -> Grid:
        """The plane as a grid: one cell centred on ``point`` (or a placeholder cell for the plane's checks)."""
        ranges = None
        if point is not None:
            u, v = point
            du, dv = 1e-9 * max(1.0, abs(u)), 1e-9 * max(1.0, abs(v))
            ranges = ((u - du, u + du), (v - dv, v + dv))
        return Grid(self.surface, self.value, (self.coordinates[0], self.coordinates[1]), dict(self.level), (1, 1),
                    ranges, self.direction, self.sheet)


class ExplorePlaneRequest(BaseModel):
    """``POST /v1/explore/plane``: the plane's extent on the level (for the page's axes)."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{
        "system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7,
                   "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}},
        "section": {"surface": "gamma3", "coordinates": ["gamma1", "M3"], "level": {"energy": 2.0, "area": 0.0}}}]})

    system: JobSystemSpec
    section: ExploreSection


class ExploreOrbitRequest(ExplorePlaneRequest):
    """``POST /v1/explore/orbits``: the orbit through a clicked point, its crossings streamed back."""

    model_config = ConfigDict(extra="forbid")

    point: list[FiniteFloat] = Field(min_length=2, max_length=2, description="the click's two coordinates")
    t_final: FiniteFloat = Field(2000.0, gt=0, le=MAX_EXPLORE_T, description="integrate up to this time [s]")
    max_points: int = Field(2000, ge=1, le=MAX_EXPLORE_POINTS, description="stop after this many crossings")

    _t_final_limit = field_validator("t_final")(t_final_within_limit)


class ExplorePeriodicRequest(ExplorePlaneRequest):
    """``POST /v1/explore/periodic-orbit``: the periodic orbit nearest a clicked point (a shift-click)."""

    model_config = ConfigDict(extra="forbid")

    point: list[FiniteFloat] = Field(min_length=2, max_length=2)
    period: int = Field(1, ge=1, le=MAX_PERIOD, description="k: a fixed point of the k-th return map")
    t_final: FiniteFloat = Field(500.0, gt=0, le=MAX_EXPLORE_T, description="the seed's horizon for k + 1 crossings")

    _t_final_limit = field_validator("t_final")(t_final_within_limit)


def plane_problems(request: ExplorePlaneRequest) -> tuple[MechanicalSystem | None, np.ndarray | None,
                                                            list[FieldProblem]]:
    """The system built and the plane checked: (system, parameters, problems)."""
    checked, found = request.system.checked_definition()
    if checked is None or found:
        return None, None, found
    system = request.system.definition()
    p = parameter_vector(system, request.system.parameter_values())
    try:
        plan(system, request.section.grid())
    except GridError as exc:
        return None, None, [FieldProblem(f"section.{exc.field}", exc.reason)]
    return system, p, []


def plane_ranges(system: MechanicalSystem, p: np.ndarray,
                 section: ExploreSection) -> tuple[list[list[float]] | None, list[FieldProblem]]:
    """The region the level allows in the plane's coordinates
    (:func:`~nonholonomic.analysis.chaos_map.grid.default_ranges`), or the problem (a level with no state)."""
    try:
        return [list(r) for r in default_ranges(system, p, section.grid())], []
    except GridError as exc:
        return None, [FieldProblem(f"section.{exc.field}", exc.reason)]


def clicked_state(system: MechanicalSystem, p: np.ndarray, section: ExploreSection,
                  point: list[float]) -> tuple[np.ndarray | None, int, list[FieldProblem]]:
    """The state on the level at ``point`` crossing the section the asked way (the first of ``branches``)."""
    grid = section.grid(point)
    assert grid.ranges is not None  # a cell centred on the point: its ranges are set
    try:
        cells = complete(system, p, grid, grid.ranges)
    except GridError as exc:
        return None, 0, [FieldProblem(f"section.{exc.field}", exc.reason)]
    if cells.branches[0] == 0:
        level = ", ".join(f"{k} = {v:g}" for k, v in section.level.items())
        return None, 0, [FieldProblem("point", f"({point[0]:g}, {point[1]:g}) is outside the level ({level}): no state "
                                               f"of it crosses {section.surface} = {section.value:g} "
                                               f"({section.direction}) there")]
    return cells.states[0], int(cells.branches[0]), []


class ExplorationView(BaseModel):
    """``GET /v1/explore/orbits/{id}``: the crossings found so far (from ``since``)."""

    id: str
    coordinate_names: list[str]
    initial_state: dict[str, list[float]]
    branches: int = Field(description="how many states of the level cross the section at the click (the first taken)")
    since: int
    points: list[list[float]] = Field(description="the crossings' two coordinates, from index since")
    count: int = Field(description="crossings so far")
    done: bool
    error: str | None
    t_reached: float = Field(description="the integration's time so far [s]")
    t_final: float
    max_points: int


class ExplorationAccepted(BaseModel):
    id: str
    location: str
    initial_state: dict[str, list[float]]
    branches: int
