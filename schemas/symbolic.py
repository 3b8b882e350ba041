"""Requests and answers of the symbolic endpoints: ``POST /v1/brackets/verify`` and ``POST /v1/hamiltonize``.

Every expression is a string parsed by :mod:`nonholonomic.expressions` (a whitelist over Python's
AST; never eval): declared names, numbers, + − * / ** and named functions (sin, cos, sqrt ...).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, Strict, model_validator

from nonholonomic.definition import MAX_PARAMETER_MAGNITUDE

#: A named constant's value (as a system parameter's: beyond, the pointwise checks overflow).
Constant = Annotated[float, Strict(), Field(allow_inf_nan=False, ge=-MAX_PARAMETER_MAGNITUDE,
                                            le=MAX_PARAMETER_MAGNITUDE)]

Expression = Annotated[str, Field(min_length=1, max_length=2000, description="expression, e.g. 'x*y - z'")]
Name = Annotated[str, Field(min_length=1, max_length=32)]
Bounds = Annotated[list[Expression], Field(min_length=2, max_length=2, description="[min, max]")]
#: Upper bound on the seconds a request may grant to symbolic work.
MAX_BUDGET_S = 30.0


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
    budget_s: float = Field(10.0, gt=0, le=MAX_BUDGET_S, description="seconds allowed for each symbolic proof")

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


class HamiltonizeRequest(BaseModel):
    """A generalized Chaplygin system with two degrees of freedom (eq. 2704-7)."""

    model_config = ConfigDict(extra="forbid")

    lagrangian: Expression = Field(description="L(q1, q2, q1dot, q2dot), quadratic in the velocities")
    coordinates: list[Name] = Field(min_length=2, max_length=2)
    velocities: list[Name] = Field(min_length=2, max_length=2)
    a1: Expression = Field(description="S = a1(q) q1dot + a2(q) q2dot + b(q) (eq. 2704-7)")
    a2: Expression
    b: Expression
    potential: Expression | None = Field(None, description="U(q), if not already in the Lagrangian")
    parameters: dict[Name, Constant] = Field(default_factory=dict, description="values of the named constants")
    symbols: list[Name] = Field(default_factory=list, description="names kept symbolic (e.g. I1, I2, I3)")
    budget_s: float = Field(20.0, gt=0, le=MAX_BUDGET_S)
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
    measure_exists: bool | None = Field(description="null: undecided within the budget")
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


class HamiltonizeExample(_Answer):
    """A ready-to-post ``POST /v1/hamiltonize`` body (add ``parameters`` for the constants if you like)."""

    lagrangian: str
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
