"""Request models for systems and potentials, generated from the core's definitions.

Each kind's parameters (names, meaning, units, admissible ranges) are declared once, in its core
module (``PARAMETERS``) and in :mod:`nonholonomic.potentials`; the pydantic models here are built
from those declarations so the API cannot disagree with the core.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from functools import lru_cache
from typing import TYPE_CHECKING, Annotated, Any, ClassVar, Literal, TypeAlias, Union

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    Strict,
    TypeAdapter,
    ValidationInfo,
    create_model,
    field_validator,
)

from nonholonomic.definition import MAX_PARAMETER_MAGNITUDE, MIN_POSITIVE_PARAMETER, MechanicalSystem, Parameter
from nonholonomic.expressions import ExpressionError, check_expression, declare_symbols
from nonholonomic.initial_state import FieldProblem, initial_state_problems
from nonholonomic.lagrangian import parse as lagrangian
from nonholonomic.lagrangian.checks import field_problem
from nonholonomic.lagrangian.parse import MAX_COORDINATES
from nonholonomic.potentials import EXPRESSION, MAX_EXPRESSION_LENGTH, MAX_EXPRESSION_PARAMETERS, Potential
from nonholonomic.refusals import RefusedField
from nonholonomic.systems import (
    KINDS,
    POTENTIAL_NAMES,
    SYSTEMS,
    generalized_chaplygin as gc,
    get_system,
    lagrangian as lag,
    own_names,
    user_potential,
)
from nonholonomic.systems.ball_on_surface import SURFACE_VARIABLES, Surface, surface
from nonholonomic.systems.generalized_chaplygin import EXAMPLE as GENERALIZED_CHAPLYGIN_EXAMPLE
from schemas.deprecations import RENAMED_FIELDS, RENAMED_STATE, FormerFieldNames, renamed

FiniteFloat = Annotated[float, Strict(), Field(allow_inf_nan=False)]
#: ``step(fields)``: the validation is about to read these fields (the safety cap names them if it stops the check).
Step = Callable[[Sequence[str]], None]


def state_renamed(system: SystemSpec, state: Any, where: str) -> tuple[Any, list[str]]:
    """An initial state with the former names of ``system``'s state vectors given their new ones, and the
    notes saying so (:mod:`schemas.deprecations`)."""
    return renamed(state, system.renamed_state, where) if system.renamed_state else (state, [])


def no_step(fields: Sequence[str]) -> None:
    """The :data:`Step` of a validation that reports nothing (in the API process)."""


#: Admissible state components (initial states, vectors): beyond, the equations' products overflow.
MAX_STATE_MAGNITUDE = 1e12
StateFloat = Annotated[float, Strict(), Field(allow_inf_nan=False, ge=-MAX_STATE_MAGNITUDE, le=MAX_STATE_MAGNITUDE)]
Vec3 = Annotated[list[StateFloat], Field(min_length=3, max_length=3)]
#: A state vector of an initial state: 3 components, 2 for a generalized Chaplygin system's q and qdot, 1 to 8
#: for a lagrangian system's q and q_dot (each kind checks its own lengths).
StateVec = Annotated[list[StateFloat], Field(min_length=1, max_length=MAX_COORDINATES)]
Mat3 = Annotated[list[Vec3], Field(min_length=3, max_length=3)]


def _camel(name: str) -> str:
    return "".join(part.capitalize() for part in name.split("_"))


def _checked_by_core(par: Parameter) -> AfterValidator:
    """Run the core's own check of a matrix parameter (symmetry, definiteness) as a field validator."""

    def check(value: Any) -> Any:
        par.flatten(value)  # raises ValueError with the reason
        return value

    return AfterValidator(check)


def _at_least_min_positive(value: float) -> float:
    if value < MIN_POSITIVE_PARAMETER:
        raise ValueError(f"must be at least {MIN_POSITIVE_PARAMETER:g} (> 0; smaller values overflow the equations)")
    return value


