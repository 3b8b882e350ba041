"""Symbolic work for user-given systems: ``POST /v1/brackets/verify`` and ``POST /v1/hamiltonize``.

User strings go through the safe parser only (:mod:`nonholonomic.expressions`); parse errors are 422
problems naming the field and position. Every symbolic step runs to its end within the request's
deterministic work limits (``limits``, :mod:`nonholonomic.work_limits`: sympy operation counts), so the
same body gets the same answer on every machine and at any load, and every answer is remembered
(:mod:`workers.disk_memo`). ``budget_s`` is deprecated and ignored: the answer's ``deprecations`` says so.

The clock is only the machine's safety cap (:func:`safety_cap_s`, from the environment variable
``NONHOLONOMIC_SYMBOLIC_REQUEST_SAFETY_CAP_S``, default :data:`DEFAULT_SAFETY_CAP_S`): a symbolic step still
running past it in the child process (:class:`nonholonomic.bounded.SafetyCapExceeded`), or a child still
running past it plus :data:`service.isolated.GRACE_S`, is a 503 with ``Retry-After``: a failure of the
machine, never a verdict on the question, and never a 422.
"""

from __future__ import annotations

import ast
import logging
import math
import os
from collections.abc import Sequence
from typing import Any

import sympy as sp
from fastapi import APIRouter, Request, Response
from starlette.concurrency import run_in_threadpool

from nonholonomic.numerics.overflow import NUMERIC_ERRORS, overflowing_fields
from nonholonomic.refusals import RefusedField, RefusedFields
from schemas.problems import OVERLOADED, FieldError
from schemas.settings import Settings, get_settings
from schemas.symbolic import (
    BUDGET_S_DEPRECATED,
    BracketVerifyRequest,
    BracketVerifyResult,
    HamiltonizeExamples,
    HamiltonizeRequest,
    HamiltonizeResult,
)
from service.errors import INVALID, ProblemError, invalid_request, problem_responses
from service.openapi import operation_id

log = logging.getLogger(__name__)
router = APIRouter(tags=["symbolic"], generate_unique_id_function=operation_id)
#: The environment variable of the symbolic routes' safety cap (seconds, > 0).
SAFETY_CAP_ENV = "NONHOLONOMIC_SYMBOLIC_REQUEST_SAFETY_CAP_S"
#: Seconds a symbolic request's child process may work when :data:`SAFETY_CAP_ENV` is not set.
DEFAULT_SAFETY_CAP_S = 120.0
#: The problems of the two symbolic routes.
_ERRORS = problem_responses({
    422: INVALID + " (parse errors name the field and position; too many expressions or characters)",
    503: "the symbolic pool and its wait queue are full, or the symbolic work outlived the machine's safety cap "
         f"({SAFETY_CAP_ENV}, default {DEFAULT_SAFETY_CAP_S:g} s: not a verdict); `Retry-After` says when to retry"})


class SafetyCapped(RuntimeError):
    """A symbolic step outlived the safety cap in the child (picklable form of
    :class:`nonholonomic.bounded.SafetyCapExceeded`): answered as a 503."""


def safety_cap_s() -> float:
    """Seconds a symbolic request may work: :data:`SAFETY_CAP_ENV` if it holds a positive number, else
    :data:`DEFAULT_SAFETY_CAP_S` (read per request)."""
    raw = os.environ.get(SAFETY_CAP_ENV, "").strip()
    if not raw:
        return DEFAULT_SAFETY_CAP_S
    try:
        value = float(raw)
    except ValueError:
        value = float("nan")
    if not (math.isfinite(value) and value > 0):
        log.warning("%s=%r is not a positive number of seconds: using %g s", SAFETY_CAP_ENV, raw, DEFAULT_SAFETY_CAP_S)
        return DEFAULT_SAFETY_CAP_S
    return value


def _declare(names: Sequence[str], field: str) -> dict[str, sp.Symbol]:
    from nonholonomic.expressions import ExpressionError, declare_symbols

    try:
        return declare_symbols(list(names))
    except ExpressionError as exc:
        raise RefusedField(field, exc.reason) from None


