"""A request's user expressions read and checked off the event loop, refused only by deterministic measures.

FastAPI reads a body on the event loop, so the request models keep only cheap checks of an expression
(characters, length, syntax, whitelist, names: :func:`nonholonomic.expressions.check_expression`).
Before sympy reads anything, every expression is measured from its syntax tree
(:func:`nonholonomic.expressions.size.size_problem`: the monomials it multiplies out to, how deeply its
functions nest); past a limit the answer is a 422 naming the field, the measure and the limit, the same on
every machine at any load. What sympy then does with the expressions (building U, Φ, L ...; a Poincaré
surface's translation for heyoka; a claim; a user's Lagrangian is only parsed and outlined here, its
equations derived with the job) runs in a child process (:func:`service.isolated.run_isolated`) holding a
slot of the symbolic pool (:class:`service.admission.SymbolicPool`), to its end: no clock decides a
refusal. ``validation_safety_cap_s`` is only a safety cap: a child still reading past it is killed and the
answer is a 503 with ``Retry-After`` saying so (a failure of the machine, never a 422); a full pool
answers 503 with ``Retry-After`` too.

A request without user expressions (built-in systems and potentials), or whose expressions are bare
names (a surface ``gamma3``), is checked in a thread of the API process, as before: no process per job.
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from typing import Any

from fastapi import Request
from pydantic import ValidationError
from starlette.concurrency import run_in_threadpool

from nonholonomic.expressions.size import size_problem
from nonholonomic.numerics.overflow import NUMERIC_ERRORS, numeric_problems
from schemas.ensembles import EnsembleRequest
from schemas.jobs import JobRequest
from schemas.problems import OVERLOADED, FieldError
from schemas.settings import get_settings
from schemas.systems import Step, no_step
from service.errors import ProblemError, invalid_request
from service.isolated import IsolatedTimeout, report_progress, run_isolated

#: Seconds the service asks a client to wait after a validation past its safety cap.
SAFETY_CAP_RETRY_S = 30
#: An expression that is a bare name (``gamma3``): read in microseconds, checked in the API process.
_BARE_NAME = re.compile(r"\s*[A-Za-z][A-Za-z0-9_]{0,31}\s*")
#: The environment the child mirrors, so that its settings (limits of t_final, samples ...) are the API's.
_PREFIXES = ("NONHOLONOMIC_", "REDIS_URL", "DATABASE_URL")
_MODELS: dict[str, type[JobRequest | EnsembleRequest]] = {"job": JobRequest, "ensemble": EnsembleRequest}

#: The 503 a request with expressions may get (its OpenAPI description).
POOL_FULL = ("; or the symbolic pool, which checks the request's expressions, is full, or their check passed the "
             "service's safety cap (`Retry-After` says when to retry)")

Problems = list[tuple[str, str]]
Chunks = list[tuple[int, int]] | None


def needs_child(expressions: Sequence[tuple[str, str]]) -> bool:
    """Whether a request's expressions (``(field, text)``) are read by sympy in a child process: any that is
    more than a bare name."""
    return any(not _BARE_NAME.fullmatch(text) for _, text in expressions)


def size_problems(expressions: Sequence[tuple[str, str]]) -> Problems:
    """The expressions too large for sympy to read on a request's path (deterministic measures)."""
    return [(field, why) for field, text in expressions if (why := size_problem(text)) is not None]


def past_safety_cap(cap_s: float, fields: Sequence[str]) -> ProblemError:
    """The 503 of a validation still running at the safety cap (not a verdict on the request)."""
    where = f" (it was reading {', '.join(fields)})" if fields else ""
    return ProblemError(503, "Validation past the safety cap",
                        f"checking the request's expressions did not finish within the service's safety cap of "
                        f"{cap_s:g} s (validation_safety_cap_s){where}: a limit of the machine, which may be "
                        "overloaded, not a verdict on the request; the same request is checked the same way when "
                        "retried", OVERLOADED, headers={"Retry-After": str(SAFETY_CAP_RETRY_S)})


def _check(kind: str, body: JobRequest | EnsembleRequest, step: Step = no_step) -> tuple[Problems, Chunks]:
    """The request's problems (``(field, reason)``) and, for a valid ensemble, its chunks."""
    try:
        found = [(p.field, p.reason) for p in body.problems(step)]
    except NUMERIC_ERRORS as exc:  # a number past the float range or the memory: name the expressions
        return numeric_problems(body.expressions(), exc), None
    chunks = None
    if kind == "ensemble" and not found:
        assert isinstance(body, EnsembleRequest)  # the model of kind "ensemble"
        chunks = body.chunks()
    return found, chunks


def _in_child(kind: str, payload: dict[str, Any], environment: dict[str, str]) -> tuple[Problems, Chunks]:
    """:func:`_check` in the child process; every stage reports the fields it reads to the parent
    (:func:`service.isolated.report_progress`), which names them if the safety cap stops the child."""
    for key in [k for k in os.environ if k.startswith(_PREFIXES)]:
        del os.environ[key]
    os.environ.update(environment)
    get_settings.cache_clear()

    def step(fields: Sequence[str]) -> None:
        report_progress(list(fields))

    try:
        body = _MODELS[kind].model_validate(payload)
    except ValidationError as exc:  # the parent accepted it: only a setting that differs here can refuse it
        return [(".".join(str(part) for part in error["loc"]), error["msg"]) for error in exc.errors()], None
    try:
        return _check(kind, body, step)
    except RecursionError:
        return [(field, "too deeply nested to validate") for field, _ in body.expressions()], None


async def validated(http: Request, kind: str, body: JobRequest | EnsembleRequest) -> Chunks:
    """Check ``body`` (``kind``: ``"job"`` or ``"ensemble"``) off the event loop; raise a 422 problem
    naming each bad field, or a 503 (the pool full, or the check past its safety cap). Returns an
    ensemble's chunks (None for a job)."""
    expressions = body.expressions()
    problems = size_problems(expressions)
    chunks: Chunks = None
    if not problems and not needs_child(expressions):
        problems, chunks = await run_in_threadpool(_check, kind, body)
    elif not problems:
        cap_s = http.app.state.settings.validation_safety_cap_s
        environment = {k: v for k, v in os.environ.items() if k.startswith(_PREFIXES)}
        async with http.app.state.symbolic_pool.slot():
            try:
                sent = body.model_dump(mode="json", exclude_unset=True)  # what was sent: defaults are not re-checked
                problems, chunks = await run_in_threadpool(run_isolated, _in_child, (kind, sent, environment), cap_s)
            except IsolatedTimeout as exc:  # the safety cap: a failure of the machine, not a verdict
                raise past_safety_cap(cap_s, exc.progress or []) from None
    if problems:
        raise invalid_request([FieldError(field=field, reason=reason) for field, reason in problems])
    return chunks