def _parameter_field(par: Parameter) -> tuple[Any, Any]:
    bounds: dict[str, float] = {"ge": -MAX_PARAMETER_MAGNITUDE, "le": MAX_PARAMETER_MAGNITUDE}
    if par.minimum is not None:
        bounds.pop("ge")
        bounds["gt" if par.strict else "ge"] = par.minimum
    bounded = Annotated[float, Strict(), Field(allow_inf_nan=False, **bounds)]
    number: Any = bounded
    if par.strict and par.minimum == 0:  # the core's smallest positive value, checked per component
        number = Annotated[bounded, AfterValidator(_at_least_min_positive)]
    annotation: Any = number
    if par.shape == "vector":
        annotation = Annotated[list[number], Field(min_length=3, max_length=3)]
    elif par.shape == "symmetric_matrix":
        annotation = Annotated[Vec3 | Mat3, _checked_by_core(par)]
    return annotation, Field(description=f"{par.meaning} [{par.unit}]; {par.admissible}")


class PotentialSpec(BaseModel):
    """Base of the potential models: ``kind`` plus the potential's own parameters."""

    model_config = ConfigDict(extra="forbid")

    def parameter_values(self) -> dict[str, Any]:
        return self.model_dump(exclude={"kind"})

    def core(self, kind: str) -> str | Potential:
        """What :func:`nonholonomic.systems.get_system` takes for this potential of ``kind``."""
        return self.kind  # type: ignore[attr-defined]  # create_model's field


ParameterFloat = Annotated[float, Strict(), Field(allow_inf_nan=False, ge=-MAX_PARAMETER_MAGNITUDE,
                                                  le=MAX_PARAMETER_MAGNITUDE)]


class ExpressionPotentialSpec(PotentialSpec):
    """A potential written as an expression (parsed without eval; the catalog lists the names it may use)."""

    kind: Literal["expression"]
    parameters: dict[str, ParameterFloat] = Field(
        default_factory=dict, max_length=MAX_EXPRESSION_PARAMETERS,
        description="values of the expression's own parameters by name (not a name of the system's)")
    U: str = Field(min_length=1, max_length=MAX_EXPRESSION_LENGTH,
                   description="U as an expression in the kind's potential variables (catalog: potential_variables) "
                               "and the parameters; + - * / **, numbers, pi, E, sin cos exp log sqrt ...")

    def parameter_values(self) -> dict[str, Any]:
        return dict(self.parameters)

    def core(self, kind: str) -> Potential:
        return user_potential(kind, self.U, tuple(sorted(self.parameters)))


def _taken(names: list[str], kind: str) -> str:
    return (f"{', '.join(names)}: already a name of {kind} (its parameters, state or potential variables); choose "
            "another")


# The validators every user-written expression shares: cheap, deterministic checks on the request path; sympy
# reads the expressions off the event loop (service/validation.py).

def own_names_checked(values: dict[str, float], reserved: Sequence[str], kind: str) -> dict[str, float]:
    """A block's own parameter names: valid identifiers (not a function's name) and none of ``reserved``
    (``kind``'s names); the system's own names (a definition to build) are checked off the event loop."""
    try:
        declare_symbols(list(values))
    except ExpressionError as exc:
        raise ValueError(str(exc)) from None
    taken = sorted(set(values) & set(reserved))
    if taken:
        raise ValueError(_taken(taken, kind))
    return values


def expression_checked(text: str, names: Sequence[str], entry: str | None = None) -> str:
    """The cheap checks of one expression: length, syntax, the whitelist of functions, only ``names``
    (``entry`` names an item of a list field: ``constraints[1]``)."""
    try:
        check_expression(text, list(names), max_length=MAX_EXPRESSION_LENGTH)
    except ExpressionError as exc:
        raise ValueError(str(exc) if entry is None else f"{entry}: {exc}") from None
    return text