def _parse(text: str, symbols: dict[str, sp.Symbol], field: str) -> sp.Expr:
    """``text`` parsed, with a first derivative that is a function: every field is differentiated (the
    Jacobi identity, Casimirs, Theorem 1), and sign's derivative, a Dirac delta, cannot be evaluated."""
    from nonholonomic.expressions import ExpressionError, differentiable, parse_expression

    try:
        return differentiable(parse_expression(text, symbols), "the checks differentiate it", order=1)
    except ExpressionError as exc:
        raise RefusedField(field, str(exc)) from None


def _expressions(request: BracketVerifyRequest | HamiltonizeRequest) -> list[tuple[str, str]]:
    """Every expression of a request with its field."""
    if isinstance(request, BracketVerifyRequest):
        return ([(f"matrix[{i}][{j}]", e) for i, row in enumerate(request.matrix) for j, e in enumerate(row)]
                + [(f"casimirs.{name}", e) for name, e in request.casimirs.items()])
    found = [(f, getattr(request, f)) for f in ("L", "a1", "a2", "b", "potential") if getattr(request, f)]
    if request.monopole is not None:
        found += [(f"monopole.domain[{i}][{j}]", e) for i, pair in enumerate(request.monopole.domain)
                  for j, e in enumerate(pair)]
        found += [(f"monopole.shift[{k}]", e) for k, e in enumerate(request.monopole.shift or [])]
    return found


def _check_size(request: BracketVerifyRequest | HamiltonizeRequest, settings: Settings) -> None:
    """At most ``max_symbolic_expressions`` expressions and ``max_symbolic_characters`` characters (422)."""
    found = _expressions(request)
    field = "casimirs" if isinstance(request, BracketVerifyRequest) and request.casimirs else (
        "matrix" if isinstance(request, BracketVerifyRequest) else "body")
    errors = []
    if len(found) > settings.max_symbolic_expressions:
        errors.append(FieldError(field=field, reason=(
            f"{len(found)} expressions in one request; at most {settings.max_symbolic_expressions} "
            "(NONHOLONOMIC_MAX_SYMBOLIC_EXPRESSIONS)")))
    characters = sum(len(text) for _, text in found)
    if characters > settings.max_symbolic_characters:
        errors.append(FieldError(field=field, reason=(
            f"{characters} characters of expressions in one request; at most {settings.max_symbolic_characters} "
            "(NONHOLONOMIC_MAX_SYMBOLIC_CHARACTERS)")))
    if errors:
        raise invalid_request(errors)


def _deprecations(request: BracketVerifyRequest | HamiltonizeRequest) -> list[str]:
    """Notes on the deprecated fields the request sent (``budget_s``; ``lagrangian``, now ``L``)."""
    renamed = request.deprecations() if isinstance(request, HamiltonizeRequest) else []
    return [*([BUDGET_S_DEPRECATED] if "budget_s" in request.model_fields_set else []), *renamed]


#: RFC 9211's ``Cache-Status`` of a symbolic answer: read back, or computed and stored.
CACHE_HIT, CACHE_MISS = "nonholonomic; hit", "nonholonomic; fwd=miss"


