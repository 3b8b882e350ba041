"""A running job rides out a Redis outage (issue 19, item 9), with a real worker, a Redis of the test's
own (stopped and started again empty; the machine's Redis is not touched) and PostgreSQL.

Progress goes to Celery's result backend (Redis) and is best-effort: a write that fails is skipped
and the job goes on; its end is written to the job store (PostgreSQL). Before, a progress write
retried for ~19 s and then raised ``ConnectionError``, and the job ended ``failed``.
"""

from __future__ import annotations

import time

import pytest

from tests.integration.test_durability import BODY, QueueStack, _redis_server
from tests.support import drop_database, free_port, fresh_database_url, poll_job, redis_available, wait_until

pytestmark = pytest.mark.integration

#: Several seconds of integration with progress reports all along.
LONG = {**BODY, "t_final": 2e6}
#: Longer than Celery's retries of one progress write (20 tries a second apart).
OUTAGE_S = 25.0


def test_a_running_job_rides_out_a_redis_outage_with_the_same_numbers(tmp_path):
    redis_port = free_port()
    redis_url = f"redis://127.0.0.1:{redis_port}/0"
    server = _redis_server(redis_port, tmp_path / "00-redis.log")
    database = fresh_database_url()
    stack = QueueStack(tmp_path, redis_url, database)
    try:
        wait_until(lambda: redis_available(redis_url), 30, "the test's Redis")
        stack.start_api()
        stack.start_worker()
        reference = poll_job(stack.client, stack.client.post("/v1/jobs", json=LONG).headers["location"], timeout=180)
        assert reference["status"] == "succeeded", reference["error"]

        location = stack.client.post("/v1/jobs", json=LONG).headers["location"]
        wait_until(lambda: stack.client.get(location).json()["progress"] >= 0.02, 120, "the job to run")
        server.kill()  # Redis gone mid-job, with every progress and message
        server.wait(10)
        time.sleep(OUTAGE_S)
        server = _redis_server(redis_port, tmp_path / "00-redis-2.log")  # back, empty
        wait_until(lambda: redis_available(redis_url), 30, "the test's Redis again")

        view = poll_job(stack.client, location, timeout=180)
        assert view["status"] == "succeeded", view["error"]
        assert view["result"]["final_state"] == reference["result"]["final_state"]
        assert view["result"]["integrals"] == reference["result"]["integrals"]
        written = "\n".join(p.read_text() for p in tmp_path.glob("*.log"))  # whole logs (stack.logs() keeps tails)
        assert "not written" in written  # the skipped progress writes, logged by the worker
        after = poll_job(stack.client, stack.client.post("/v1/jobs", json=BODY).headers["location"], timeout=120)
        assert after["status"] == "succeeded", after["error"]  # the worker took up the queue again
    except Exception:
        print(stack.logs())
        raise
    finally:
        stack.stop()
        server.kill()
        drop_database(database)