def core_names_checked(value: Any, field_name: str, check: Callable[[], object]) -> Any:
    """``value`` of the names field ``field_name`` after the core's own name check (``check()``, raising a
    :class:`~nonholonomic.refusals.RefusedField`); refusals of other fields are left to their validators."""
    try:
        check()
    except RefusedField as exc:
        if exc.field == field_name:
            raise ValueError(exc.reason) from None
    return value


def _expression_model(kind: str) -> type[PotentialSpec]:
    def names(cls: type, values: dict[str, float]) -> dict[str, float]:
        return own_names_checked(values, POTENTIAL_NAMES[kind], kind)

    def parsed(cls: type, text: str, info: ValidationInfo) -> str:
        if "parameters" not in info.data:
            return text  # the parameters are refused already
        return expression_checked(text, [*POTENTIAL_NAMES[kind], *info.data["parameters"]])

    validators = {"names": field_validator("parameters")(classmethod(names)),
                  "parsed": field_validator("U")(classmethod(parsed))}
    return create_model(
        f"{_camel(kind)}ExpressionPotential",
        __base__=ExpressionPotentialSpec,
        __doc__=f"U written as an expression in {', '.join(POTENTIAL_NAMES[kind])} and its own parameters",
        __validators__=validators,  # type: ignore[arg-type]  # the stub takes callables; these are classmethods
    )


#: Declared after ``D`` in the JSON schema of the ball kinds, so that generated clients keep the attribute ``D``.
_LOWER_D = {"not": {}, "description": "not a field (always refused): the parameter is upper-case D, the paper's "
                                      "D = m R^2. Declared so that generated clients name D's attribute 'D'."}


def _keep_client_names(schema: dict[str, Any], cls: type) -> None:
    """Guard generated clients against a name clash of the paper's ``D``.

    openapi-python-client (0.29) names a property's attribute by snake-casing its key, so ``D`` becomes
    ``d``, and its generated ``from_dict`` parses into a local dict that is also called ``d``: the line
    ``d = d.pop("D")`` replaces the dict by the number, the next ``d.pop("potential", ...)`` raises
    AttributeError, and the union parser of ``system`` then rejects every ball (chaplygin_ball,
    chaplygin_ball_veselova, rubber_ball). Two keys with the same snake-case name make the generator keep
    both keys verbatim instead, so ``D`` stays ``D``. The second key ``d`` is declared with the schema
    ``{"not": {}}``, which no value satisfies (``extra="forbid"`` refuses it already), and last, so it is
    parsed after every real field. The request format is unchanged.
    """
    properties = schema.get("properties", {})
    if "D" in properties and "d" not in properties:
        properties["d"] = dict(_LOWER_D)


class SurfaceSpec(BaseModel):
    """The surface Φ(x) = 0 on which the ball's centre moves, as an expression (parsed without eval)."""

    model_config = ConfigDict(extra="forbid")

    parameters: dict[str, ParameterFloat] = Field(
        default_factory=dict, max_length=MAX_EXPRESSION_PARAMETERS,
        description="values of Phi's own parameters by name (not a name of the system's or of the potential's)")
    Phi: str = Field(min_length=1, max_length=MAX_EXPRESSION_LENGTH,
                     description=f"Phi as an expression in {', '.join(SURFACE_VARIABLES)} and the parameters; the "
                                 "centre of the ball moves on Phi(x) = 0, with normal grad Phi/|grad Phi|")

    @field_validator("parameters")
    @classmethod
    def _names(cls, values: dict[str, float]) -> dict[str, float]:
        return own_names_checked(values, SURFACE_VARIABLES, "ball_on_surface")

    @field_validator("Phi")
    @classmethod
    def _parsed(cls, text: str, info: ValidationInfo) -> str:
        if "parameters" not in info.data:
            return text  # the parameters are refused already
        return expression_checked(text, [*SURFACE_VARIABLES, *info.data["parameters"]])

    def core(self) -> Surface:
        """The core's :class:`nonholonomic.systems.ball_on_surface.Surface`."""
        return surface(self.Phi, tuple(sorted(self.parameters)))


