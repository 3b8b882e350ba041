"""Symbolic work for user-given systems: ``POST /v1/brackets/verify``.

User strings go through the safe parser only (:mod:`nonholonomic.expressions`). Every symbolic step
runs under the request's time budget; parse errors are 422 problems naming the field and position.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import sympy as sp
from fastapi import APIRouter

from schemas.problems import FieldError
from schemas.symbolic import BracketVerifyRequest
from service.errors import invalid_request

router = APIRouter(tags=["symbolic"])


def _declare(names: Sequence[str], field: str) -> dict[str, sp.Symbol]:
    from nonholonomic.expressions import ExpressionError, declare_symbols

    try:
        return declare_symbols(list(names))
    except ExpressionError as exc:
        raise invalid_request([FieldError(field=field, reason=exc.reason)]) from None


def _parse(text: str, symbols: dict[str, sp.Symbol], field: str) -> sp.Expr:
    from nonholonomic.expressions import ExpressionError, parse_expression

    try:
        return parse_expression(text, symbols)
    except ExpressionError as exc:
        raise invalid_request([FieldError(field=field, reason=str(exc))]) from None


@router.post("/v1/brackets/verify", summary="Jacobi identity, Casimirs and rank of a user-given bracket")
def verify_bracket(request: BracketVerifyRequest) -> dict[str, Any]:
    from nonholonomic.evidence.brackets import verify_user_bracket

    symbols = _declare(request.variables + list(request.parameters) + request.symbols, "variables")
    matrix = sp.Matrix([[_parse(entry, symbols, f"matrix[{i}][{j}]") for j, entry in enumerate(row)]
                        for i, row in enumerate(request.matrix)])
    casimirs = {name: _parse(text, symbols, f"casimirs.{name}") for name, text in request.casimirs.items()}
    try:
        report = verify_user_bracket([symbols[v] for v in request.variables], matrix, casimirs,
                                     {symbols[k]: v for k, v in request.parameters.items()}, budget_s=request.budget_s)
    except ValueError as exc:
        raise invalid_request([FieldError(field="matrix", reason=str(exc))]) from None
    return {"variables": request.variables, "convention": "matrix[i][j] = {x_i, x_j}", **report}
