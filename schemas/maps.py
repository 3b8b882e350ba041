"""``/v1/maps``: the request of ``POST /v1/maps/{name}`` (the source system, as in a job, and the states
to map) and the answers of both routes."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from schemas.systems import AnySystemSpec, Vec3

#: Most states one request may map.
MAX_MAP_STATES = 10000


class MapRequest(BaseModel):
    """A source system and one or many of its states (target states with ``inverse``)."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{
        "system": {"kind": "chaplygin_ball", "inertia": [1.0, 2.0, 3.5], "D": 0.7, "potential": {"kind": "zero"}},
        "states": [{"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}], "project": True}]})

    system: AnySystemSpec = Field(description="the source system, as in POST /v1/jobs (its kind is the map's source)")
    states: list[dict[str, Vec3]] = Field(min_length=1, max_length=MAX_MAP_STATES,
                                          description="source states by vector name (target states if inverse)")
    inverse: bool = Field(False, description="map target states back to the source (maps with an inverse)")
    project: bool = Field(False, description="project each state onto the constraints and the map's level set "
                                             "first (reported) instead of refusing it")


# --------------------------------------------------------------------------------------------------
# responses

#: A parameter group's value: a number, or its components (a vector; a symmetric matrix's 11, 12, 13, 22, 23, 33).
GroupValue = float | list[float]


class _Answer(BaseModel):
    model_config = ConfigDict(extra="forbid")


class MapSource(_Answer):
    kind: str
    potential: str
    state: list[str] = Field(description="the source's state vectors")


class MapTarget(_Answer):
    kind: str
    potential: str
    title: str
    state: list[str]
    job_kind: bool = Field(description="whether the target is a kind of POST /v1/jobs")


class MapConstant(_Answer):
    name: str
    meaning: str


class MapDescription(_Answer):
    """An isomorphism in words: source, target, time substitution, level set, constants, corrections."""

    name: str
    title: str
    equation: str
    formula: str
    source: MapSource
    target: MapTarget
    time: str
    level_set: list[str] = Field(description="where the map holds (the source's constraints and the map's conditions)")
    constants: list[MapConstant] = Field(description="the target's constants computed per state")
    inverse: bool = Field(description="whether POST /v1/maps/{name} accepts inverse = true")
    corrections: list[str]
    convention: str


class MapListEntry(MapDescription):
    source_potentials: list[str] | Literal["all of the source's"] = Field(
        description="the source potentials the map holds for")


class MapList(_Answer):
    """``GET /v1/maps``."""

    maps: list[MapListEntry]


class MapProjection(_Answer):
    """What ``project`` changed in one state."""

    field: str
    change: float = Field(description="max |component change|")
    projection: str


class MappedState(_Answer):
    """One mapped state (forward: with the target's parameters, constants and dτ/dt there)."""

    state: dict[str, list[float]] = Field(description="the image, by vector name")
    target_parameters: dict[str, GroupValue] | None = None
    constants: dict[str, float] | None = None
    time_density: float | None = Field(None, description="d tau / dt at the state")
    source_state: dict[str, list[float]] | None = Field(None, description="with project: the state mapped, after "
                                                                          "projection")
    projections: list[MapProjection] | None = None


class PushForwardResidual(_Answer):
    value: float
    tolerance: float
    passed: bool
    detail: str


class MapResult(_Answer):
    """Answer to ``POST /v1/maps/{name}``."""

    map: MapDescription
    source_parameters: dict[str, GroupValue]
    direction: Literal["forward", "inverse"]
    states: list[MappedState]
    push_forward_residual: PushForwardResidual | None = Field(None, description="forward only")
    target_job_system: dict[str, Any] | None = Field(
        None, description="forward only: the target as a job's system block (for the first state); null if the "
                          "target is not a job kind")
