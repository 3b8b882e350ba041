"""``GET /health``: the answer's model (the same body with 200 and with 503)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class WarmUpState(BaseModel):
    """Where the warm-up is: systems ready of ``total``, the one being prepared, and how many symbolic
    results the memo on disk gave back or had to be derived (a first start derives them all)."""

    model_config = ConfigDict(extra="forbid")

    total: int
    done: int
    now: str | None = Field(None, description="the system being prepared")
    read_back: int = Field(description="symbolic results read back from the memo on disk (workers/disk_memo.py)")
    derived: int = Field(description="symbolic results derived and written to it")
    seconds: float | None = Field(None, description="the warm-up's duration, once finished")


class EmbeddedWorkers(BaseModel):
    """Embedded mode: the in-process job threads."""

    model_config = ConfigDict(extra="forbid")

    threads: int
    warm: bool = Field(description="whether the kernels are compiled (warm-up done)")
    warm_up: WarmUpState | None = None
    long_lane: LongLane | None = Field(None, description="jobs past embedded_long_after_s moved beside the threads")
    let_go: int = Field(0, description="threads given up (stuck past a hard limit, or a cancelled job's inside a "
                                       "compile) and replaced")


class LongLane(BaseModel):
    """Embedded mode's long lane: its size and the long jobs in it now."""

    model_config = ConfigDict(extra="forbid")

    size: int
    running: int


class QueueWorker(BaseModel):
    """Queue mode: a live worker (from its heartbeat, at most 10 s old)."""

    model_config = ConfigDict(extra="forbid")

    queues: list[str] = Field(description="the queues it consumes")
    warm_processes: int = Field(description="its pool processes that finished the warm-up")


class SymbolicPoolStatus(BaseModel):
    """The symbolic endpoints' pool: its bounds and occupancy."""

    model_config = ConfigDict(extra="forbid")

    size: int
    queue: int
    running: int
    waiting: int
    refused: int = Field(description="requests answered 503 since the API started")


class Health(BaseModel):
    """Status of the API, the broker and the workers; 200 when a job would start now (a warm worker on the
    queue), else 503 with ``degraded`` and a ``detail`` saying why."""

    status: Literal["ok", "degraded"]
    api: Literal["ok"]
    version: str
    mode: Literal["embedded", "queue"]
    broker: str = Field(description="'ok', 'none (embedded)' or 'unreachable: <reason>'")
    store: Literal["ok", "unreachable", "unknown"] = Field(
        description="the job store: PostgreSQL in queue mode, SQLite embedded ('unknown': no answer in time)")
    queue: str | None = Field(None, description="queue mode: the Celery queue the jobs go to")
    workers: EmbeddedWorkers | dict[str, QueueWorker] = Field(
        description="embedded mode: threads and warm-up; queue mode: each live worker, its queues and warm processes")
    age_s: float = Field(0.0, ge=0, description="seconds since the check reported here began: 0 for a check made for "
                         "this request; under load, the latest check of the API's monitor (every 0.5 s)")
    symbolic: SymbolicPoolStatus
    detail: str | None = Field(None, description="why jobs cannot start now (with 'degraded')")
