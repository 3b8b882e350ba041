"""Symbolic work for user-given systems: ``POST /v1/brackets/verify`` and ``POST /v1/hamiltonize``.

User strings go through the safe parser only (:mod:`nonholonomic.expressions`). Every symbolic step
runs under the request's time budget; parse errors are 422 problems naming the field and position.
"""

from __future__ import annotations

import ast
from collections.abc import Sequence
from typing import Any

import sympy as sp
from fastapi import APIRouter

from schemas.problems import TIMEOUT, FieldError
from schemas.symbolic import (
    BracketVerifyRequest,
    BracketVerifyResult,
    HamiltonizeExamples,
    HamiltonizeRequest,
    HamiltonizeResult,
)
from service.errors import INVALID, ProblemError, invalid_request, problem_responses
from service.openapi import operation_id

router = APIRouter(tags=["symbolic"], generate_unique_id_function=operation_id)
#: The problems of the two symbolic routes.
_ERRORS = problem_responses({408: "the symbolic work is still running at budget_s + 30 s; it was stopped",
                             422: INVALID + " (parse errors name the field and position)"})


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


@router.post("/v1/brackets/verify", operation_id="symbolic-brackets-verify", response_model=BracketVerifyResult,
             response_model_exclude_unset=True, responses=_ERRORS,
             summary="Jacobi identity, Casimirs and rank of a user-given bracket")
def verify_bracket(request: BracketVerifyRequest) -> dict[str, Any]:
    from nonholonomic.evidence.brackets import verify_user_bracket

    symbols = _declare(request.variables + list(request.parameters) + request.symbols, "variables")
    matrix = sp.Matrix([[_parse(entry, symbols, f"matrix[{i}][{j}]") for j, entry in enumerate(row)]
                        for i, row in enumerate(request.matrix)])
    casimirs = {name: _parse(text, symbols, f"casimirs.{name}") for name, text in request.casimirs.items()}
    try:
        report = _isolated(verify_user_bracket, ([symbols[v] for v in request.variables], matrix, casimirs,
                                                 {symbols[k]: v for k, v in request.parameters.items()},
                                                 request.budget_s), request.budget_s)
    except ValueError as exc:
        raise invalid_request([FieldError(field="matrix", reason=str(exc))]) from None
    return {"variables": request.variables, "convention": "matrix[i][j] = {x_i, x_j}", **report}


def _isolated(fn: Any, args: tuple[Any, ...], budget_s: float) -> Any:
    """``fn(*args)`` in a child process (:mod:`service.isolated`): nothing it starts outlives the request."""
    from service.isolated import GRACE_S, IsolatedTimeout, run_isolated

    try:
        return run_isolated(fn, args, budget_s + GRACE_S)
    except IsolatedTimeout as exc:
        raise ProblemError(408, "Symbolic work timed out", f"{exc}; lower the expressions' size or raise budget_s",
                           TIMEOUT) from None


def _hamiltonize_json(args: tuple[Any, ...], kwargs: dict[str, Any]) -> dict[str, Any]:
    """Theorem 1 for a user's system, as JSON (runs in the child process)."""
    from nonholonomic.reducing_multiplier import hamiltonize as reduce

    return reduce(*args, **kwargs).to_json()


@router.post("/v1/hamiltonize", operation_id="symbolic-hamiltonize", response_model=HamiltonizeResult,
             response_model_exclude_unset=True, responses=_ERRORS,
             summary="Reducing multiplier, bracket and Hamiltonian of a 2-DOF Chaplygin system")
