"""Requests and answers of the symbolic endpoints: ``POST /v1/brackets/verify`` and ``POST /v1/hamiltonize``.

Every expression is a string parsed by :mod:`nonholonomic.expressions` (a whitelist over Python's
AST; never eval): declared names, numbers, + − * / ** and named functions (sin, cos, sqrt ...).

The answer to a body is the same on every machine and at any load: the symbolic work is bounded by
deterministic work limits (``limits``: sympy operation counts, :mod:`nonholonomic.work_limits`), never by
seconds. ``budget_s`` is deprecated and ignored (the answer's ``deprecations`` says so).
"""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal

from pydantic import BaseModel, ConfigDict, Field, Strict, model_validator

from nonholonomic import work_limits
from nonholonomic.definition import MAX_PARAMETER_MAGNITUDE
from schemas.deprecations import RENAMED_FIELDS, FormerFieldNames

#: A named constant's value (as a system parameter's: beyond, the pointwise checks overflow).
Constant = Annotated[float, Strict(), Field(allow_inf_nan=False, ge=-MAX_PARAMETER_MAGNITUDE,
                                            le=MAX_PARAMETER_MAGNITUDE)]

Expression = Annotated[str, Field(min_length=1, max_length=2000, description="expression, e.g. 'x*y - z'")]
Name = Annotated[str, Field(min_length=1, max_length=32)]
Bounds = Annotated[list[Expression], Field(min_length=2, max_length=2, description="[min, max]")]
#: Upper bound of the deprecated ``budget_s`` (still validated, no longer used).
MAX_BUDGET_S = 30.0
#: How far a request may raise a work limit above its default.
MAX_LIMIT_FACTOR = 10
#: The note an answer carries when its request sent ``budget_s``.
BUDGET_S_DEPRECATED = ("budget_s is deprecated and ignored: verdicts are bounded by work limits (limits.max_proof_ops, "
                       "limits.max_integrate_ops, limits.max_tidy_ops: sympy operation counts), not seconds, so the "
                       "same body gets the same answer on every machine; it will be removed")

_BUDGET_S_DESCRIPTION = ("deprecated and ignored (validated as before: > 0, <= 30): the symbolic work is bounded by "
                         "`limits`, not by seconds; the answer's `deprecations` says so. It will be removed")
_DEPRECATIONS_DESCRIPTION = ("notes on deprecated request fields this request used (e.g. budget_s), each saying "
                             "what replaces it; empty when it used none")


class SymbolicLimits(BaseModel):
    """Deterministic limits of a request's symbolic work, in sympy operations (``count_ops``).

    A step past its limit is not tried: its verdict is undecided (a pointwise check decides where one
    exists) with a reason naming the limit, e.g. "not tried: 25,310 operations > max 20,000
    (max_proof_ops)". Raising a limit decides more, at a cost in CPU time that grows faster than the
    limit; the answer stays the same on every machine."""

    model_config = ConfigDict(extra="forbid")

    max_proof_ops: int = Field(
        work_limits.MAX_PROOF_OPS, ge=0, le=MAX_LIMIT_FACTOR * work_limits.MAX_PROOF_OPS,
        description="largest expression a symbolic identity proof is tried on (a Jacobiator, {C, x_i}, P_ij + P_ji, "
                    "the closedness condition and density equations of Theorem 1). Cost: expanding a numerator grows "
                    "faster than linearly in its size; at the default the known proofs take seconds, at 10x a proof "
                    "may take minutes and meet the service's safety cap (a 503)")
    max_integrate_ops: int = Field(
        work_limits.MAX_INTEGRATE_OPS, ge=0, le=MAX_LIMIT_FACTOR * work_limits.MAX_INTEGRATE_OPS,
        description="largest integrand given to sympy's integrate (Theorem 1's density by integration; past it the "
                    "line integral is left unevaluated). Cost: sympy's Risch and heuristic integrators have no bound "
                    "of their own; above the default an integral may run for minutes and meet the safety cap (a 503)")
    max_tidy_ops: int = Field(
        work_limits.MAX_TIDY_OPS, ge=0, le=MAX_LIMIT_FACTOR * work_limits.MAX_TIDY_OPS,
        description="largest expression cancelled and factored into a normal form (Theorem 1's G, w, V, A1, A2, B); "
                    "larger ones are kept equal but unshortened. Cost: factoring grows fast with the size; a "
                    "normal form makes the later steps cheaper, so raising it may also save time")

    def to_core(self) -> work_limits.WorkLimits:
        """These limits for the core."""
        return work_limits.WorkLimits(max_proof_ops=self.max_proof_ops, max_integrate_ops=self.max_integrate_ops,
                                      max_tidy_ops=self.max_tidy_ops)


