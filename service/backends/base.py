"""What the API needs from a job backend."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

from workers.ensembles import EnsembleStore


@dataclass
class JobRecord:
    """A job as the API reports it (see :class:`schemas.jobs.JobView`)."""

    id: str
    status: str
    progress: float
    created_at: str
    request: dict[str, Any]
    result: dict[str, Any] | None = None
    error: dict[str, str] | None = None
    extra: dict[str, Any] = field(default_factory=dict)


class JobBackend(Protocol):
    mode: str
    #: Where ensembles' records and member results live.
    ensembles: EnsembleStore

    def submit(self, request: dict[str, Any]) -> JobRecord:
        """Accept a validated request; returns the queued job."""

    def get(self, job_id: str) -> JobRecord | None:
        """The job, or None if this service never accepted that id."""

    def cancel(self, job_id: str) -> JobRecord | None:
        """Ask the job to stop; returns it (None if unknown)."""

    def submit_ensemble(self, request: dict[str, Any], chunks: list[tuple[int, int]]) -> tuple[str, str]:
        """Record a validated ensemble and send its chunks to the workers; returns (id, created_at)."""

    def cancel_ensemble(self, ensemble_id: str) -> None:
        """Stop every chunk: queued ones never start, running ones stop at their next progress report."""

    def health(self) -> dict[str, Any]:
        """Status of the parts this backend depends on; ``ok`` is False if jobs cannot run."""

    def close(self) -> None:
        """Release threads and connections."""
