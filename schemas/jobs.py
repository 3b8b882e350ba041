"""Job requests and job views (``POST /v1/jobs``, ``GET /v1/jobs/{id}``)."""

from __future__ import annotations

from typing import Any, Literal, cast

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ModelWrapValidatorHandler,
    PrivateAttr,
    field_validator,
    model_validator,
)

from nonholonomic.definition import MechanicalSystem
from nonholonomic.evidence.claims import MAX_CLAIMS, claim_initial_problem, parse_claim
from nonholonomic.expressions import ExpressionError
from nonholonomic.initial_state import FieldProblem
from nonholonomic.numerics.integration import MACHINE_EPSILON, SCIPY_MIN_TOLERANCE
from nonholonomic.numerics.kernels import parameter_vector, state_vector
from nonholonomic.potentials import MAX_EXPRESSION_LENGTH
from nonholonomic.simulation import DEFAULT_CHECKS, available_checks
from schemas.analysis import LyapunovRequest, PoincareRequest
from schemas.periodic_orbits import PeriodicOrbitRequest
from schemas.report import PaperReport
from schemas.results import SimulationResultModel
from schemas.settings import get_settings
from schemas.systems import FiniteFloat, JobSystemSpec, StateVec, Step, no_step, state_renamed

JobStatus = Literal["queued", "running", "succeeded", "failed", "cancelled"]
JobCheck = Literal["integrals", "measure", "bracket", "euler_angles", "isomorphisms"]
TERMINAL_STATUSES: frozenset[str] = frozenset({"succeeded", "failed", "cancelled"})


def t_final_within_limit(cls: type, v: float) -> float:
    """``t_final`` up to the service's ``max_t_final`` (a field validator of jobs and ensembles)."""
    limit = get_settings().max_t_final
    if v > limit:
        raise ValueError(f"t_final = {v:g} exceeds this service's maximum {limit:g}")
    return v


#: Loosest accepted integrator tolerance (beyond, the evidence's drifts say nothing).
MAX_TOLERANCE = 1e-3


class IntegratorOptions(BaseModel):
    """Which engine integrates, at which tolerance."""

    model_config = ConfigDict(extra="forbid")

    engine: Literal["heyoka", "scipy"] = Field(
        "heyoka", description="heyoka: adaptive Taylor method (default); scipy: DOP853, an independent cross-check")
    tolerance: FiniteFloat | None = Field(
        None, ge=MACHINE_EPSILON, le=MAX_TOLERANCE,
        description=f"heyoka: relative/absolute tolerance in [machine epsilon {MACHINE_EPSILON:.7g}, "
                    f"{MAX_TOLERANCE:g}] (default machine epsilon: below it the engine cannot reach the tolerance "
                    f"and the job would not end); scipy: rtol = atol (default 1e-12, at least {SCIPY_MIN_TOLERANCE:g})")


