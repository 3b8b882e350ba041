"""Requests of the symbolic endpoints: ``POST /v1/brackets/verify`` and ``POST /v1/hamiltonize``.

Every expression is a string parsed by :mod:`nonholonomic.expressions` (a whitelist over Python's
AST; never eval): declared names, numbers, + − * / ** and named functions (sin, cos, sqrt ...).
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, model_validator

from schemas.systems import FiniteFloat

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
    parameters: dict[Name, FiniteFloat] = Field(
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
    parameters: dict[Name, FiniteFloat] = Field(default_factory=dict)
    symbols: list[Name] = Field(default_factory=list, description="names kept symbolic (e.g. I1, I2, I3)")
    budget_s: float = Field(20.0, gt=0, le=MAX_BUDGET_S)
    monopole: MonopoleRequest | None = Field(
        None, description="integrate S_bar dq1^dq2 over a chart: exact (integral 0) or a monopole")
