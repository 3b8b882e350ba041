"""A request's user expressions read and checked within a budget, off the event loop.

FastAPI reads a body on the event loop, so the request models keep only cheap checks of an expression
(characters, length, syntax, whitelist, names: :func:`nonholonomic.expressions.check_expression`).
What sympy does with it (building U, Φ, L ...; the equations' derivatives; a Poincaré surface's
translation for heyoka; a claim) can take minutes for a text of 25 characters (``(M1 + gamma2 +
gamma3 + 1)**64``). A request with such expressions is therefore checked in a child process
(:func:`service.isolated.run_isolated`) holding a slot of the symbolic pool
(:class:`service.admission.SymbolicPool`): past ``validation_budget_s`` the child stops (a signal
between two Python steps, else the hard limit kills it) and the answer is a 422 naming the field being
read; a full pool answers 503 with ``Retry-After``.

A request without user expressions (built-in systems and potentials), or whose expressions are bare
names (a surface ``gamma3``), is checked in a thread of the API process, as before: no process per job.
"""

from __future__ import annotations

import os
import re
import signal
from collections.abc import Sequence
from types import FrameType
from typing import Any

from fastapi import Request
from pydantic import ValidationError
from starlette.concurrency import run_in_threadpool

from schemas.ensembles import EnsembleRequest
from schemas.jobs import JobRequest
from schemas.problems import FieldError
from schemas.settings import get_settings
from schemas.systems import Step, no_step
from service.errors import invalid_request
from service.isolated import IsolatedTimeout, report_progress, run_isolated

#: Seconds the child may take beyond the budget before it is killed (start-up, a step sympy does in C).
HARD_GRACE_S = 3.0
#: An expression that is a bare name (``gamma3``): read in microseconds, checked in the API process.
_BARE_NAME = re.compile(r"\s*[A-Za-z][A-Za-z0-9_]{0,31}\s*")
#: The environment the child mirrors, so that its settings (limits of t_final, samples ...) are the API's.
_PREFIXES = ("NONHOLONOMIC_", "REDIS_URL", "DATABASE_URL")
_MODELS: dict[str, type[JobRequest | EnsembleRequest]] = {"job": JobRequest, "ensemble": EnsembleRequest}

#: The 503 a request with expressions may get (its OpenAPI description).
POOL_FULL = ("; or the symbolic pool, which checks the request's expressions, is full (`Retry-After` says when "
             "to retry)")

Problems = list[tuple[str, str]]
Chunks = list[tuple[int, int]] | None


class _OverBudget(BaseException):
    """Raised in the child by the budget's timer (a BaseException: no ``except Exception`` swallows it)."""


def needs_budget(expressions: Sequence[tuple[str, str]]) -> bool:
    """Whether a request's expressions (``(field, text)``) must be checked within the budget in a child:
    any that is more than a bare name."""
    return any(not _BARE_NAME.fullmatch(text) for _, text in expressions)


def too_expensive(budget_s: float) -> str:
    """The reason of a field whose check ran out of the budget."""
    return (f"too expensive to validate within {budget_s:g} s (validation_budget_s): write it shorter or "
            "simpler (fewer nested functions, no large powers of sums)")


def _check(kind: str, body: JobRequest | EnsembleRequest, step: Step = no_step) -> tuple[Problems, Chunks]:
    """The request's problems (``(field, reason)``) and, for a valid ensemble, its chunks."""
    found = [(p.field, p.reason) for p in body.problems(step)]
    chunks = body.chunks() if kind == "ensemble" and not found else None  # type: ignore[union-attr]
    return found, chunks


def _in_child(kind: str, payload: dict[str, Any], fields: list[str], environment: dict[str, str],
              budget_s: float) -> tuple[Problems, Chunks]:
    """:func:`_check` in the child process, stopped by a timer at ``budget_s``; every stage reports the fields
    it reads to the parent (:func:`service.isolated.report_progress`) and to the timer's answer (before the
    first stage: every expression field, ``fields``)."""
    for key in [k for k in os.environ if k.startswith(_PREFIXES)]:
        del os.environ[key]
    os.environ.update(environment)
    get_settings.cache_clear()
    stage: list[str] = list(fields)

    def step(fields: Sequence[str]) -> None:
        stage[:] = list(fields)
        report_progress(list(fields))

    def over_budget(signum: int, frame: FrameType | None) -> None:
        raise _OverBudget

    signal.signal(signal.SIGALRM, over_budget)
    signal.setitimer(signal.ITIMER_REAL, budget_s)
    try:
        try:
            body = _MODELS[kind].model_validate(payload)
        except ValidationError as exc:  # the parent accepted it: only a setting that differs here can refuse it
            return [(".".join(str(part) for part in error["loc"]), error["msg"]) for error in exc.errors()], None
        return _check(kind, body, step)
    except _OverBudget:
        return [(field, too_expensive(budget_s)) for field in stage], None
    except RecursionError:
        return [(field, "too deeply nested to validate") for field in stage], None
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)


async def validated(http: Request, kind: str, body: JobRequest | EnsembleRequest) -> Chunks:
    """Check ``body`` (``kind``: ``"job"`` or ``"ensemble"``) off the event loop; raise a 422 problem
    naming each bad field, or the pool's 503. Returns an ensemble's chunks (None for a job)."""
    expressions = body.expressions()
    if not needs_budget(expressions):
        problems, chunks = await run_in_threadpool(_check, kind, body)
    else:
        budget_s = http.app.state.settings.validation_budget_s
        environment = {k: v for k, v in os.environ.items() if k.startswith(_PREFIXES)}
        async with http.app.state.symbolic_pool.slot():
            try:
                fields = [field for field, _ in expressions]
                sent = body.model_dump(mode="json", exclude_unset=True)  # what was sent: defaults are not re-checked
                problems, chunks = await run_in_threadpool(
                    run_isolated, _in_child, (kind, sent, fields, environment, budget_s), budget_s + HARD_GRACE_S)
            except IsolatedTimeout as exc:  # a step in C the timer could not stop
                problems, chunks = [(field, too_expensive(budget_s)) for field in exc.progress or fields], None
    if problems:
        raise invalid_request([FieldError(field=field, reason=reason) for field, reason in problems])
    return chunks