class ClaimRequest(BaseModel):
    """A claimed integral ``I(x)`` in the state components and the system's parameter symbols."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z_][A-Za-z0-9_ ()-]*$",
                      description="what to call it in the result")
    expression: str = Field(min_length=1, max_length=MAX_EXPRESSION_LENGTH,
                            description="I as an expression, e.g. 'M1*gamma1 + M2*gamma2 + M3*gamma3'")


class JobRequest(BaseModel):
    """A simulation job: a system, an initial state, the sample grid and the evidence wanted."""

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={"examples": [{
            "system": {"kind": "chaplygin_ball", "inertia": [1.0, 2.0, 3.5], "D": 0.7,
                       "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}},
            "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]},
            "t_final": 20.0, "samples": 201, "checks": ["integrals", "measure"]}]},
    )

    system: JobSystemSpec
    initial_state: dict[str, StateVec] = Field(
        description="state vectors by name (the catalog lists them), e.g. {'M': [..], 'gamma': [..]}; "
                    "for the ball 'omega' may replace 'M'; for a system written by the user 'q' and 'q_dot', one "
                    "component per coordinate (a generalized_chaplygin system: two; its former 'qdot' is still "
                    "read, deprecated)")
    t_final: FiniteFloat = Field(gt=0, description="end of the integration interval [0, t_final], in s")
    samples: int = Field(201, ge=2, description="number of equally spaced sample times, both ends included")
    checks: list[JobCheck] = Field(
        default_factory=lambda: cast(list[JobCheck], list(DEFAULT_CHECKS)),  # the core's names are str
        description="evidence to compute (default integrals and measure); 'bracket' (Hamiltonian form after the "
                    "time substitution), 'euler_angles' (local forms) and 'isomorphisms' (the paper's maps to "
                    "e(3), Neumann, Clebsch, Veselova) where the catalog lists them")
    integrator: IntegratorOptions = Field(default_factory=IntegratorOptions)
    project_initial_state: bool = Field(
        False, description="move an initial state that is off a constraint (|gamma| = 1, (omega, gamma) = 0, "
                           "the quadric ...) onto it, and report what changed, instead of refusing it")
    poincare: PoincareRequest | None = Field(None, description="a Poincare section of the orbit (heyoka events)")
    lyapunov: LyapunovRequest | None = Field(None, description="the Lyapunov spectrum of the orbit (heyoka "
                                                               "variational equations, QR)")
    periodic_orbit: PeriodicOrbitRequest | None = Field(
        None, description="a periodic orbit of a Poincare section map, seeded by the initial state (Newton with the "
                          "monodromy), its multipliers and checks; with 'sweep', its continuation in a parameter")
    claims: list[ClaimRequest] = Field(
        default_factory=list, max_length=MAX_CLAIMS,
        description="candidate integrals or Casimirs of one's own, each checked along the trajectory (drift) and "
                    "symbolically (dI/dt = sum dI/dx_i f_i identically zero, within the work limits)")

    _t_final_limit = field_validator("t_final")(t_final_within_limit)
    #: Notes on the old names the request used (schemas.deprecations).
    _deprecations: list[str] = PrivateAttr(default_factory=list)

    @model_validator(mode="wrap")
    @classmethod
    def _old_names(cls, data: Any, handler: ModelWrapValidatorHandler[JobRequest]) -> Any:
        job = handler(data)
        job.initial_state, notes = state_renamed(job.system, job.initial_state, "initial_state.")
        job._deprecations = [*job.system.deprecations(), *notes]
        return job

    def deprecations(self) -> list[str]:
        """Notes on the deprecated names this request used, for the answer (empty if none)."""
        return list(self._deprecations)

    @field_validator("samples")
    @classmethod
    def _samples_limit(cls, v: int) -> int:
        limit = get_settings().max_samples
        if v > limit:
            raise ValueError(f"samples = {v} exceeds this service's maximum {limit}")
        return v

    def expressions(self) -> list[tuple[str, str]]:
        """Every expression the user wrote, by field path: the system's, the surface, the claims."""
        found = self.system.expressions()
        if self.poincare is not None:
            found.append(("poincare.surface", self.poincare.surface))
        if self.periodic_orbit is not None:
            found.append(("periodic_orbit.surface", self.periodic_orbit.surface))
        return found + [(f"claims[{i}].expression", claim.expression) for i, claim in enumerate(self.claims)]

    def problems(self, step: Step = no_step) -> list[FieldProblem]:
        """Violations only the physics can see: the expressions read by sympy, state names, |γ| = 1, the
        engine's tolerance range. ``step(fields)`` is told which fields each stage reads (a validation
        safety cap names them if it stops the check)."""
        system, found = self.system.checked_definition(step)
        if system is None:
            return found
        found = [FieldProblem(f"checks[{i}]", f"{check!r} is not available for {system.kind}; "
                                              f"available: {', '.join(available_checks(system))}")
                 for i, check in enumerate(self.checks) if check not in available_checks(system)]
        found += self.system.state_problems(system, self.system.parameter_values(),
                                            self.initial_state, self.project_initial_state)
        found += analysis_problems(system, self.integrator, self.t_final, self.poincare, self.lyapunov, step)
        if self.periodic_orbit is not None:
            step(["periodic_orbit.surface"])
            if self.integrator.engine != "heyoka":
                found.append(FieldProblem("integrator.engine", "periodic_orbit needs heyoka (events and the "
                                                               "variational equations)"))
            found += self.periodic_orbit.problems(system, self.system.parameter_values(),
                                                  self.t_final, self.integrator.tolerance)
        start = None if found or not self.claims else self._start(system)
        for i, claim in enumerate(self.claims):
            step([f"claims[{i}].expression"])
            try:
                parsed = parse_claim(system, claim.expression)
            except ExpressionError as exc:
                found.append(FieldProblem(f"claims[{i}].expression", str(exc)))
                continue
            why = None if start is None else claim_initial_problem(system, *start, parsed)
            if why is not None:
                found.append(FieldProblem(f"claims[{i}].expression", why))
        return found

    def _start(self, system: MechanicalSystem) -> tuple[np.ndarray, np.ndarray]:
        """The parameter vector and the initial state vector (a valid request's)."""
        p = parameter_vector(system, dict(self.system.parameter_values()))
        return p, state_vector(system, dict(self.initial_state), p)


def analysis_problems(system: MechanicalSystem, integrator: IntegratorOptions, t_final: float,
                      poincare: PoincareRequest | None, lyapunov: LyapunovRequest | None,
                      step: Step = no_step) -> list[FieldProblem]:
    """The integrator's tolerance range and the analysis blocks, checked against the system (``step`` is
    told when the surface is read)."""
    found = []
    tol = integrator.tolerance
    if integrator.engine == "scipy" and tol is not None and tol < SCIPY_MIN_TOLERANCE:
        found.append(FieldProblem("integrator.tolerance",
                                  f"scipy DOP853 cannot honour {tol:g}; use >= {SCIPY_MIN_TOLERANCE:g} or heyoka"))
    if integrator.engine != "heyoka" and (poincare or lyapunov):
        found.append(FieldProblem("integrator.engine", "poincare and lyapunov need heyoka (events and variational "
                                                       "equations)"))
    if poincare is not None:
        step(["poincare.surface"])
        found += poincare.problems(system)
    if lyapunov is not None:
        found += lyapunov.problems(system, t_final)
    return found


class JobAccepted(BaseModel):
    """Answer to ``POST /v1/jobs`` (202)."""

    id: str
    status: JobStatus
    location: str
    deprecations: list[str] = Field(
        default_factory=list, description="notes on deprecated names the request used (e.g. a generalized "
                                          "Chaplygin system's `lagrangian`, now `L`), each saying what replaces it")


class JobError(BaseModel):
    """Why a job failed."""

    type: str
    message: str


class JobView(BaseModel):
    """A job as ``GET /v1/jobs/{id}`` shows it; ``result`` is set once it succeeded."""

    id: str
    status: JobStatus
    progress: float = Field(ge=0, le=1)
    created_at: str
    request: dict[str, Any]
    result: SimulationResultModel | PaperReport | None = None
    error: JobError | None = None
