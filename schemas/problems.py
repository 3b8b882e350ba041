"""RFC 9457 problem details."""

from __future__ import annotations

from pydantic import BaseModel, Field

PROBLEM_MEDIA_TYPE = "application/problem+json"
#: Problem types (relative URIs, described in docs/api.md, "Errors").
INVALID_REQUEST = "/problems/invalid-request"
NOT_FOUND = "/problems/not-found"
CONFLICT = "/problems/conflict"
UNAVAILABLE = "/problems/unavailable"
TIMEOUT = "/problems/timeout"
OVERLOADED = "/problems/overloaded"
UNAUTHORIZED = "/problems/unauthorized"
RATE_LIMITED = "/problems/rate-limited"
QUEUE_FULL = "/problems/queue-full"
INTERNAL = "/problems/internal-error"


class FieldError(BaseModel):
    """One offending field: its dotted path in the request body and why it was refused."""

    field: str = Field(description="dotted path, e.g. 'system.inertia[0]' or 'initial_state.gamma'")
    reason: str


class Problem(BaseModel):
    """An RFC 9457 problem (``application/problem+json``)."""

    type: str = "about:blank"
    title: str
    status: int
    detail: str | None = None
    instance: str | None = None
    errors: list[FieldError] = Field(default_factory=list)