def hamiltonize(request: HamiltonizeRequest) -> dict[str, Any]:
    names = request.coordinates + request.velocities + list(request.parameters) + request.symbols
    symbols = _declare(names, "coordinates")
    parsed = {field: _parse(getattr(request, field), symbols, field) for field in ("lagrangian", "a1", "a2", "b")}
    potential = None if request.potential is None else _parse(request.potential, symbols, "potential")
    domain, shift, multiplier = _monopole(request, symbols)
    args = (parsed["lagrangian"], tuple(symbols[q] for q in request.coordinates),
            tuple(symbols[v] for v in request.velocities), parsed["a1"], parsed["a2"], parsed["b"], potential,
            {symbols[k]: v for k, v in request.parameters.items()})
    kwargs = {"budget_s": request.budget_s, "domain": domain, "shift": shift, "multiplier_symbol": multiplier}
    try:
        return _isolated(_hamiltonize_json, (args, kwargs), request.budget_s)  # type: ignore[no-any-return]
    except ValueError as exc:
        raise invalid_request([FieldError(field="lagrangian", reason=str(exc))]) from None


#: The name standing for the reducing multiplier N in ``monopole.shift``.
MULTIPLIER_NAME = "N"


def _monopole(request: HamiltonizeRequest, symbols: dict[str, sp.Symbol]) -> tuple[Any, Any, sp.Symbol | None]:
    """The chart (floats), the shift W (sympy, may contain N) and N's symbol of ``request.monopole``."""
    spec = request.monopole
    if spec is None:
        return None, None, None
    domain = []
    for i, pair in enumerate(spec.domain):
        bounds = []
        for j, text in enumerate(pair):
            value = _parse(text, {}, f"monopole.domain[{i}][{j}]")
            if not (value.is_number and value.is_real and value.is_finite):
                raise invalid_request([FieldError(field=f"monopole.domain[{i}][{j}]",
                                                  reason="must be a finite real constant (numbers and pi)")])
            bounds.append(float(value))
        if not bounds[0] < bounds[1]:
            raise invalid_request([FieldError(field=f"monopole.domain[{i}]",
                                              reason=f"the lower bound {bounds[0]:g} must be below the upper {bounds[1]:g}")])
        domain.append((bounds[0], bounds[1]))
    if spec.shift is None:
        return tuple(domain), None, None
    if MULTIPLIER_NAME in symbols:
        raise invalid_request([FieldError(field="monopole.shift", reason=(
            f"'{MULTIPLIER_NAME}' stands for the reducing multiplier in the shift; rename the declared name "
            f"'{MULTIPLIER_NAME}'"))])
    N = sp.Symbol(MULTIPLIER_NAME, real=True)
    allowed = {name: symbols[name] for name in request.coordinates + list(request.parameters) + request.symbols}
    shift = tuple(_parse(text, {**allowed, MULTIPLIER_NAME: N}, f"monopole.shift[{k}]") for k, text in enumerate(spec.shift))
    return tuple(domain), shift, N


def _free_names(*texts: str) -> list[str]:
    """Names used in expression strings (read with ast.parse, never evaluated)."""
    from nonholonomic.expressions import ALLOWED_FUNCTIONS

    found = {node.id for text in texts for node in ast.walk(ast.parse(text, mode="eval")) if isinstance(node, ast.Name)}
    return sorted(found - set(ALLOWED_FUNCTIONS))


@router.get("/v1/hamiltonize/examples", operation_id="symbolic-hamiltonize-examples",
            response_model=HamiltonizeExamples, response_model_exclude_unset=True,
            summary="Worked examples: Veselova and Chaplygin's ball in Euler angles")
def hamiltonize_examples() -> dict[str, Any]:
    from nonholonomic.local_forms import (
        BALL_MONOPOLE_CHART,
        chaplygin_ball_generalized_chaplygin,
        veselova_generalized_chaplygin,
    )

    examples = {}
    for name, build in (("veselova", veselova_generalized_chaplygin), ("chaplygin_ball", chaplygin_ball_generalized_chaplygin)):
        spec = build()
        coordinates, velocities = spec["coordinates"].split(","), spec["velocities"].split(",")
        fields = {k: spec[k] for k in ("lagrangian", "a1", "a2", "b")}
        used = _free_names(*fields.values())
        examples[name] = {**fields, "coordinates": coordinates, "velocities": velocities,
                          "symbols": [n for n in used if n not in coordinates + velocities]}
    examples["chaplygin_ball"]["monopole"] = BALL_MONOPOLE_CHART
    return {"examples": examples}
