"""Response models of the catalog (``GET /v1/systems``, ``GET /v1/systems/{kind}``).

They describe what :func:`nonholonomic.catalog.describe` returns; ``extra="forbid"`` so that a key
the core adds without a field here fails the API tests (response validation) instead of going
undocumented.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class CatalogParameter(_Strict):
    """A parameter group as a request spells it (``inertia``, ``D``, ``a`` ...)."""

    name: str = Field(description="request name of the group")
    shape: Literal["scalar", "vector", "symmetric_matrix"]
    components: list[str] = Field(
        description="the symbols, in order (a symmetric matrix: entries 11, 12, 13, 22, 23, 33)")
    meaning: str
    unit: str
    admissible: str = Field(description="admissible range, e.g. '> 0'")
    components_are: str | None = Field(None, description="present when the equations use a transform of the "
                                                          "requested matrix (the quadric's B^-1)")


class CatalogPotential(_Strict):
    """A potential the kind supports, with what an ensemble's ``sample.level`` may fix for it."""

    kind: str
    formula: str
    parameters: list[CatalogParameter]
    levels: list[str] = Field(description="integrals a {'sample': {'level': {...}}} of an ensemble may fix")
    sampling: str = Field(description="how states on a level set are drawn")
    explore: str | None = Field(None, description="the page where its section can be clicked (/explore?...)")


class CatalogExpressionPotential(_Strict):
    """How to write a potential of one's own: ``{"kind": "expression", "U": ..., "parameters": {...}}``."""

    kind: str
    variables: list[str] = Field(description="the names U may use besides its own parameters")
    formula: str
    max_length: int = Field(description="longest U (characters)")
    max_parameters: int
    reserved_names: list[str] = Field(description="names a parameter of U may not take (the system's own)")
    example: dict[str, Any]


class CatalogSurfaceExpression(_Strict):
    """How to write the surface of a ``ball_on_surface``: ``{"Phi": ..., "parameters": {...}}``."""

    variables: list[str] = Field(description="the names Phi may use besides its own parameters")
    formula: str
    max_length: int = Field(description="longest Phi (characters)")
    max_parameters: int
    reserved_names: list[str] = Field(description="names a parameter of Phi may not take (the system's own)")
    example: dict[str, Any]


class CatalogStateVector(_Strict):
    name: str
    components: list[str]
    meaning: str
    unit: str


class CatalogAlternativeInput(_Strict):
    """A vector an initial state may give instead of a state vector (the ball's ``omega`` for ``M``)."""

    name: str
    replaces: str
    formula: str


class CatalogDerivedVector(_Strict):
    """A vector computed from the state and reported along the trajectory."""

    name: str
    formula: str
    meaning: str
    unit: str


class CatalogConstraint(_Strict):
    field: str = Field(description="the state vector it constrains")
    formula: str
    equation: str
    tolerance: float = Field(description="largest violation accepted in an initial state")
    projection: str | None = Field(description="how project_initial_state moves a state onto it (null: no projection)")


class CatalogIntegral(_Strict):
    name: str
    formula: str
    equation: str
    claimed_for_potentials: list[str]


class CatalogMeasure(_Strict):
    formula: str
    equation: str


class CatalogReducedTime(_Strict):
    formula: str
    equation: str
    unit: str


class SystemDescription(_Strict):
    """One kind of the catalog: everything a client needs to pose a job for it."""

    kind: str
    title: str
    equation: str = Field(description="paper equation label")
    parameters: list[CatalogParameter]
    potentials: list[CatalogPotential]
    potential_expression: CatalogExpressionPotential = Field(
        description="a potential written as an expression; integrals claimed for it are those whose "
                    "claimed_for_potentials lists 'expression'")
    surface_expression: CatalogSurfaceExpression | None = Field(
        description="for ball_on_surface: the surface Phi(x) = 0 written as an expression (null for other kinds)")
    state: list[CatalogStateVector]
    alternative_inputs: list[CatalogAlternativeInput]
    derived: list[CatalogDerivedVector]
    constraints: list[CatalogConstraint]
    integrals: list[CatalogIntegral]
    measure: CatalogMeasure
    reduced_time: CatalogReducedTime | None
    notes: list[str]
    checks: list[str] = Field(description="the evidence a job of this kind may ask for")
    maps: dict[str, list[str]] = Field(description="potential -> names of the maps (POST /v1/maps/{name}) from it")
    example: dict[str, Any] | None = Field(description="a POST /v1/jobs body for this kind")
    time_unit: str


class CatalogGeneralizedChaplygin(_Strict):
    """A generalized Chaplygin system of one's own (eq. 2704-7) as a job's ``system``."""

    kind: str
    title: str
    equation: str
    fields: dict[str, str] = Field(description="what each field of the system block holds")
    state: list[str] = Field(description="the initial state's vectors (two components each)")
    checks: list[str]
    example: dict[str, Any] = Field(description="a runnable job: Veselova's system in Euler angles")


class LagrangianClassic(_Strict):
    """A classic nonholonomic system written as a Lagrangian with constraints."""

    title: str
    job: dict[str, Any] = Field(description="a runnable POST /v1/jobs body")
    facts: list[str] = Field(description="the closed forms or published facts its tests check")
    measure: str = Field(description="the invariant-measure verdict the search reaches: found, none or undecided")
    hamiltonization: str = Field(description="Theorem 1's verdict: found, none or not applicable")
    references: list[str]


class CatalogLagrangian(_Strict):
    """A Lagrangian system of one's own with constraints linear in the velocities as a job's ``system``."""

    kind: str
    title: str
    equation: str
    fields: dict[str, str] = Field(description="what each field of the system block holds")
    max_coordinates: int
    reserved_names: list[str] = Field(description="names a coordinate or parameter may not take")
    state: list[str] = Field(description="the initial state's vectors (one component per coordinate each)")
    integrals: list[str] = Field(description="what a job claims along the motion")
    measure: str = Field(description="how the invariant measure is sought and when it is claimed")
    integrals_search: str = Field(description="how integrals beyond the energy are sought")
    hamiltonization: str = Field(description="when Theorem 1's time substitution and Hamiltonian form are given")
    initial_state: str = Field(description="what the initial state must satisfy")
    checks: list[str]
    example: dict[str, Any] = Field(description="a runnable job: Chaplygin's sleigh")
    classics: dict[str, LagrangianClassic] = Field(
        description="classic systems as worked examples, each a runnable job with the facts it is tested against")


class Catalog(_Strict):
    """``GET /v1/systems``: one entry per kind, the generalized Chaplygin system and the Lagrangian system of
    one's own."""

    systems: list[SystemDescription]
    generalized_chaplygin: CatalogGeneralizedChaplygin
    lagrangian: CatalogLagrangian
