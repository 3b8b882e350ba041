"""The job registry in Redis: which job ids exist, their requests, and cancellation flags.

Celery's result backend answers PENDING for any id, so the API keeps its own record of every job
it accepted; workers read the cancellation flag to stop a running job cooperatively.
"""

from __future__ import annotations

import json
from datetime import datetime, timezone
from typing import Any

import redis

KEY_PREFIX = "nonholonomic:job:"


class RedisJobRegistry:
    """Job records as Redis hashes ``nonholonomic:job:{id}`` with a time to live."""

    def __init__(self, client: redis.Redis, ttl_s: int) -> None:
        self.client = client
        self.ttl_s = ttl_s

    @staticmethod
    def key(job_id: str) -> str:
        return KEY_PREFIX + job_id

    def create(self, job_id: str, request: dict[str, Any]) -> str:
        created_at = datetime.now(timezone.utc).isoformat()
        pipe = self.client.pipeline()
        pipe.hset(self.key(job_id), mapping={"request": json.dumps(request), "created_at": created_at,
                                             "cancelled": "0"})
        pipe.expire(self.key(job_id), self.ttl_s)
        pipe.execute()
        return created_at

    def get(self, job_id: str) -> dict[str, Any] | None:
        raw = self.client.hgetall(self.key(job_id))
        if not raw:
            return None
        fields = {k.decode(): v.decode() for k, v in raw.items()}
        return {"request": json.loads(fields["request"]), "created_at": fields["created_at"],
                "cancelled": fields.get("cancelled") == "1"}

    def cancel(self, job_id: str) -> None:
        self.client.hset(self.key(job_id), "cancelled", "1")

    def is_cancelled(self, job_id: str) -> bool:
        return self.client.hget(self.key(job_id), "cancelled") == b"1"
