"""Deployment settings, read from the environment (shared by the API and the workers)."""

from __future__ import annotations

from functools import lru_cache
from typing import Literal

from pydantic import AliasChoices, Field
from pydantic_settings import BaseSettings, SettingsConfigDict

#: Queue mode's job store when ``DATABASE_URL`` is not set: PostgreSQL on this machine (the database is
#: created if missing).
DEFAULT_QUEUE_DATABASE_URL = "postgresql+psycopg://postgres@127.0.0.1:5432/nonholonomic"


class Settings(BaseSettings):
    """Settings; every field can be set as ``NONHOLONOMIC_<NAME>`` (``REDIS_URL`` also plain).

    Without a Redis URL the API runs in embedded mode: jobs run in-process, nothing is queued.
    """

    model_config = SettingsConfigDict(env_prefix="NONHOLONOMIC_", extra="ignore")

    redis_url: str | None = Field(None, validation_alias=AliasChoices("REDIS_URL", "NONHOLONOMIC_REDIS_URL"))
    database_url: str | None = Field(
        None, validation_alias=AliasChoices("DATABASE_URL", "NONHOLONOMIC_DATABASE_URL"),
        description="where job records and results live (SQLAlchemy URL); embedded mode's default: a SQLite file "
                    "in data_dir")
    data_dir: str = Field(".nonholonomic", description="folder of embedded mode's SQLite file (relative: to the "
                                                       "working directory)")
    queue: str = Field("nonholonomic", description="Celery queue the API sends jobs to and workers consume")
    max_t_final: float = Field(1e5, gt=0, description="largest accepted t_final")
    max_samples: int = Field(100_001, ge=2, description="largest accepted number of samples")
    max_body_bytes: int = Field(1 << 20, ge=1024, description="largest accepted request body (bytes); above: 413")
    max_section_points: int = Field(100_000, ge=1, description="largest accepted poincare.max_points")
    max_ensemble_members: int = Field(100_000, ge=1, description="largest number of members of one ensemble")
    max_ensemble_values: int = Field(2_000_000, ge=1,
                                     description="largest members x samples of one ensemble (what its results hold)")
    max_ensemble_section_points: int = Field(10_000_000, ge=1,
                                             description="largest members x poincare.max_points of one ensemble")
    max_ensemble_chunks: int = Field(1000, ge=1, description="most chunks (queue messages) of one ensemble: its POST "
                                                            "sends them all (~1 ms of API CPU each); by default chunks "
                                                            "grow to fit")
    job_soft_time_limit_s: float = Field(600.0, gt=0)
    job_time_limit_s: float = Field(660.0, gt=0)
    visibility_timeout_s: float = Field(3600.0, gt=0, description="broker redelivery timeout (> time limits)")
    job_ttl_s: int = Field(7 * 24 * 3600, gt=0, description="how long job records and results are kept")
    embedded_workers: int = Field(1, ge=1, description="threads running jobs in embedded mode")
    embedded_long_lane: int = Field(2, ge=0, description="embedded mode: jobs past embedded_long_after_s of work "
                                    "that run beside the embedded_workers threads, which take the next jobs "
                                    "(0: a long job keeps its thread)")
    embedded_long_after_s: float = Field(5.0, gt=0, description="embedded mode: seconds of work after which a job "
                                         "moves to the long lane (a scheduling choice: no result depends on it)")
    max_job_attempts: int = Field(2, ge=1, description="starts of one job: a job whose runner stopped this many times "
                                  "while running it (a crash, a restart, a lost worker) is not started again but "
                                  "failed as quarantined, with the reason")
    symbolic_workers: int = Field(2, ge=1, description="symbolic requests running at once (child processes)")
    symbolic_queue: int = Field(8, ge=0,
                                description="symbolic requests waiting for a slot; beyond: 503 with Retry-After")
    max_symbolic_expressions: int = Field(200, ge=1, description="most expressions in one symbolic request")
    max_symbolic_characters: int = Field(40_000, ge=1,
                                         description="most characters of expressions in one symbolic request")
    api_keys: str | None = Field(None, description="comma-separated API keys ('name:key' or 'key'); unset: no keys")
    api_keys_file: str | None = Field(None, description="a file of API keys, one per line ('name:key' or 'key')")
    rate_limit_per_minute: int = Field(0, ge=0, description="requests per minute per API key (0: no limit)")
    max_active_jobs_per_key: int = Field(1000, ge=1,
                                         description="queued and running jobs one key may have; beyond: 429")
    max_queued_messages: int = Field(10_000, ge=1,
                                     description="jobs and ensemble chunks waiting in the queue; beyond: 429")
    cors_origins: str = Field("", description="comma-separated origins allowed by CORS ('' : none, '*': any)")
    warm_up: bool = Field(True, description="compile the integrators when a worker (or embedded API) starts")
    cache_dir: str | None = Field(None, description="folder of the symbolic results remembered between runs "
                                  "(definitions, heyoka forms, kernels, proofs; workers/disk_memo.py); unset: "
                                  "$XDG_CACHE_HOME/nonholonomic or ~/.cache/nonholonomic; 'off': none")
    symbolic_prestart: bool = Field(True, description="start the symbolic pool's fork server (~3 s of CPU, in the "
                                    "background) when the API starts; false: at the first request that needs it")
    cache_max_mib: int = Field(512, ge=1, description="size of cache_dir beyond which its least recently used "
                                                      "files are deleted (MiB)")
    auth_failures_per_minute: int = Field(20, ge=0, description="requests with an unknown API key one client "
                                          "address may send a minute; beyond: 429 (0: no limit)")
    validation_safety_cap_s: float = Field(
        120.0, gt=0, validation_alias=AliasChoices("NONHOLONOMIC_VALIDATION_SAFETY_CAP_S",
                                                   "NONHOLONOMIC_VALIDATION_BUDGET_S"),
        description="safety cap (seconds) on checking a request's expressions in a child process of the symbolic "
                    "pool: beyond it the child is killed and the answer is a 503 with Retry-After, never a 422 "
                    "(refusals are decided by deterministic size measures, not by time). "
                    "NONHOLONOMIC_VALIDATION_BUDGET_S, its old name, is still read (deprecated)")
    symbolic_safety_cap_s: float = Field(
        900.0, gt=0, description="safety cap (seconds) on one symbolic step of a job (a derivation, a search, a "
                                 "proof): beyond it the job fails saying so (never a different verdict)")
    request_threads: int = Field(8, ge=1, description="threads running the API's blocking request work at once, "
                                 "besides the symbolic pool's; more requests wait on the event loop (few threads keep "
                                 "the event loop, and /health, answering under load)")
    worker_max_memory_mib: int = Field(1024, ge=0, description="a worker's pool process whose resident memory passes "
                                       "this after a job is replaced by a new one (compiled code of many distinct "
                                       "user expressions is not all given back); 0: never")
    worker_max_jobs: int = Field(0, ge=0, description="jobs after which a worker's pool process is replaced (0: never)")
    metrics: bool = Field(True, description="Prometheus metrics: the API's GET /metrics (behind the API keys when "
                                            "they are on) and its request counts and durations; false: neither")
    worker_metrics_port: int = Field(9191, ge=0, le=65535, description="port on which a Celery worker serves its "
                                     "metrics (every pool process's, added up; PROMETHEUS_MULTIPROC_DIR); 0: none")
    log_format: Literal["json", "text"] = Field("json", description="log lines of the API and the workers: one JSON "
                                                "object each, with the request id and job id ('json'), or plain text")
    worker_soft_shutdown_s: float = Field(0.0, ge=0, description="Celery's soft shutdown: on a cold shutdown "
                                          "(SIGQUIT, or SIGTERM with REMAP_SIGTERM=SIGQUIT) running tasks get this "
                                          "many seconds to end before they are put back in the queue (0: none)")

    @property
    def embedded(self) -> bool:
        return not self.redis_url

    @property
    def store_url(self) -> str:
        """``database_url``; else in queue mode the local PostgreSQL (:data:`DEFAULT_QUEUE_DATABASE_URL`),
        in embedded mode the SQLite file ``data_dir/jobs.sqlite3``."""
        if self.database_url:
            return self.database_url
        if not self.embedded:
            return DEFAULT_QUEUE_DATABASE_URL
        from pathlib import Path

        return f"sqlite:///{Path(self.data_dir).expanduser().resolve() / 'jobs.sqlite3'}"


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """The process's settings (cached; ``get_settings.cache_clear()`` rereads the environment)."""
    return Settings()
