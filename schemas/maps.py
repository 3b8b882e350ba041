"""Requests of ``POST /v1/maps/{name}``: the source system (as in a job) and the states to map."""

from __future__ import annotations

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