class BracketVerifyRequest(BaseModel):
    """A Poisson bracket given by its matrix ``{x_i, x_j}`` in named variables."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{
        "variables": ["x", "y", "z"], "matrix": [["0", "z", "-y"], ["-z", "0", "x"], ["y", "-x", "0"]],
        "casimirs": {"x^2+y^2+z^2": "x**2 + y**2 + z**2"}}]})

    variables: list[Name] = Field(min_length=1, max_length=12)
    matrix: list[list[Expression]] = Field(description="matrix[i][j] = {variables[i], variables[j]}")
    casimirs: dict[Name, Expression] = Field(default_factory=dict, description="candidate Casimir functions by name")
    parameters: dict[Name, Constant] = Field(
        default_factory=dict, description="named constants: symbolic in the proofs, these values in pointwise checks")
    symbols: list[Name] = Field(default_factory=list, description="further names kept symbolic (no value)")
    limits: SymbolicLimits | None = Field(
        None, description="work limits of the symbolic checks (null: the defaults); only max_proof_ops applies here")
    budget_s: float | None = Field(None, gt=0, le=MAX_BUDGET_S, deprecated=True, description=_BUDGET_S_DESCRIPTION)

    @model_validator(mode="after")
    def _square(self) -> BracketVerifyRequest:
        n = len(self.variables)
        if len(self.matrix) != n or any(len(row) != n for row in self.matrix):
            raise ValueError(f"matrix must be {n}x{n} (one row and column per variable)")
        return self


class MonopoleRequest(BaseModel):
    """Where to integrate the gyroscopic 2-form S̄ dq₁∧dq₂ (text after eq. 2704-9)."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{
        "domain": [["0", "pi"], ["0", "2*pi"]], "shift": ["0", "c*N*cos(theta)"]}]})

    domain: list[Bounds] = Field(
        min_length=2, max_length=2,
        description="chart [[q1 min, q1 max], [q2 min, q2 max]] as constant expressions, e.g. [['0', 'pi'], "
                    "['0', '2*pi']] for Euler angles covering S^2")
    shift: list[Expression] | None = Field(
        None, min_length=2, max_length=2,
        description="W = [W1, W2] with p~ = p - W smooth fibre coordinates (e.g. after a Routh reduction); "
                    "expressions in the coordinates and constants, and N, the reducing multiplier found. "
                    "The integrated form is then S_bar + dW2/dq1 - dW1/dq2")


class HamiltonizeRequest(FormerFieldNames):
    """A generalized Chaplygin system with two degrees of freedom (eq. 2704-7). ``lagrangian`` is the old name
    of ``L`` (still read, with a note in the answer's ``deprecations``: :mod:`schemas.deprecations`)."""

    model_config = ConfigDict(extra="forbid")
    former_fields: ClassVar[dict[str, str]] = RENAMED_FIELDS

    L: Expression = Field(description="L(q1, q2, q1_dot, q2_dot), quadratic in the velocities; formerly "
                                      "`lagrangian` (still read, deprecated)")
    coordinates: list[Name] = Field(min_length=2, max_length=2)
    velocities: list[Name] = Field(min_length=2, max_length=2)
    a1: Expression = Field(description="S = a1(q) q1_dot + a2(q) q2_dot + b(q) (eq. 2704-7)")
    a2: Expression
    b: Expression
    potential: Expression | None = Field(None, description="U(q), if not already in the Lagrangian")
    parameters: dict[Name, Constant] = Field(default_factory=dict, description="values of the named constants")
    symbols: list[Name] = Field(default_factory=list, description="names kept symbolic (e.g. I1, I2, I3)")
    limits: SymbolicLimits | None = Field(None, description="work limits of the symbolic steps (null: the defaults)")
    budget_s: float | None = Field(None, gt=0, le=MAX_BUDGET_S, deprecated=True, description=_BUDGET_S_DESCRIPTION)
    monopole: MonopoleRequest | None = Field(
        None, description="integrate S_bar dq1^dq2 over a chart: exact (integral 0) or a monopole")


# --------------------------------------------------------------------------------------------------
# responses