async def _run(http: Request, fn: Any, request: BracketVerifyRequest | HamiltonizeRequest,
               response: Response) -> Any:
    """``fn(payload)`` in a child process (:mod:`service.isolated`), holding a slot of the symbolic pool
    (:mod:`service.admission`); the child's problems become 422s, work past the safety cap a 503. Every
    answer is deterministic (work limits, no clock), so every answer is remembered
    (:mod:`workers.disk_memo`): the same body is then answered at once."""
    from nonholonomic import memo
    from service.isolated import GRACE_S, IsolatedTimeout, run_isolated
    from workers.disk_memo import response_fingerprint

    payload = request.model_dump()
    deprecations = _deprecations(request)
    # the same body (budget_s aside: it decides nothing), the same code and libraries: the same answer
    same = ({k: v for k, v in payload.items() if k != "budget_s"}, deprecations)
    key = (memo.key_of("symbolic-response", (fn.__name__, same, response_fingerprint()))
           if memo.installed() else None)
    if key is not None:
        found, answer = await run_in_threadpool(memo.recall, key)
        if found:
            response.headers["Cache-Status"] = CACHE_HIT
            return answer
    cap = safety_cap_s()
    pool = http.app.state.symbolic_pool
    async with pool.slot():
        try:
            answer = await run_in_threadpool(run_isolated, _in_child, (fn, payload, cap), cap + GRACE_S)
        except (IsolatedTimeout, SafetyCapped) as exc:
            retry = max(pool.retry_after_s(), math.ceil(cap))
            raise ProblemError(
                503, "Symbolic work past the safety cap",
                f"{exc}. This is the machine's safety cap ({cap:g} s, {SAFETY_CAP_ENV}), not a verdict on the "
                f"question: the machine may be overloaded; retry after {retry} s (the same body gets the same "
                "answer), or lower `limits` to try less", OVERLOADED, headers={"Retry-After": str(retry)}) from None
    answer = {**answer, "deprecations": deprecations}
    if key is not None:
        await run_in_threadpool(memo.keep, key, answer)
    response.headers["Cache-Status"] = CACHE_MISS + ("; stored" if key is not None else "")
    return answer


def _in_child(fn: Any, payload: dict[str, Any], cap: float) -> Any:
    """``fn(payload)`` in the child, every symbolic step waited for at most ``cap`` seconds
    (:func:`nonholonomic.bounded.set_safety_cap`); a step past it is :class:`SafetyCapped`."""
    from nonholonomic import bounded

    bounded.set_safety_cap(cap)
    try:
        return fn(payload)
    except bounded.SafetyCapExceeded as exc:
        raise SafetyCapped(str(exc)) from None


def _limits(request: BracketVerifyRequest | HamiltonizeRequest) -> Any:
    from nonholonomic import work_limits

    return work_limits.DEFAULT if request.limits is None else request.limits.to_core()


def _verify_in_child(payload: dict[str, Any]) -> dict[str, Any]:
    """The bracket checks of a request (runs in the child)."""
    from nonholonomic.evidence.brackets import verify_user_bracket

    request = BracketVerifyRequest.model_validate(payload)
    symbols = _declare(request.variables + list(request.parameters) + request.symbols, "variables")
    matrix = sp.Matrix([[_parse(entry, symbols, f"matrix[{i}][{j}]") for j, entry in enumerate(row)]
                        for i, row in enumerate(request.matrix)])
    casimirs = {name: _parse(text, symbols, f"casimirs.{name}") for name, text in request.casimirs.items()}
    try:
        report = verify_user_bracket([symbols[v] for v in request.variables], matrix, casimirs,
                                     {symbols[k]: v for k, v in request.parameters.items()}, limits=_limits(request))
    except RefusedField:
        raise
    except ValueError as exc:
        raise RefusedField("matrix", str(exc)) from None
    return {"variables": request.variables, "convention": "matrix[i][j] = {x_i, x_j}", **report}


@router.post("/v1/brackets/verify", operation_id="symbolic-brackets-verify", response_model=BracketVerifyResult,
             response_model_exclude_unset=True, responses=_ERRORS,
             summary="Jacobi identity, Casimirs and rank of a user-given bracket")
async def verify_bracket(request: BracketVerifyRequest, http: Request, response: Response) -> dict[str, Any]:
    _check_size(request, get_settings())
    return await _run(http, _verify_in_child, request, response)