class SystemSpec(FormerFieldNames):
    """Base of the system models: ``kind``, the system's parameters and ``potential`` (and, for a ball
    on a surface of the user's own, ``surface``)."""

    model_config = ConfigDict(extra="forbid", json_schema_extra=_keep_client_names)
    # kind, potential (and surface) are fields of each kind's own model, added by create_model (_system_model)
    #: Former names of this kind's state vectors, still read (old → new; schemas.deprecations).
    renamed_state: ClassVar[dict[str, str]] = {}

    def parameter_values(self) -> dict[str, Any]:
        """Every parameter group by name, the potential's and the surface's included (the core's input)."""
        values = self.model_dump(exclude={"kind", "potential", "surface"})
        values.update(self.potential.parameter_values())  # type: ignore[attr-defined]  # create_model's field
        if getattr(self, "surface", None) is not None:
            values.update(self.surface.parameters)  # type: ignore[attr-defined]  # create_model's field
        return values

    def definition(self) -> MechanicalSystem:
        """The core's symbolic definition for this kind and potential (and surface)."""
        on = getattr(self, "surface", None)
        kind: str = self.kind  # type: ignore[attr-defined]  # create_model's field
        potential: PotentialSpec = self.potential  # type: ignore[attr-defined]  # create_model's field
        return get_system(kind, potential.core(kind), None if on is None else on.core())

    def validation_definition(self) -> MechanicalSystem:
        """The definition without its structure searches (the same as :meth:`definition` but for kinds whose
        definition runs heavy symbolic work): units, labels and plots of a stored job."""
        return self.definition()

    def outline(self) -> MechanicalSystem:
        """What a request is checked against on the request path (:meth:`validation_definition`, but for
        kinds whose equations are derived with the job)."""
        return self.validation_definition()

    def state_problems(self, system: MechanicalSystem, parameters: Mapping[str, Any],
                       initial_state: Mapping[str, Sequence[float]], project: bool = False) -> list[FieldProblem]:
        """Everything wrong with ``initial_state`` (:func:`nonholonomic.initial_state.initial_state_problems`)
        at the parameters' ``parameters``."""
        return initial_state_problems(system, parameters, initial_state, project)

    def component_names(self) -> dict[str, list[str]]:
        """The names of the state's components where the request gives them (a system written by the user:
        ``{"q": [...], "q_dot": [...]}``); empty for a catalog kind (its definition names them)."""
        return {}

    def expressions(self) -> list[tuple[str, str]]:
        """The expressions the user wrote in this block, by field path (``system.potential.U`` ...)."""
        found = []
        potential: PotentialSpec = self.potential  # type: ignore[attr-defined]  # create_model's field
        if isinstance(potential, ExpressionPotentialSpec):
            found.append(("system.potential.U", potential.U))
        on = getattr(self, "surface", None)
        if on is not None:
            found.append(("system.surface.Phi", on.Phi))
        return found

    def checked_definition(self, step: Step = no_step) -> tuple[MechanicalSystem | None, list[FieldProblem]]:
        """:meth:`validation_definition`, or the problems that keep it from being built, each naming its
        field; ``step`` is told which fields each stage reads."""
        fields = [field for field, _ in self.expressions()]
        step(fields or ["system"])
        kind: str = self.kind  # type: ignore[attr-defined]  # create_model's field
        own = own_names(kind) if fields else frozenset()
        potential: PotentialSpec = self.potential  # type: ignore[attr-defined]  # create_model's field
        on = getattr(self, "surface", None)
        declared = {"system.potential": potential.parameter_values() if "system.potential.U" in fields else {},
                    "system.surface": on.parameters if "system.surface.Phi" in fields and on is not None else {}}
        for block, names in declared.items():
            taken = sorted(set(names) & own)
            if taken:
                return None, [FieldProblem(f"{block}.parameters", _taken(taken, kind))]
        for field, read in (("system.potential.U", lambda: potential.core(kind)),
                            ("system.surface.Phi", lambda: on.core())):  # type: ignore[union-attr]  # with a surface
            if field in fields:
                step([field])
                try:
                    read()
                except ExpressionError as exc:
                    return None, [FieldProblem(field, str(exc))]
        step(fields or ["system"])
        return self.outline(), []


