"""``GET /health``: the answer's model (the same body with 200 and with 503)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class EmbeddedWorkers(BaseModel):
    """Embedded mode: the in-process job threads."""

    model_config = ConfigDict(extra="forbid")

    threads: int
    warm: bool = Field(description="whether the kernels are compiled (warm-up done)")


class Health(BaseModel):
    """Status of the API, the broker and the workers; 200 when jobs can run, else 503 with ``degraded``."""

    status: Literal["ok", "degraded"]
    api: Literal["ok"]
    version: str
    mode: Literal["embedded", "queue"]
    broker: str = Field(description="'ok', 'none (embedded)' or 'unreachable: <reason>'")
    queue: str | None = Field(None, description="queue mode: the Celery queue the jobs go to")
    workers: EmbeddedWorkers | dict[str, list[str]] = Field(
        description="embedded mode: threads and warm-up; queue mode: each live worker with the queues it consumes")
