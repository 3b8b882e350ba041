"""Where jobs run: :class:`EmbeddedBackend` (in-process threads) or :class:`QueueBackend` (Celery)."""

from __future__ import annotations

from schemas.settings import Settings
from service.backends.base import JobBackend, JobRecord
from service.backends.embedded import EmbeddedBackend


def make_backend(settings: Settings) -> JobBackend:
    """The queue backend when a Redis URL is set, else the embedded one."""
    if settings.embedded:
        return EmbeddedBackend(settings)
    from service.backends.queue import QueueBackend

    return QueueBackend(settings)


__all__ = ["EmbeddedBackend", "JobBackend", "JobRecord", "make_backend"]