def _names_apart(cls: type, potential: PotentialSpec, info: ValidationInfo) -> PotentialSpec:
    """A surface's parameters and a potential's may not share a name (they are one list of values)."""
    if "surface" not in info.data:
        return potential  # the surface is refused already
    shared = sorted(set(info.data["surface"].parameters) & set(potential.parameter_values()))
    if shared:
        raise ValueError(f"{', '.join(shared)}: a parameter of the surface too; give the potential's and the "
                         "surface's parameters different names")
    return potential


def _potential_model(kind: str, pot: Potential) -> type[PotentialSpec]:
    return create_model(  # type: ignore[call-overload]  # the fields are the catalog's, as **kwargs
        f"{_camel(kind)}{_camel(pot.kind)}Potential",
        __base__=PotentialSpec,
        __doc__=pot.formula,
        kind=(Literal[pot.kind], ...),
        **{par.name: _parameter_field(par) for par in pot.parameters},
    )


def _system_model(kind: str) -> type[SystemSpec]:
    module = SYSTEMS[kind]
    allowed = [_potential_model(kind, pot) for pot in module.POTENTIALS.values()] + [_expression_model(kind)]
    potential_union = Annotated[Union[tuple(allowed)],  # type: ignore[valid-type]  # built at import  # noqa: UP007
                                Field(discriminator="kind")]
    default, default_kind = allowed[0], next(iter(module.POTENTIALS))

    def default_potential() -> PotentialSpec:
        return default(kind=default_kind)  # type: ignore[call-arg]  # kind: create_model's field

    extra: dict[str, Any] = {}
    surface_kind = KINDS[kind].surface
    if surface_kind:
        extra["surface"] = (SurfaceSpec, Field(description="the surface Phi(x) = 0 on which the centre moves"))
    return create_model(  # type: ignore[call-overload]  # the fields are the catalog's, as **kwargs
        f"{_camel(kind)}Spec",
        __base__=SystemSpec,
        __doc__=module.TITLE,
        __validators__=({"names_apart": field_validator("potential")(classmethod(_names_apart))}
                        if surface_kind else None),
        kind=(Literal[kind], ...),
        **{par.name: _parameter_field(par) for par in module.PARAMETERS},
        **extra,
        potential=(potential_union, Field(default_factory=default_potential,
                                          description=f"one of: {', '.join(module.POTENTIALS)}, {EXPRESSION} "
                                                      f"(default {list(module.POTENTIALS)[0]})")),
    )


SYSTEM_MODELS: dict[str, type[SystemSpec]] = {kind: _system_model(kind) for kind in SYSTEMS}
if TYPE_CHECKING:  # the union's members are built from the catalog at import: to a type checker, a SystemSpec
    AnySystemSpec: TypeAlias = SystemSpec
else:
    AnySystemSpec = Annotated[Union[tuple(SYSTEM_MODELS.values())], Field(discriminator="kind")]  # noqa: UP007


def system_spec(system_json: Mapping[str, Any]) -> SystemSpec:
    """The request model of a stored (already validated) request's ``system`` block, of any kind.

    Raises
    ------
    pydantic.ValidationError
        For a block no kind's model accepts (a job sent straight to the broker may carry anything).
    """
    return _system_spec(json.dumps(system_json, sort_keys=True))


@lru_cache(maxsize=64)
def _system_spec(system_text: str) -> SystemSpec:
    return _JOB_SYSTEM.validate_json(system_text)


