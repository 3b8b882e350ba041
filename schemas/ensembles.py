"""Ensemble requests (``POST /v1/ensembles``): one system, many members, the same evidence for each.

Members come from an explicit list of initial states, from ``sample`` (states on a level set of the
kind's integrals, drawn with a seed), from a one-parameter ``sweep`` or from a chaos map's ``grid`` (a
section plane's cells completed to states on a level). :meth:`EnsembleRequest.members_list` turns the
request into the core's :class:`~nonholonomic.analysis.ensemble.Member` list, the same in the API
(validation) and in every worker (each chunk rebuilds it), so a chunk needs only its range.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ModelWrapValidatorHandler,
    PositiveFloat,
    PrivateAttr,
    field_validator,
    model_validator,
)

from nonholonomic.analysis.chaos_map import MapOptions
from nonholonomic.analysis.chaos_map.grid import Grid, GridError, complete, default_ranges, plan as plan_grid
from nonholonomic.analysis.chaos_map.indicators import thresholds_for
from nonholonomic.analysis.ensemble import Member, default_chunk_size, plan
from nonholonomic.definition import MechanicalSystem
from nonholonomic.initial_state import FieldProblem, project_initial_state
from nonholonomic.numerics.kernels import parameter_vector, state_vector
from nonholonomic.refusals import RefusedField
from schemas.analysis import LyapunovRequest, PoincareRequest
from schemas.jobs import IntegratorOptions, JobStatus, analysis_problems, t_final_within_limit
from schemas.results import MemberResultModel
from schemas.settings import get_settings
from schemas.sweeps import sweep_target, swept
from schemas.systems import FiniteFloat, JobSystemSpec, StateVec, Step, no_step, state_renamed

ENSEMBLE_JOB = "ensemble"
#: Cells of a map completed at validation (evenly spread; the chunks complete every one).
VALIDATED_CELLS = 256


class SampleMembers(BaseModel):
    """``count`` states on one level set of the kind's integrals (the catalog's ``levels`` lists what
    each kind can fix), drawn with ``seed``: the same seed gives the same states."""

    model_config = ConfigDict(extra="forbid")

    count: int = Field(ge=1, description="number of members")
    seed: int = Field(0, ge=0, le=2**63 - 1, description="seed of numpy's default generator")
    level: dict[str, FiniteFloat] = Field(description="integral name -> value, e.g. {'energy': 1.0, 'area': 0.0}")


class SweepMembers(BaseModel):
    """One member per value of one parameter, all from the same initial state."""

    model_config = ConfigDict(extra="forbid")

    parameter: str = Field(description="parameter path: 'D', 'inertia[1]', 'potential.a[2]'")
    values: list[FiniteFloat] = Field(min_length=1)
    initial_state: dict[str, StateVec]


class GridMembers(BaseModel):
    """A chaos map's cells: a ``shape[0]`` × ``shape[1]`` grid on the section ``surface = value`` in two
    state components, each cell's centre completed to a state on ``level`` that crosses the section in
    ``direction`` (:mod:`nonholonomic.analysis.chaos_map.grid`). Cell ``k = i · shape[1] + j``."""

    model_config = ConfigDict(extra="forbid")

    surface: str = Field(description="the section's state component, e.g. 'gamma3'")
    value: FiniteFloat = Field(0.0, description="the section: surface = value")
    direction: Literal["increasing", "decreasing"] = Field("increasing", description="the crossing's sense")
    coordinates: list[str] = Field(min_length=2, max_length=2, description="the plane's two state components")
    level: dict[str, FiniteFloat] = Field(description="integral name -> value (the energy required), e.g. "
                                                      "{'energy': 2.0, 'area': 0.0}")
    shape: list[int] = Field(min_length=2, max_length=2, description="cells along each coordinate (1 .. 512)")
    ranges: list[list[FiniteFloat]] | None = Field(None, description="[[lo, hi], [lo, hi]] of the coordinates; by "
                                                                     "default the region the level allows")
    sheet: str | None = Field(None, max_length=500,
                              description="an expression in the state; of a cell's states on the level, those where "
                                          "it is > 0 (e.g. the Jacobi problem's a = (omega, n) > 0: "
                                          "'x1*omega1 + x3*omega3/3' on x2 = 0 with B = (1, 2, 3))")

    @field_validator("shape")
    @classmethod
    def _shape(cls, v: list[int]) -> list[int]:
        if any(n < 1 or n > 512 for n in v):
            raise ValueError(f"each side has 1 .. 512 cells, got {v}")
        return v

    @field_validator("ranges")
    @classmethod
    def _ranges(cls, v: list[list[float]] | None) -> list[list[float]] | None:
        if v is not None and (len(v) != 2 or any(len(r) != 2 or not r[0] < r[1] for r in v)):
            raise ValueError("give two [lo, hi] pairs with lo < hi")
        return v

    def grid(self) -> Grid:
        ranges = None if self.ranges is None else ((self.ranges[0][0], self.ranges[0][1]),
                                                   (self.ranges[1][0], self.ranges[1][1]))
        return Grid(self.surface, self.value, (self.coordinates[0], self.coordinates[1]), dict(self.level),
                    (self.shape[0], self.shape[1]), ranges, self.direction, self.sheet)


EnsembleCheck = Literal["integrals", "measure"]


def _integrals_only() -> list[EnsembleCheck]:
    return ["integrals"]


class MembersSpec(BaseModel):
    """Exactly one of ``initial_states``, ``sample``, ``sweep``, ``grid``."""

    model_config = ConfigDict(extra="forbid")

    initial_states: list[dict[str, StateVec]] | None = Field(None, min_length=1)
    sample: SampleMembers | None = None
    sweep: SweepMembers | None = None
    grid: GridMembers | None = Field(None, description="a chaos map's cells (with 'indicators')")

    @model_validator(mode="after")
    def _exactly_one(self) -> MembersSpec:
        given = [k for k in ("initial_states", "sample", "sweep", "grid") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("give exactly one of initial_states, sample, sweep, grid (got "
                             f"{', '.join(given) or 'none'})")
        return self

    @property
    def count(self) -> int:
        if self.initial_states is not None:
            return len(self.initial_states)
        if self.sample is not None:
            return self.sample.count
        if self.grid is not None:
            return self.grid.shape[0] * self.grid.shape[1]
        assert self.sweep is not None  # exactly one of the four is given (_exactly_one)
        return len(self.sweep.values)


class EnsembleRequest(BaseModel):
    """Many orbits of one system, with the same evidence, section and spectrum for each member."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{
        "system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
        "members": {"sample": {"count": 64, "seed": 1, "level": {"energy": 1.0, "area": 0.0}}},
        "t_final": 500.0, "samples": 2,
        "poincare": {"surface": "gamma3", "coordinates": ["M1", "M2"]},
        "lyapunov": {"count": 1}}]})

    system: JobSystemSpec
    members: MembersSpec
    t_final: FiniteFloat = Field(gt=0, description="end of each member's integration [s]")
    samples: int = Field(2, ge=2, description="sample times per member (both ends included)")
    checks: list[EnsembleCheck] = Field(
        default_factory=_integrals_only,
        description="evidence per member (the integrals at its samples and 64 equally spaced check points, "
                    "not every step)")
    poincare: PoincareRequest | None = None
    lyapunov: LyapunovRequest | None = None
    integrator: IntegratorOptions = Field(default_factory=IntegratorOptions)
    project_initial_state: bool = Field(False, description="project each member's state onto the constraints")
    chunk_size: int | None = Field(None, ge=1, description="members per chunk (default: about one second of work)")
    indicators: list[Literal["megno", "fli", "lyapunov"]] | None = Field(
        None, min_length=1, description="a chaos map's indicators (with members.grid), from one integration of the "
                                        "tangent flow; the first sets each cell's status")
    thresholds: dict[str, PositiveFloat] | None = Field(
        None, description="indicator -> value above which a cell is chaotic (default: megno 3, fli ln T + 3, "
                          "lyapunov (ln T + 3)/T)")
    #: Notes on the old names the request used (schemas.deprecations).
    _deprecations: list[str] = PrivateAttr(default_factory=list)

    @model_validator(mode="wrap")
    @classmethod
    def _old_names(cls, data: Any, handler: ModelWrapValidatorHandler[EnsembleRequest]) -> Any:
        ensemble = handler(data)
        notes = ensemble.system.deprecations()
        members = ensemble.members
        states = members.initial_states if members.initial_states is not None else []
        for i, state in enumerate(states):
            states[i], renamed = state_renamed(ensemble.system, state, f"members.initial_states[{i}].")
            notes += renamed
        if members.sweep is not None:
            members.sweep.initial_state, renamed = state_renamed(ensemble.system, members.sweep.initial_state,
                                                                 "members.sweep.initial_state.")
            notes += renamed
        ensemble._deprecations = notes
        return ensemble

    def deprecations(self) -> list[str]:
        """Notes on the deprecated names this request used, for the answer (empty if none)."""
        return list(self._deprecations)

    @model_validator(mode="after")
    def _map_fields(self) -> EnsembleRequest:
        grid = self.members.grid is not None
        if grid and not self.indicators:
            raise ValueError("members.grid is a chaos map: give indicators, e.g. ['megno', 'fli']")
        if self.indicators and not grid:
            raise ValueError("indicators make a chaos map: give members.grid")
        if grid and (self.poincare is not None or self.lyapunov is not None):
            raise ValueError("a chaos map computes its own indicators: leave out poincare and lyapunov")
        unknown = sorted(set(self.thresholds or {}) - set(self.indicators or []))
        if unknown:
            raise ValueError(f"thresholds for indicators not asked for: {', '.join(unknown)}")
        if len(set(self.indicators or [])) != len(self.indicators or []):
            raise ValueError("each indicator once")
        return self

    def map_thresholds(self) -> dict[str, float]:
        """Every indicator's threshold: the request's, else the default for ``t_final``."""
        return thresholds_for(self.t_final, self.thresholds)

    def map_options(self) -> MapOptions:
        return MapOptions(tuple(self.indicators or ()), self.map_thresholds(), self.members.count,
                          self.integrator.tolerance)

    _t_final_limit = field_validator("t_final")(t_final_within_limit)

    def definition(self) -> MechanicalSystem:
        """The members' shared definition (a sweep of a user-written system's parameter: its generic one)."""
        if self.members.sweep is not None and hasattr(self.system, "generic_definition"):
            return self.system.generic_definition()
        return self.system.definition()

    def effective_chunk_size(self, system: MechanicalSystem | None = None) -> int:
        """``chunk_size``, else about a second of work per chunk, larger when that would make more than
        ``max_ensemble_chunks`` chunks (each is a message the POST sends)."""
        if self.chunk_size:
            return self.chunk_size
        size = default_chunk_size(system or self.system.outline(), self.t_final,
                                  poincare=self.poincare.options() if self.poincare else None,
                                  lyapunov=self.lyapunov.options() if self.lyapunov else None,
                                  indicators=bool(self.indicators))
        return max(size, -(-self.members.count // get_settings().max_ensemble_chunks))

    def chunks(self) -> list[tuple[int, int]]:
        """``(start, stop)`` of every chunk."""
        return [(c.start, c.stop) for c in plan(self.members.count, self.effective_chunk_size())]

    def expressions(self) -> list[tuple[str, str]]:
        """Every expression the user wrote, by field path: the system's and the surface."""
        found = self.system.expressions()
        grid = self.members.grid
        return (found + ([("poincare.surface", self.poincare.surface)] if self.poincare is not None else [])
                + ([("members.grid.sheet", grid.sheet)] if grid is not None and grid.sheet else []))

    def problems(self, step: Step = no_step) -> list[FieldProblem]:
        """Everything wrong with the request, each member's state included, before anything is queued
        (``step(fields)`` is told which fields each stage reads, as for a job)."""
        settings = get_settings()
        system, found = self.system.checked_definition(step)
        if system is None:
            return found
        count = self.members.count
        if count > settings.max_ensemble_members:
            found.append(FieldProblem("members", f"{count} members exceed this service's maximum "
                                                  f"{settings.max_ensemble_members}"))
        if count * self.samples > settings.max_ensemble_values:
            found.append(FieldProblem("samples", f"members x samples = {count} x {self.samples} = "
                                                 f"{count * self.samples} exceeds this service's maximum "
                                                 f"{settings.max_ensemble_values}; ask for fewer samples"))
        if self.poincare is not None and count * self.poincare.max_points > settings.max_ensemble_section_points:
            found.append(FieldProblem("poincare.max_points", f"members x max_points = {count} x "
                                                             f"{self.poincare.max_points} exceeds this service's "
                                                             f"maximum {settings.max_ensemble_section_points}"))
        found += analysis_problems(system, self.integrator, self.t_final, self.poincare, self.lyapunov, step)
        if found:
            return found
        found += self._chunk_problems(system, count, settings.max_queued_messages)
        if found:
            return found
        step([field for field, _ in self.system.expressions()] or ["members"])
        return self._member_problems(system)

    def _chunk_problems(self, system: MechanicalSystem, count: int, max_queued: int) -> list[FieldProblem]:
        """An ensemble whose chunks alone exceed the queue's bound could never be admitted: refused here,
        before its members are validated or anything is sent (issue 19, item 5)."""
        if count < 1:
            return []
        size = self.effective_chunk_size(system)
        chunks = -(-count // size)
        most = get_settings().max_ensemble_chunks
        if self.chunk_size and chunks > most:  # each chunk is a message the POST sends: a bound on its cost
            return [FieldProblem("chunk_size", f"{count} members in chunks of {size} make {chunks} chunks, more than "
                                               f"one ensemble may have (max_ensemble_chunks={most}); use chunk_size "
                                               f">= {-(-count // most)}, or leave it out")]
        if chunks <= max_queued:
            return []
        field = "chunk_size" if self.chunk_size else "members"
        return [FieldProblem(field, f"{count} members in chunks of {size} make {chunks} chunks, more than the "
                                    f"queue holds (max_queued_messages={max_queued}); send at most "
                                    f"{max_queued * size} members, or larger chunks")]

    def _member_problems(self, system: MechanicalSystem) -> list[FieldProblem]:
        parameters = self.system.parameter_values()
        project = self.project_initial_state
        spec = self.members
        found: list[FieldProblem] = []
        if spec.initial_states is not None:
            for i, state in enumerate(spec.initial_states):
                for p in self.system.state_problems(system, parameters, state, project):
                    found.append(FieldProblem(p.field.replace("initial_state", f"members.initial_states[{i}]", 1),
                                              p.reason))
                if len(found) >= 20:
                    break
        elif spec.sweep is not None:
            try:
                group, index = sweep_target(system, spec.sweep.parameter)
            except ValueError as exc:
                return [FieldProblem("members.sweep.parameter", str(exc))]
            for i, value in enumerate(spec.sweep.values):
                values = swept(parameters, group, index, value)
                try:
                    parameter_vector(system, values)
                except ValueError as exc:
                    found.append(FieldProblem(f"members.sweep.values[{i}]", str(exc)))
                    continue
                for p in self.system.state_problems(system, values, spec.sweep.initial_state,
                                                    project):
                    found.append(FieldProblem(p.field.replace("initial_state", "members.sweep.initial_state", 1),
                                              f"{p.reason} (with {spec.sweep.parameter} = {value:g})"))
                if len(found) >= 20:
                    break
        elif spec.grid is not None:  # a sample of the cells, spread over the grid: a grid's problems are structural
            try:
                cells = np.unique(np.linspace(0, spec.count - 1, min(spec.count, VALIDATED_CELLS)).round().astype(int))
                complete(system, parameter_vector(system, self.system.parameter_values()),
                         spec.grid.grid(), self.grid_ranges(system), indices=cells)
            except LevelProblem as exc:
                found.append(FieldProblem(exc.field, exc.reason))
            except GridError as exc:
                found.append(FieldProblem(f"members.grid.{exc.field}", exc.reason))
        else:
            try:
                self.members_list(0, spec.count)
            except LevelProblem as exc:
                found.append(FieldProblem(exc.field, exc.reason))
        return found

    def grid_ranges(self, system: MechanicalSystem | None = None) -> tuple[tuple[float, float], ...]:
        """The map's ranges: the request's, else the region its level allows.

        Raises
        ------
        LevelProblem
            If the grid cannot be built (:class:`~nonholonomic.analysis.chaos_map.grid.GridError`).
        """
        members = self.members.grid
        assert members is not None  # a chaos map's: members.grid is given
        grid = members.grid()
        system = system or self.definition()
        try:
            plan_grid(system, grid)
            if grid.ranges is not None:
                return grid.ranges
            p = parameter_vector(system, self.system.parameter_values())
            return default_ranges(system, p, grid)
        except GridError as exc:
            raise LevelProblem(f"members.grid.{exc.field}", exc.reason) from None

    def members_list(self, start: int = 0, stop: int | None = None) -> list[Member]:
        """Members ``start .. stop − 1`` (all by default) as the core's :class:`Member` objects.

        Sampled members are drawn in order with the seed (a shorter draw is a prefix of a longer one),
        so any chunk gets the same states as the whole ensemble would.

        Raises
        ------
        LevelProblem
            If the level set cannot be sampled (names it cannot fix, an unreachable level).
        """
        system = self.definition()
        parameters = self.system.parameter_values()
        spec = self.members
        stop = spec.count if stop is None else stop
        p = parameter_vector(system, parameters)
        if spec.initial_states is not None:
            return [Member(i, p, self._state(system, p, spec.initial_states[i])) for i in range(start, stop)]
        if spec.sweep is not None:
            group, index = sweep_target(system, spec.sweep.parameter)
            out = []
            for i in range(start, stop):
                value = spec.sweep.values[i]
                pi = parameter_vector(system, swept(parameters, group, index, value))
                out.append(Member(i, pi, self._state(system, pi, spec.sweep.initial_state),
                                  {"parameter": spec.sweep.parameter, "value": value}))
            return out
        if spec.grid is not None:
            grid = spec.grid.grid()
            try:
                cells = complete(system, p, grid, self.grid_ranges(system), start, stop)
            except GridError as exc:
                raise LevelProblem(f"members.grid.{exc.field}", exc.reason) from None
            names = grid.coordinates
            return [Member(i, p, cells.states[i - start],
                           {"cell": [i // grid.shape[1], i % grid.shape[1]],
                            names[0]: float(cells.values[i - start, 0]),
                            names[1]: float(cells.values[i - start, 1]), "branches": int(cells.branches[i - start])})
                    for i in range(start, stop)]
        from nonholonomic.analysis.sampling import LevelError, on_level

        sample = spec.sample
        assert sample is not None  # exactly one of the four is given (MembersSpec._exactly_one)
        try:
            states = on_level(system, p, sample.level, stop, sample.seed)
        except LevelError as exc:
            raise LevelProblem(f"members.sample.{exc.field}", exc.reason) from None
        return [Member(i, p, states[i]) for i in range(start, stop)]

    def _state(self, system: MechanicalSystem, p: np.ndarray, state: dict[str, list[float]]) -> np.ndarray:
        y = state_vector(system, dict(state), p)
        if self.project_initial_state:
            y, _ = project_initial_state(system, p, y)
        return y


class LevelProblem(RefusedField):
    """A level set that cannot be sampled, with the request field that says so."""


class EnsembleAccepted(BaseModel):
    """Answer to ``POST /v1/ensembles`` (202)."""

    id: str
    status: JobStatus
    location: str
    members: int
    chunks: int
    deprecations: list[str] = Field(default_factory=list, description="notes on deprecated names the request "
                                                                      "used, each saying what replaces it")


class EnsembleView(BaseModel):
    """An ensemble as ``GET /v1/ensembles/{id}`` shows it."""

    id: str
    status: JobStatus
    progress: float = Field(ge=0, le=1, description="members done / members")
    created_at: str
    request: dict[str, Any]
    members: int
    members_done: int
    chunks: dict[str, Any] = Field(description="total, done, and the workers that ran them")
    summary: dict[str, Any] | None = Field(description="members succeeded/failed, worst integral drift, exponent "
                                                       "statistics, section points (over the members done so far)")


class EnsembleListItem(BaseModel):
    """One ensemble of the list: no request and no summary (``location`` has them)."""

    id: str
    status: JobStatus
    progress: float = Field(ge=0, le=1, description="members done / members")
    created_at: str
    kind: str | None = Field(description="the system's kind")
    members: int
    members_done: int
    label: str = Field(description="what varies across the members: 'list', 'level set' or 'sweep of D', "
                                   "'grid (chaos map) of gamma1, M3' ...")
    location: str = Field(description="the ensemble's URL, /v1/ensembles/{id}")


class EnsembleList(BaseModel):
    """A page of ensembles, newest first."""

    items: list[EnsembleListItem]
    next_cursor: str | None = Field(
        description="pass as `cursor` for the next page; null at the end. With a status filter a page may hold "
                    "fewer items than `limit` (even none) and still have a next cursor: a page reads `limit` "
                    "ensembles")


class MembersPage(BaseModel):
    """``GET /v1/ensembles/{id}/members``: members ``offset .. offset + limit - 1`` whose chunk is done."""

    offset: int
    limit: int
    total: int = Field(description="members of the ensemble")
    components: dict[str, list[str]] = Field(default_factory=dict, description=(
        "the name of each component of every state and derived vector (the system's own coordinates: x, theta, "
        "x_dot ...; M1 ... for the catalog's kinds), as a job's result.system.components"))
    members: list[MemberResultModel]