class _Answer(BaseModel):
    model_config = ConfigDict(extra="forbid")


class AntisymmetryEntry(_Answer):
    """An entry of the matrix whose P_ij + P_ji is not (or not provably) zero."""

    entry: list[int] = Field(description="[i, j]")
    bracket: str
    sum: str = Field(description="P_ij + P_ji, expanded (cut at 200 characters)")
    status: Literal["non-zero", "undecided"]


class AntisymmetryCheck(_Answer):
    passed: bool
    method: Literal["symbolic", "pointwise"]
    residual: float | None = Field(description="max |P_ij + P_ji| / (|P_ij| + |P_ji|) at the sample points "
                                               "(null if not finite)")
    offending: list[AntisymmetryEntry]
    detail: str


class BracketCheck(_Answer):
    """A verdict (Jacobi identity, a Casimir) with how it was reached."""

    method: Literal["symbolic", "pointwise"]
    passed: bool
    residual: float | None = Field(description="pointwise relative residual |sum of terms| / sum |terms|, max over "
                                               "the sample points (null if not finite)")
    detail: str


class CasimirCheck(BracketCheck):
    name: str


class BracketRank(_Answer):
    values: list[int] = Field(description="rank of the matrix at each random point where it is finite")
    generic: int | None = Field(description="the largest rank seen")


class BracketVerifyResult(_Answer):
    """Answer to ``POST /v1/brackets/verify``."""

    variables: list[str]
    convention: str
    dimension: int
    antisymmetric: AntisymmetryCheck
    jacobi: BracketCheck
    casimirs: list[CasimirCheck]
    rank: BracketRank
    deprecations: list[str] = Field(default_factory=list, description=_DEPRECATIONS_DESCRIPTION)


class HamiltonizeBracket(_Answer):
    """The bracket of eq. 2704-9 in (q, p)."""

    name: str
    equation: str
    variables: list[str]
    matrix: list[list[str]]
    formula: str
    convention: str


class HamiltonizeVerification(_Answer):
    """Whether the τ-flow is Hamiltonian with the multiplier found."""

    method: Literal["symbolic", "pointwise"]
    residual: float | None = Field(description="max relative residual at the sample points (null if not finite)")
    passed: bool | None = Field(description="null when there is no multiplier to verify")
    detail: str
    pointwise_residual_brackets_py_convention: float | None = Field(None, description="null if not finite")
    symbolic: bool | None = None


class MonopoleResult(_Answer):
    """The integral of the gyroscopic 2-form S̄ dq₁∧dq₂ over the chart (exact iff 0)."""

    integral: float | None
    exact: bool | None
    detail: str
    absolute_integral: float | None = None
    error_estimate: float | None = None
    form: str | None = Field(None, description="the integrand")
    integral_S_bar: float | None = Field(None, description="with a shift: the chart integral of S_bar alone")
    symbolic: str | None = Field(None, description="sympy's exact integral, when it found one")


class HamiltonizeResult(_Answer):
    """Answer to ``POST /v1/hamiltonize``: Theorem 1 for the posted system (expressions as sympy strings)."""

    A1: str = Field(description="S = A1 P1 + A2 P2 + B (eq. 2704-10)")
    A2: str
    B: str
    measure_exists: bool | None = Field(description="null: undecided (`reason` says why, e.g. a work limit)")
    integrability_condition: str
    reason: str
    density: str | None
    reducing_multiplier: str | None
    S_bar: str | None = Field(description="S_bar = N B (ERRATA 6)")
    hamiltonian: str | None = Field(description="H_bar(q, p)")
    momenta: list[str]
    bracket: HamiltonizeBracket | None
    verification: HamiltonizeVerification
    monopole: MonopoleResult | None
    equations: dict[str, str]
    convention: str
    deprecations: list[str] = Field(default_factory=list, description=_DEPRECATIONS_DESCRIPTION)


class HamiltonizeExample(_Answer):
    """A ready-to-post ``POST /v1/hamiltonize`` body (add ``parameters`` for the constants if you like)."""

    L: str
    a1: str
    a2: str
    b: str
    coordinates: list[str]
    velocities: list[str]
    symbols: list[str]
    monopole: MonopoleRequest | None = None


class HamiltonizeExamples(_Answer):
    """``GET /v1/hamiltonize/examples``: by name (``veselova``, ``chaplygin_ball``)."""

    examples: dict[str, HamiltonizeExample]