def definition_of(system_json: Mapping[str, Any]) -> MechanicalSystem:
    """The core's definition of a stored (already validated) request's ``system`` block: its names,
    state, units and field (a user-written system's without Theorem 1's reduction, which only its job
    or ensemble needs). Remembered by the block's JSON: an export asks for units, widths and labels."""
    return _definition_of(json.dumps(system_json, sort_keys=True))


@lru_cache(maxsize=64)
def _definition_of(system_text: str) -> MechanicalSystem:
    spec = _system_spec(system_text)
    return spec.validation_definition() if type(spec) in USER_WRITTEN_MODELS.values() else spec.definition()


# --------------------------------------------------------------------------------------------------
# a generalized Chaplygin system of the user's own (jobs only)


class GeneralizedChaplyginSpec(SystemSpec):
    """A generalized Chaplygin system with two degrees of freedom (eq. 2704-7), as in POST /v1/hamiltonize:
    L(q, q_dot), S = a1(q) q1_dot + a2(q) q2_dot + b(q), an optional U(q), every constant a parameter with a
    value. Integrated in t, and in tau with its Hamiltonian form when Theorem 1 gives a reducing multiplier.
    ``lagrangian`` is the old name of ``L`` (still read, with a note in the answer: :mod:`schemas.deprecations`)."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [GENERALIZED_CHAPLYGIN_EXAMPLE]})
    renamed_state: ClassVar[dict[str, str]] = RENAMED_STATE
    former_fields: ClassVar[dict[str, str]] = RENAMED_FIELDS
    former_fields_at: ClassVar[str] = "system."

    kind: Literal["generalized_chaplygin"]
    coordinates: list[Annotated[str, Field(min_length=1, max_length=32)]] = Field(
        min_length=2, max_length=2, description="names of q1, q2 (the state vector q of the initial state)")
    velocities: list[Annotated[str, Field(min_length=1, max_length=32)]] = Field(
        min_length=2, max_length=2, description="names of the velocities q1_dot, q2_dot (the state vector q_dot)")
    parameters: dict[str, ParameterFloat] = Field(
        default_factory=dict, max_length=MAX_EXPRESSION_PARAMETERS,
        description="every constant of the expressions, by name, with its value")
    L: str = Field(min_length=1, max_length=MAX_EXPRESSION_LENGTH,
                   description="L(q, q_dot), a polynomial of degree 2 in the velocities (Theorem 1); formerly "
                               "`lagrangian` (still read, deprecated)")
    a1: str = Field(min_length=1, max_length=MAX_EXPRESSION_LENGTH,
                    description="S = a1(q) q1_dot + a2(q) q2_dot + b(q) (eq. 2704-7)")
    a2: str = Field(min_length=1, max_length=MAX_EXPRESSION_LENGTH)
    b: str = Field(min_length=1, max_length=MAX_EXPRESSION_LENGTH)
    potential: str | None = Field(None, max_length=MAX_EXPRESSION_LENGTH,
                                  description="U(q), subtracted from L (null: none, or already in L)")

    @field_validator("coordinates", "velocities", "parameters")
    @classmethod
    def _names(cls, value: Any, info: ValidationInfo) -> Any:
        field = info.field_name
        assert field is not None  # a field validator's info names its field
        order = ("coordinates", "velocities", "parameters")
        names = {k: tuple(info.data.get(k, ())) for k in order[:order.index(field)]}
        names[field] = tuple(value)
        return core_names_checked(value, field, lambda: gc.declared(*(names.get(k, ()) for k in order)))

    @field_validator("L", "a1", "a2", "b", "potential")
    @classmethod
    def _parsed(cls, text: str | None, info: ValidationInfo) -> str | None:
        if text is None or any(k not in info.data for k in ("coordinates", "velocities", "parameters")):
            return text  # the names are refused already
        return expression_checked(text, [*info.data["coordinates"], *info.data["velocities"],
                                         *info.data["parameters"]])

    def parameter_values(self) -> dict[str, Any]:
        return dict(self.parameters)

    def data(self) -> gc.ChaplyginData:
        """The core's parsed system."""
        return gc.chaplygin_data(self.L, tuple(self.coordinates), tuple(self.velocities), self.a1, self.a2,
                                 self.b, self.potential, tuple(self.parameters))

    def definition(self) -> MechanicalSystem:
        """The system with Theorem 1's measure, time and Hamiltonian form (symbolic work, up to 20 s)."""
        return gc.define(self.data())

    def validation_definition(self) -> MechanicalSystem:
        """The system without Theorem 1 (enough to check a request: names, state, the field at it)."""
        return gc.define(self.data(), reduce=False)

    def component_names(self) -> dict[str, list[str]]:
        return {"q": list(self.coordinates), "q_dot": list(self.velocities)}

    def expressions(self) -> list[tuple[str, str]]:
        return [(f"system.{field}", getattr(self, field)) for field in gc.EXPRESSION_FIELDS
                if getattr(self, field) is not None]

    def checked_definition(self, step: Step = no_step) -> tuple[MechanicalSystem | None, list[FieldProblem]]:
        step([field for field, _ in self.expressions()])
        try:
            self.data()
        except RefusedField as exc:
            return None, [FieldProblem(f, r) for f, r in exc.within("system").problems()]
        return self.validation_definition(), []