def _hamiltonize_in_child(payload: dict[str, Any]) -> dict[str, Any]:
    """Theorem 1 for a user's system, as JSON (runs in the child)."""
    from nonholonomic.hamiltonization.reducing_multiplier import hamiltonize as reduce

    request = HamiltonizeRequest.model_validate(payload)
    names = request.coordinates + request.velocities + list(request.parameters) + request.symbols
    symbols = _declare(names, "coordinates")
    parsed = {field: _parse(getattr(request, field), symbols, field) for field in ("L", "a1", "a2", "b")}
    potential = None if request.potential is None else _parse(request.potential, symbols, "potential")
    domain, shift, multiplier = _monopole(request, symbols)
    args = (parsed["L"], tuple(symbols[q] for q in request.coordinates),
            tuple(symbols[v] for v in request.velocities), parsed["a1"], parsed["a2"], parsed["b"], potential,
            {symbols[k]: v for k, v in request.parameters.items()})
    kwargs = {"domain": domain, "shift": shift, "multiplier_symbol": multiplier, "limits": _limits(request)}
    variables = [symbols[n] for n in (*request.coordinates, *request.velocities)]
    values = {symbols[k]: float(v) for k, v in request.parameters.items()}
    # First, in floats at the sample points (milliseconds): an expression whose value overflows there cannot
    # be checked numerically, and sympy would spend minutes on it before saying so (a tower of exp in b).
    overflowing = overflowing_fields({**parsed, "potential": potential}, variables, values)
    if overflowing:
        raise RefusedFields(overflowing)
    try:
        return reduce(*args, **kwargs).to_json()
    except RefusedField:
        raise
    except NUMERIC_ERRORS as exc:  # past the float range or the memory, though none overflows at the probes above
        why = (f"evaluating the expressions failed ({type(exc).__name__}): one of them grows too fast to be evaluated "
               "or checked")
        raise RefusedFields([(field, why) for field in ("L", "a1", "a2", "b")]) from None
    except ValueError as exc:
        raise RefusedField("L", str(exc)) from None


@router.post("/v1/hamiltonize", operation_id="symbolic-hamiltonize", response_model=HamiltonizeResult,
             response_model_exclude_unset=True, responses=_ERRORS,
             summary="Reducing multiplier, bracket and Hamiltonian of a 2-DOF Chaplygin system")
async def hamiltonize(request: HamiltonizeRequest, http: Request, response: Response) -> dict[str, Any]:
    _check_size(request, get_settings())
    return await _run(http, _hamiltonize_in_child, request, response)


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
                raise RefusedField(f"monopole.domain[{i}][{j}]", "must be a finite real constant (numbers and pi)")
            bounds.append(float(value))
        if not bounds[0] < bounds[1]:
            raise RefusedField(f"monopole.domain[{i}]",
                               f"the lower bound {bounds[0]:g} must be below the upper {bounds[1]:g}")
        domain.append((bounds[0], bounds[1]))
    if spec.shift is None:
        return tuple(domain), None, None
    if MULTIPLIER_NAME in symbols:
        raise RefusedField("monopole.shift", (
            f"'{MULTIPLIER_NAME}' stands for the reducing multiplier in the shift; rename the declared name "
            f"'{MULTIPLIER_NAME}'"))
    N = sp.Symbol(MULTIPLIER_NAME, real=True)
    allowed = {name: symbols[name] for name in request.coordinates + list(request.parameters) + request.symbols}
    shift = tuple(_parse(text, {**allowed, MULTIPLIER_NAME: N}, f"monopole.shift[{k}]")
                  for k, text in enumerate(spec.shift))
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
    from nonholonomic.hamiltonization.local_forms import (
        BALL_MONOPOLE_CHART,
        chaplygin_ball_generalized_chaplygin,
        veselova_generalized_chaplygin,
    )

    examples: dict[str, dict[str, Any]] = {}
    for name, build in (("veselova", veselova_generalized_chaplygin),
                        ("chaplygin_ball", chaplygin_ball_generalized_chaplygin)):
        spec = build()
        coordinates, velocities = spec["coordinates"].split(","), spec["velocities"].split(",")
        fields = {k: spec[k] for k in ("L", "a1", "a2", "b")}
        used = _free_names(*fields.values())
        examples[name] = {**fields, "coordinates": coordinates, "velocities": velocities,
                          "symbols": [n for n in used if n not in coordinates + velocities]}
    examples["chaplygin_ball"]["monopole"] = BALL_MONOPOLE_CHART
    return {"examples": examples}