# --------------------------------------------------------------------------------------------------
# a Lagrangian system with constraints linear in the velocities (jobs only)


Name = Annotated[str, Field(min_length=1, max_length=32)]


class LagrangianSpec(SystemSpec):
    """A system given by its Lagrangian L(q, q_dot) in coordinates of one's own and constraints linear and
    homogeneous in the velocities (each written as sum_j a_j(q) q_j_dot, meaning = 0); the velocity of ``x``
    is ``x_dot``. The Lagrange-d'Alembert equations are derived with the multipliers eliminated."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [lag.EXAMPLE]})

    kind: Literal["lagrangian"]
    coordinates: list[Name] = Field(
        min_length=1, max_length=MAX_COORDINATES,
        description=f"names of the generalized coordinates q (1 to {MAX_COORDINATES}); their velocities are "
                    "'<name>_dot'")
    parameters: dict[str, ParameterFloat] = Field(
        default_factory=dict, max_length=MAX_EXPRESSION_PARAMETERS,
        description="every constant of L and the constraints, by name, with its value")
    L: str = Field(min_length=1, max_length=MAX_EXPRESSION_LENGTH,
                   description="the Lagrangian L(q, q_dot), a polynomial of degree 2 in the velocities with a regular "
                               "mass matrix d2L/dq_dot2 (a potential is part of it: L = T - U)")
    constraints: list[Annotated[str, Field(min_length=1, max_length=MAX_EXPRESSION_LENGTH)]] = Field(
        default_factory=list, max_length=MAX_COORDINATES - 1,
        description="each sum_j a_j(q) q_j_dot, meaning = 0 (linear and homogeneous in the velocities); fewer "
                    "than the coordinates")

    @field_validator("coordinates", "parameters")
    @classmethod
    def _names(cls, value: Any, info: ValidationInfo) -> Any:
        field = info.field_name
        assert field is not None  # a field validator's info names its field
        if field == "parameters" and "coordinates" not in info.data:
            return value  # the coordinates are refused already
        coordinates = tuple(value if field == "coordinates" else info.data["coordinates"])
        parameters = tuple(value) if field == "parameters" else ()
        return core_names_checked(value, field, lambda: lagrangian.declared(coordinates, parameters))

    @field_validator("L", "constraints")
    @classmethod
    def _parsed(cls, value: Any, info: ValidationInfo) -> Any:
        if any(k not in info.data for k in ("coordinates", "parameters")):
            return value  # the names are refused already
        names = ["t", *info.data["coordinates"], *(lagrangian.velocity_name(c) for c in info.data["coordinates"]),
                 *info.data["parameters"]]
        if info.field_name == "L":
            return expression_checked(value, names)
        for i, text in enumerate(value):
            expression_checked(text, names, entry=f"constraints[{i}]")
        return value

    def parameter_values(self) -> dict[str, Any]:
        return dict(self.parameters)

    def data(self) -> lagrangian.LagrangianData:
        """The core's parsed and checked system (raises :class:`nonholonomic.lagrangian.DataError`)."""
        return lagrangian.lagrangian_data(tuple(self.coordinates), self.L, tuple(self.constraints),
                                          tuple(self.parameters.items()))

    def definition(self) -> MechanicalSystem:
        """The system with its derived equations of motion and the structure search (symbolic work, cached)."""
        return lag.define(self.data())

    def validation_definition(self) -> MechanicalSystem:
        """The derived equations without the structure searches (units, labels and plots of a stored job)."""
        return lag.define(self.data(), reduce=False)

    def outline(self) -> MechanicalSystem:
        """Names, integrals, constraints and the plain elimination's field, in milliseconds
        (:func:`nonholonomic.systems.lagrangian.outline`): the derivation runs with the job."""
        return lag.outline(self.data())

    def state_problems(self, system: MechanicalSystem, parameters: Mapping[str, Any],
                       initial_state: Mapping[str, Sequence[float]], project: bool = False) -> list[FieldProblem]:
        """As the base class, the field at the state checked by numbers alone (M, A, h there: never a
        compiled kernel of the outline's field)."""
        data = self.data()

        def field_check(y: Any, p: Any) -> str | None:
            n = len(data.q)
            return field_problem(data, y[:n], y[n:], dict(zip(data.parameters, map(float, p))))

        return initial_state_problems(system, parameters, initial_state, project, field_check)

    def generic_definition(self) -> MechanicalSystem:
        """The definition an ensemble sweeping a parameter shares: only what holds for every value claimed."""
        return lag.define(self.data(), generic=True)

    def component_names(self) -> dict[str, list[str]]:
        return {"q": list(self.coordinates), "q_dot": [lagrangian.velocity_name(c) for c in self.coordinates]}

    def expressions(self) -> list[tuple[str, str]]:
        return [("system.L", self.L), *((f"system.constraints[{i}]", c) for i, c in enumerate(self.constraints))]

    def checked_definition(self, step: Step = no_step) -> tuple[MechanicalSystem | None, list[FieldProblem]]:
        fields = [field for field, _ in self.expressions()]
        step(fields)
        try:
            self.data()
            return self.outline(), []
        except RefusedField as exc:
            return None, [FieldProblem(f, r) for f, r in exc.within("system").problems()]


#: The request models of the kinds written by the user (each its own shape), by kind; every such kind of the registry
#: has one (checked below).
USER_WRITTEN_MODELS: dict[str, type[SystemSpec]] = {gc.KIND: GeneralizedChaplyginSpec, lag.KIND: LagrangianSpec}
_unmodelled = sorted(k for k, record in KINDS.items() if record.written_by_user and k not in USER_WRITTEN_MODELS)
if _unmodelled:
    raise TypeError(f"kinds written by the user without a request model in schemas.systems: {_unmodelled}")

#: What POST /v1/jobs takes as ``system``: every catalog kind, and every kind written by the user.
if TYPE_CHECKING:  # the union's members are built from the registry at import: to a type checker, a SystemSpec
    JobSystemSpec: TypeAlias = SystemSpec
else:
    JobSystemSpec = Annotated[Union[(*SYSTEM_MODELS.values(), *USER_WRITTEN_MODELS.values())],  # noqa: UP007
                              Field(discriminator="kind")]
_JOB_SYSTEM: TypeAdapter[SystemSpec] = TypeAdapter(JobSystemSpec)
